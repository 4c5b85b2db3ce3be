// What the store keeps of a scene (db::SceneFacts), computed once from the
// parsed scene with mechanics' own functions: db reads no scene. The service
// and `arena submit` call it when they plan trials, the CLI hands the JSON
// form to the store's export and to the importer.
#pragma once

#include <string>

#include "arena/db/scene_facts.hpp"
#include "arena/mechanics/scene.hpp"

namespace arena::orchestrator {

// The indexed columns (parameters, contact types, nominal start pose) and
// the contact sites of `scene`.
db::SceneFacts SceneFactsOf(const mechanics::Scene& scene);

// The same of a scene's JSON text (mechanics::ParseScene). @throws what
// ParseScene throws for a scene it refuses.
db::SceneFacts SceneFactsOfJson(const std::string& scene_json);

}  // namespace arena::orchestrator
