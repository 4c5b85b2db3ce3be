// Recorded planar pushes, lab-neutral: what an importer (an adaptor for one
// lab's file layout, e.g. push_dataset.hpp) hands the core of this room, and
// what the core makes of it: the streams on one 250 Hz clock, the checks of
// each trial against its geometry, the trial's scene, and a dataset that
// `arena cell --backend replay:DATASET` serves (import.hpp).
//
// Frame: the table frame T (x, y on the table, z up). Every pose is planar:
// (x, y) in m and the angle theta about z in rad. The object's pose is that
// of the frame its outline is given in (`Shape::outline`); the pusher's is
// the centre of its tip.
//
// Thread safety: plain structs and pure functions.
#pragma once

#include <array>
#include <cstdint>
#include <limits>
#include <stdexcept>
#include <string>
#include <vector>

#include "arena/errors/error.hpp"

namespace arena::recordings {

// Bad input: names the file (or the shapes table) and the reason. The import
// writes nothing then.
class ImportError : public Error {
 public:
  ImportError(std::string file, const std::string& reason)
      : Error(ErrorCategory::kBadInput, file + ": " + reason), file_(std::move(file)) {}
  const std::string& file() const { return file_; }

 private:
  std::string file_;
};

// One measured stream: time stamps (s, any origin shared by the trial's
// streams, in the order recorded: they need not be sorted) and three values
// per stamp.
struct Stream {
  std::string name;  // for messages: "object_pose", "tip_pose", "ft_wrench"
  std::vector<double> t;
  std::vector<std::array<double, 3>> values;
};

// A prism: the outline (counter-clockwise, m, in the object's frame whose
// origin is the area centroid), extruded over `thickness`.
struct Shape {
  std::string name;
  std::vector<std::array<double, 2>> outline;
  double mass = 0;               // kg
  double moment_of_inertia = 0;  // kg m^2 about the vertical axis through the centroid
  double thickness = 0;          // m
};

// One recorded push, as an adaptor read it.
struct Recording {
  std::string name;    // the trial's name (unique within an import)
  std::string source;  // the file it came from (named in every message)
  Shape shape;
  double pusher_radius = 0;  // m: the tip is a vertical cylinder; the model sees a sphere
  Stream object_pose;        // t, x, y, theta of the object (motion capture)
  Stream pusher_pose;        // t, x, y, theta of the pusher tip's centre
  // t, fx, fy (N), tau_z (N m): the force the pusher applies ON THE OBJECT,
  // in T (an adaptor converts its sensor's convention); empty: not measured.
  Stream force;
  std::string parameters_json = "{}";  // the push as the lab describes it (JSON object)
  // The push angle the lab states (rad): from the inward normal of the outline
  // at the pusher's start to the pusher's travel, counter-clockwise; NaN:
  // not stated. Checked against the poses.
  double stated_push_angle = std::numeric_limits<double>::quiet_NaN();
};

// The streams of one recording on one clock: t_k = k / rate from the latest
// first stamp of the streams to the earliest last one, each value linear
// between its neighbouring stamps (angles unwrapped first).
struct Resampled {
  double rate_hz = 0;
  double t0 = 0;  // the recording's stamp of t = 0
  std::vector<double> t;
  std::vector<std::array<double, 3>> object, pusher, force;  // force empty: not measured
  // Stamps that came out of order, per stream (sorted before resampling).
  int object_out_of_order = 0, pusher_out_of_order = 0, force_out_of_order = 0;
};

// Sorts each stream by time, refuses what cannot be put on one clock (fewer
// than 2 stamps, a repeated stamp, NaN or infinity, streams that do not
// overlap), and resamples.
// @throws ImportError naming the recording's file, the stream and the reason.
Resampled Resample(const Recording& recording, double rate_hz = 250.0);

// One finding of the checks, for the report.
struct Finding {
  std::string check;   // e.g. "force_frozen", "pusher_inside_at_start", "contact_gap_at_onset"
  std::string detail;  // what was measured
  bool fails = false;  // true: the stream it concerns must not be scored
};

// What the checks found in one trial.
struct TrialChecks {
  std::vector<Finding> findings;
  bool pose_usable = true;   // the object and pusher poses may be scored
  bool force_usable = true;  // the force stream may be scored
  // Measured, for the report (NaN when it does not apply).
  double onset_t = 0;          // s: when the object starts to move (NaN: it never does)
  double onset_gap = 0;        // m: pusher disk to outline at onset (< 0: inside)
  double start_gap = 0;        // m: the same at t = 0
  double force_offset = 0;     // N: |mean force| while the pusher is clear of the object
  double force_drift = 0;      // N: change of that offset between the start and the end
  double object_travel = 0;    // m: |final - start| object position
  double object_rotation = 0;  // rad: final - start angle
  double push_angle = 0;       // rad: the measured push angle (as Recording::stated_push_angle)
};

// Tolerances of the checks (docs/real_data.md says why these).
struct CheckOptions {
  double onset_motion = 0.0005;  // m: a point of the outline moved this far: the object moves
  double onset_gap_tol = 0.002;  // m: |gap at onset| above this fails the poses
  double inside_warn = 0.0;      // m: a start deeper than this inside the outline is reported
  double inside_fail = 0.001;    // m: ... and deeper than this fails the poses
  double clear_gap = 0.003;      // m: pusher this far from the outline: no contact force
  double frozen_range = 1e-9;    // N: every force channel within this: frozen
  double offset_fail = 0.5;      // N: |force| while clear above this: an offset
  double drift_fail = 0.5;       // N: the offset changing by more than this: a drift
  double angle_fail = 0.0873;    // rad (5 deg): measured push angle off the stated one
};

TrialChecks CheckTrial(const Recording& recording, const Resampled& streams,
                       const CheckOptions& options = {});

// Signed distance (m) from a point to a simple polygon's boundary: negative
// inside. The polygon in the point's frame.
double SignedDistance(const std::vector<std::array<double, 2>>& polygon, double x, double y);
// The closest point of the polygon's boundary to (x, y).
std::array<double, 2> NearestPoint(const std::vector<std::array<double, 2>>& polygon, double x,
                                   double y);

}  // namespace arena::recordings
