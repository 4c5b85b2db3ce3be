// Reading and writing scene JSON (SCENE.md). This is the edge of the
// mechanics room: the model itself never sees JSON.
#pragma once

#include <stdexcept>
#include <string>
#include <string_view>

#include "arena/mechanics/scene.hpp"

namespace arena::mechanics {

// A scene that is missing a field, has a field of the wrong type, a
// non-finite number or a value out of range. field() is the JSON path
// ("fingers[1].mu"), what() is "fingers[1].mu: must be >= 0, got -0.2".
class SceneError : public std::runtime_error {
 public:
  SceneError(std::string field, const std::string& reason);
  const std::string& field() const { return field_; }

 private:
  std::string field_;
};

// @throws SceneError naming the first offending field.
Scene ParseScene(std::string_view json_text);

// Checks ranges and consistency of a scene built in code.
// @throws SceneError naming the first offending field.
void ValidateScene(const Scene& scene);

// The scene as SCENE.md JSON; ParseScene(SceneToJson(s)) reproduces s.
std::string SceneToJson(const Scene& scene);

}  // namespace arena::mechanics
