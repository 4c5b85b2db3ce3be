// The extremes suite of the mechanics issue (issue 3): one change per case
// applied to a base scene (canonical, or with patch fingers). Shared by
// tests/mechanics/extremes_test.cpp and bench/extremes_table.cpp (the table
// of residuals in bench/README.md, "Extremes").
#pragma once

#include <functional>
#include <string>
#include <vector>

#include "arena/mechanics/scene.hpp"
#include "scenes.hpp"

namespace arena::mechanics::testing {

inline Scene PatchScene() {
  Scene s = CanonicalScene();
  s.fingers[0].type = ContactType::kPatch;
  s.fingers[0].radius = 0.01;
  s.fingers[1].type = ContactType::kPatch;
  s.fingers[1].radius = 0.01;
  s.model.points = 4;
  return s;
}

inline void ScaleLength(Scene& s, double k) {
  s.object.size *= k;
  s.object.radius *= k;
  s.object.height *= k;
  s.object.pose.position *= k;
  for (auto& f : s.fingers) {
    f.position *= k;
    f.length *= k;
    f.radius *= k;
  }
  if (s.pusher) {
    s.pusher->position *= k;
    s.pusher->length *= k;
    s.pusher->radius *= k;
  }
}

struct Extreme {
  std::string name;
  std::function<void(Scene&)> apply;
};

inline std::vector<Extreme> Extremes() {
  std::vector<Extreme> e;
  for (double mu : {1e-6, 1e3}) {
    e.push_back({"mu " + std::to_string(mu), [mu](Scene& s) {
                   for (auto& f : s.fingers) f.mu = mu;
                   s.pusher->mu = mu;
                 }});
  }
  for (double g : {1e-6, 1e6})
    e.push_back({"grip " + std::to_string(g), [g](Scene& s) { s.grip_force = g; }});
  for (double m : {1e-6, 1e3})
    e.push_back({"mass " + std::to_string(m), [m](Scene& s) { s.object.mass = m; }});
  for (double size : {1e-4, 10.0}) {
    e.push_back({"size " + std::to_string(size),
                 [size](Scene& s) { ScaleLength(s, size / s.object.size.maxCoeff()); }});
  }
  e.push_back({"line points 1e-9 m apart", [](Scene& s) {
                 for (auto& f : s.fingers) {
                   if (f.type == ContactType::kLine) f.length = 2e-9;
                   if (f.type == ContactType::kPatch) f.radius = 1.5e-9;
                 }
               }});
  for (double v : {0.0, 10.0}) {
    e.push_back({"pusher speed " + std::to_string(v), [v](Scene& s) {
                   s.pusher->motion.velocity = {0, 0, v};
                 }});
  }
  e.push_back({"light object, huge grip", [](Scene& s) {
                 s.object.mass = 1e-6;
                 s.grip_force = 1e6;
               }});
  e.push_back({"heavy object, tiny grip, slippery", [](Scene& s) {
                 s.object.mass = 1e3;
                 s.grip_force = 1e-6;
                 for (auto& f : s.fingers) f.mu = 1e-6;
               }});
  e.push_back({"tiny object, fast pusher", [](Scene& s) {
                 ScaleLength(s, 1e-3);
                 s.pusher->motion.velocity = {0, 0, 10};
               }});
  e.push_back({"huge object, sticky", [](Scene& s) {
                 ScaleLength(s, 100);
                 for (auto& f : s.fingers) f.mu = 1e3;
               }});
  return e;
}

}  // namespace arena::mechanics::testing
