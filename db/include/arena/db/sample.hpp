// One ground-truth sample as the store keeps it: plain, DDS-free, mirrors
// schemas/arena.idl GroundTruthSample (and mechanics TrajectorySample).
//
// Frames and units (all SI): poses and twists of the object and the pusher
// are in the gripper frame G; a pose is (x, y, z, qw, qx, qy, qz) with the
// position in m and a unit quaternion; a twist is (vx, vy, vz, wx, wy, wz) in
// m/s and rad/s. Contact wrenches act on the object, force in G (N), torque
// about the contact point in G (N m); contacts are in scene order (fingers,
// then the pusher). Observed values are what the cell's sensors saw.
#pragma once

#include <array>
#include <cstdint>
#include <string>
#include <vector>

namespace arena::db {

enum class ContactMode : std::uint8_t { kStick = 0, kSlide = 1, kSeparate = 2 };
const char* ToString(ContactMode mode);

struct ContactWrench {
  std::array<double, 3> force{};   // N, on the object, gripper frame
  std::array<double, 3> torque{};  // N m about the contact point, gripper frame
  ContactMode mode = ContactMode::kSeparate;
};

struct Sample {
  double t = 0;                                            // s since the execute phase started
  std::array<double, 7> object_pose{0, 0, 0, 1, 0, 0, 0};  // true (m, quaternion w x y z)
  std::array<double, 6> object_twist{};                    // true (m/s, rad/s)
  std::array<double, 7> pusher_pose{0, 0, 0, 1, 0, 0, 0};  // true
  std::array<double, 6> pusher_twist{};                    // true
  std::vector<ContactWrench> contacts;  // true, scene order (fingers, then pusher)
  bool observed_valid = true;           // false: the sensors dropped this sample
  std::array<double, 7> observed_object_pose{0, 0, 0, 1, 0, 0, 0};  // motion capture
  std::array<double, 6> observed_pusher_wrench{};                   // pusher F/T sensor (N, N m)
  std::vector<double> observed_finger_wrenches;  // 6 per finger, scene order (N, N m)
};

// Returns "" when every number in `s` is finite and the sizes are in range
// (at most 255 contacts and 255 finger-wrench values), else a message naming
// the field ("object_pose[3] is NaN").
std::string CheckSample(const Sample& s);

// The block codec used for the gt_chunks.data BLOB (db/README.md gives the
// byte layout). Encode appends to *out; Decode throws StoreError(kCorrupt)
// on a malformed block and never reads past `size`.
// EncodeSamples writes the raw format "AGT1"; DecodeSamples reads "AGT1"
// and the packed "AGT2" (PackBlock) alike.
void EncodeSamples(const Sample* samples, std::size_t count, std::string* out);
std::vector<Sample> DecodeSamples(const void* data, std::size_t size);

// Samples per block at most (IngestOptions::samples_per_chunk has the same
// bound), and the largest raw block a packed one may expand to: a corrupt
// count cannot make a reader allocate more.
constexpr std::uint32_t kMaxBlockSamples = 100000;
constexpr std::size_t kMaxBlockBytes = std::size_t{256} << 20;

// Lossless packing of an AGT1 block whose samples all have the same number of
// contacts and finger values (what one stream delivers): appends the "AGT2"
// block to *out and returns true, or returns false and leaves *out alone
// when the block is not uniform, not well formed, or would not get smaller.
bool PackBlock(const void* agt1, std::size_t size, std::string* out);
// The AGT1 block a packed block came from, byte for byte.
// @throws StoreError(kCorrupt) on a malformed block; never reads past `size`.
std::string UnpackBlock(const void* agt2, std::size_t size);

}  // namespace arena::db
