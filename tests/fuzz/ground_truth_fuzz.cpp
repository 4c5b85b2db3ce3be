// libFuzzer target for the ground-truth sample decoder (scripts/fuzz.sh builds
// and runs it): the bytes a cell, or anyone on the domain, puts on the wire.
// Path: CDR payload -> msg::GroundTruth (the generated type support, as the
// service's reader does it) -> CheckBatch -> DecodeSample of every sample.
// Oracle: nothing crashes or throws past the type support; a batch that
// passes CheckBatch decodes to finite values only, and its samples re-encode
// to the same message fields.
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <exception>
#include <string>

#include <fastdds/rtps/common/SerializedPayload.h>

#include "arena/schemas/arena.h"
#include "arena/schemas/arenaPubSubTypes.h"
#include "arena/schemas/ground_truth.hpp"

namespace {

bool Finite(const Eigen::Ref<const Eigen::VectorXd>& v) { return v.allFinite(); }

void CheckDecoded(const arena::msg::GroundTruthSample& in) {
  using namespace arena;
  dds::PusherState pusher;
  dds::Observation observed;
  const mechanics::TrajectorySample s = dds::DecodeSample(in, &pusher, &observed);
  const struct {
    const char* field;
    bool finite;
  } checks[] = {{"t", std::isfinite(s.t)},
                {"position", Finite(s.position)},
                {"orientation", Finite(s.orientation.coeffs())},
                {"velocity", Finite(s.velocity)},
                {"angular_velocity", Finite(s.angular_velocity)},
                {"pusher_force", Finite(s.pusher_force)},
                {"pusher.position", Finite(pusher.position)},
                {"pusher.velocity", Finite(pusher.velocity)},
                {"observed.t", std::isfinite(observed.t)},
                {"observed.position", Finite(observed.position)},
                {"observed.pusher_wrench", Finite(observed.pusher_wrench)}};
  for (const auto& c : checks) {
    if (!c.finite) {
      std::fprintf(stderr, "CheckSample passed a non-finite %s\n", c.field);
      std::abort();
    }
  }
  msg::GroundTruthSample again;
  dds::EncodeSample(s, pusher, observed, &again);
  if (again.object_pose() != in.object_pose() || again.contacts().size() != in.contacts().size() ||
      again.observed_valid() != in.observed_valid()) {
    std::abort();  // decode and encode disagree on the layout
  }
}

// Seeds: real, well-formed batches serialized as a cell sends them (0, 1 and
// 3 samples), written when ARENA_GT_SEEDS names a directory (scripts/fuzz.sh).
void WriteSeeds(const char* dir) {
  using namespace arena;
  msg::GroundTruthPubSubType type;
  for (int n : {0, 1, 3}) {
    msg::GroundTruth batch;
    batch.trial_id(7);
    batch.attempt(1);
    batch.schema_version(msg::SCHEMA_VERSION);
    batch.cell_id("sim1");
    batch.first_sample(0);
    batch.last(true);
    for (int k = 0; k < n; ++k) {
      mechanics::TrajectorySample s;
      s.t = 0.004 * k;
      s.position = {0.001 * k, 0, 0};
      s.contacts.resize(3);
      s.contacts[0].mode = mechanics::ContactMode::kStick;
      s.contacts[2].mode = mechanics::ContactMode::kSlide;
      dds::Observation observed;
      observed.valid = k % 2 == 0;
      observed.t = s.t;
      observed.finger_wrenches.assign(2, dds::Wrench::Ones());
      msg::GroundTruthSample out;
      dds::EncodeSample(s, dds::PusherState{}, observed, &out);
      batch.samples().push_back(out);
    }
    eprosima::fastrtps::rtps::SerializedPayload_t payload(type.getSerializedSizeProvider(&batch)());
    if (!type.serialize(&batch, &payload)) std::abort();
    const std::string path = std::string(dir) + "/seed_" + std::to_string(n) + ".cdr";
    if (FILE* f = std::fopen(path.c_str(), "wb")) {
      std::fwrite(payload.data + 4, 1, payload.length - 4, f);  // without the encapsulation header
      std::fclose(f);
    }
  }
}

}  // namespace

extern "C" int LLVMFuzzerInitialize(int*, char***) {
  if (const char* dir = std::getenv("ARENA_GT_SEEDS")) WriteSeeds(dir);
  return 0;
}

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  // The reader never sees more than one datagram-sized payload per sample;
  // Fast DDS caps it the same way (max message size).
  if (size > 1 << 20) return 0;
  eprosima::fastrtps::rtps::SerializedPayload_t payload(static_cast<uint32_t>(size + 4));
  // RTPS encapsulation header: CDR little endian, then the fuzzer's bytes.
  payload.data[0] = 0x00;
  payload.data[1] = 0x01;
  payload.data[2] = 0x00;
  payload.data[3] = 0x00;
  if (size > 0) std::memcpy(payload.data + 4, data, size);
  payload.length = static_cast<uint32_t>(size + 4);

  arena::msg::GroundTruthPubSubType type;
  arena::msg::GroundTruth batch;
  try {
    if (!type.deserialize(&payload, &batch)) return 0;
  } catch (const std::exception&) {
    return 0;  // the type support refuses short or malformed CDR by throwing
  }
  if (!arena::dds::CheckBatch(batch, batch.first_sample()).empty()) return 0;
  for (const auto& sample : batch.samples()) CheckDecoded(sample);
  return 0;
}
