// libFuzzer target for the scene reader (scripts/fuzz.sh builds and runs it).
// Oracle: ParseScene either returns a scene or throws SceneError (never
// crashes, never throws anything else), and an accepted scene survives a
// write/read round trip unchanged.
#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <string>
#include <string_view>

#include "arena/mechanics/scene_json.hpp"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace arena::mechanics;
  const std::string_view text(reinterpret_cast<const char*>(data), size);
  Scene scene;
  try {
    scene = ParseScene(text);
  } catch (const SceneError&) {
    return 0;
  }
  const std::string once = SceneToJson(scene);
  try {
    const std::string twice = SceneToJson(ParseScene(once));
    if (twice != once) std::abort();  // the round trip changed the scene
  } catch (const SceneError&) {
    std::abort();  // an accepted scene, written back, must read again
  }
  return 0;
}
