// `arena plot --scene SCENE.json` (or a stored trial's scene): a picture of
// the set-up a scene file describes — the object, the fingers, the pusher and
// its motion, gravity — in two views (front: x right, z up; top: x right,
// y up) at one scale with a scale bar, so a researcher sees what the file
// says before running it (issue 26).
#pragma once

#include <string>

#include "arena/mechanics/scene.hpp"

namespace arena::cli {

// The SVG document. Groups carry ids tests can find: view-front, view-top,
// and inside each: object, finger-NAME, pusher, push-motion, scale-bar.
std::string SceneSvg(const mechanics::Scene& scene, const std::string& title);

}  // namespace arena::cli
