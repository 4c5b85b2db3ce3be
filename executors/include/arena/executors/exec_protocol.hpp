// The exec:COMMAND protocol, version 1: a cell backend in any language.
//
// The cell starts COMMAND (/bin/sh -c, in its own process group, killed when
// the cell dies) and speaks JSON lines on the driver's stdin/stdout: one JSON
// object per line, UTF-8, "\n"-terminated. stderr is the driver's log (it
// goes to the cell's log). Every message has "type". Full description and a
// worked example: executors/README.md and examples/drivers/replay.py.
//
//   driver -> cell, first, within hello_timeout:
//     {"type":"hello","protocol":1,"name":"...","truth":"robot|recorded|simulator",
//      "engine":"free text","contact_types":["point","line","patch"],
//      "emulates_defects":false,"resets":true|false,
//      "fixture_changes":{"finger_s":S,"pusher_s":S,"object_s":S}}   (optional)
//     fixture_changes (issue 29, schemas/fixtures.hpp): the seconds a change
//     of the finger pads, the pusher or the object takes on this rig; the
//     cell announces them and the service's change-aware scheduling uses
//     them. Absent: the cell's defect profile's (changes, reset.swap_time).
//     The driver makes the changes itself (in its reset, or before a trial
//     whose scene's fixtures differ from the last one's).
//   cell -> driver                         driver -> cell
//     {"type":"prepare","trial_id","attempt","seed","scene":{SCENE}}
//                                            {"type":"ready"} | {"type":"refused","reason"}
//     {"type":"execute","trial_id","attempt","deadline_s"}
//                                            {"type":"sample", t, position[3],
//                                             orientation[4] (w,x,y,z), velocity[3],
//                                             angular_velocity[3], pusher_position[3],
//                                             pusher_force[3], contacts[{normal_force,
//                                             tangential_force[3], torque[3],
//                                             mode: stick|slide|separate}]} ...
//                                            (or {"type":"samples","samples":[...]})
//                                            then {"type":"done","detail":{...}}
//                                            or {"type":"failed","reason"}
//     Samples stream live: the cell forwards each line as it arrives (live
//     topic, log); a failure after some of them still fails the phase.
//     {"type":"reset","trial_id","attempt","target":{"position","orientation"},
//      "scene":{SCENE}|null}               (only when hello said "resets": true)
//                                            {"type":"reset_done","achieved":{"position",
//                                             "orientation"},"attempts"}
//                                            | {"type":"reset_failed","reason","attempts"}
//     {"type":"shutdown"}                    the driver exits (killed after 2 s)
//   Either way, {"type":"error","message"} ends the phase in progress.
//
// A phase fails (the cell stays up, kills the driver and starts it afresh for
// the next trial) on: a line that is not a JSON object or lacks a field
// ("malformed"), a non-finite number (NaN, Infinity), timestamps that do not
// start at 0 or do not increase, the driver exiting ("crashed", with its exit
// status or signal), and silence longer than reply_timeout or past the
// phase's deadline ("hung").
#pragma once

#include <optional>
#include <string>
#include <string_view>

#include <nlohmann/json.hpp>

#include "arena/mechanics/simulate.hpp"

namespace arena::executors::exec {

inline constexpr int kProtocolVersion = 1;

// A driver's sample as a TrajectorySample. @returns "" or why it is malformed.
std::string ParseSample(const nlohmann::json& j, mechanics::TrajectorySample* out);
// The sample as the driver would send it (tests, the reference driver's format).
nlohmann::json SampleToJson(const mechanics::TrajectorySample& s);

}  // namespace arena::executors::exec
