// The first adaptor: the MIT MCube push dataset (Yu, Bauza, Fazeli,
// Rodriguez, IROS 2016), one HDF5 file per push:
//
//   motion_surface=SURFACE_shape=S_a=A_v=V_i=I_s=S_t=T.h5
//     tip_pose     N x 4 float64: t (s, Unix time), x, y (m), theta (rad) of the pusher
//     object_pose  N x 4 float64: t, x, y, theta of the object (motion capture)
//     ft_wrench    N x 4 float64: t, fx, fy (N), tau_z (N m) at the pusher's sensor
//
// all in the table frame, each stream with its own stamps. The shapes table
// (docs/real_data.md documents its format) gives each shape's outline, mass
// and moment of inertia, the thickness and the pusher radius.
#pragma once

#include <map>
#include <string>
#include <vector>

#include "arena/recordings/recording.hpp"

namespace arena::recordings {

struct ShapesTable {
  double thickness = 0;      // m
  double pusher_radius = 0;  // m
  std::map<std::string, Shape> shapes;
};

// @throws ImportError naming the file and the field.
ShapesTable ReadShapesTable(const std::string& path);

// The push parameters in a file name: surface, shape, a (acceleration), v
// (mm/s), i, s (the contact's place on the outline), t (push angle, rad).
struct PushParameters {
  std::string surface, shape;
  double a = 0, v = 0, i = 0, s = 0, t = 0;
};
// @throws ImportError when the name lacks one of them or a value is not a number.
PushParameters ParsePushFileName(const std::string& file_name);

// One file. The sensor's force is the pusher's reaction: the force on the
// object is its negative (checked against the push direction on the data:
// docs/real_data.md).
// @throws ImportError naming the file: unreadable, truncated, a dataset
//   missing or not N x 4 float64, NaN, an unknown shape.
Recording ReadPushFile(const std::string& path, const ShapesTable& shapes);

// Every *.h5 file under `dir` (recursively), in name order.
// @throws ImportError: no such directory, no .h5 file, or a file as above.
std::vector<Recording> ReadPushDataset(const std::string& dir, const ShapesTable& shapes);

}  // namespace arena::recordings
