// The ground-truth block codec (layout in db/README.md, "gt_chunks.data").
#include <cmath>
#include <cstring>
#include <string>

#include "arena/db/sample.hpp"
#include "arena/db/store.hpp"

namespace arena::db {
namespace {

constexpr char kMagic[4] = {'A', 'G', 'T', '1'};

static_assert(sizeof(double) == 8, "the block format stores IEEE-754 binary64");

template <std::size_t N>
std::string CheckArray(const std::array<double, N>& a, const char* name) {
  for (std::size_t i = 0; i < N; ++i) {
    if (!std::isfinite(a[i])) {
      return std::string(name) + "[" + std::to_string(i) + "] is " +
             (std::isnan(a[i]) ? "NaN" : "infinite");
    }
  }
  return {};
}

void Put(std::string* out, const void* p, std::size_t n) {
  out->append(static_cast<const char*>(p), n);
}

template <std::size_t N>
void PutArray(std::string* out, const std::array<double, N>& a) {
  Put(out, a.data(), N * sizeof(double));
}

struct Reader {
  const unsigned char* p;
  const unsigned char* end;
  void Get(void* dst, std::size_t n) {
    if (n == 0) return;  // dst may be an empty vector's null data()
    if (static_cast<std::size_t>(end - p) < n) {
      throw StoreError(StoreError::Kind::kCorrupt, "DecodeSamples: block truncated");
    }
    std::memcpy(dst, p, n);
    p += n;
  }
  template <std::size_t N>
  void GetArray(std::array<double, N>* a) {
    Get(a->data(), N * sizeof(double));
  }
};

}  // namespace

const char* ToString(ContactMode mode) {
  switch (mode) {
    case ContactMode::kStick:
      return "stick";
    case ContactMode::kSlide:
      return "slide";
    case ContactMode::kSeparate:
      return "separate";
  }
  return "?";
}

namespace {
// The fast path of CheckSample: no strings unless something is wrong.
template <std::size_t N>
bool AllFinite(const std::array<double, N>& a) {
  bool ok = true;
  for (double v : a) ok &= std::isfinite(v);
  return ok;
}
bool LooksValid(const Sample& s) {
  bool ok = std::isfinite(s.t) && AllFinite(s.object_pose) && AllFinite(s.object_twist) &&
            AllFinite(s.pusher_pose) && AllFinite(s.pusher_twist) &&
            AllFinite(s.observed_object_pose) && AllFinite(s.observed_pusher_wrench) &&
            s.contacts.size() <= 255 && s.observed_finger_wrenches.size() <= 255;
  for (const auto& c : s.contacts) {
    ok &= AllFinite(c.force) && AllFinite(c.torque) && static_cast<int>(c.mode) <= 2;
  }
  for (double v : s.observed_finger_wrenches) ok &= std::isfinite(v);
  return ok;
}
}  // namespace

std::string CheckSample(const Sample& s) {
  if (LooksValid(s)) return {};
  if (!std::isfinite(s.t)) return std::string("t is ") + (std::isnan(s.t) ? "NaN" : "infinite");
  std::string e;
  if (!(e = CheckArray(s.object_pose, "object_pose")).empty()) return e;
  if (!(e = CheckArray(s.object_twist, "object_twist")).empty()) return e;
  if (!(e = CheckArray(s.pusher_pose, "pusher_pose")).empty()) return e;
  if (!(e = CheckArray(s.pusher_twist, "pusher_twist")).empty()) return e;
  if (!(e = CheckArray(s.observed_object_pose, "observed_object_pose")).empty()) return e;
  if (!(e = CheckArray(s.observed_pusher_wrench, "observed_pusher_wrench")).empty()) return e;
  if (s.contacts.size() > 255) return "contacts has more than 255 entries";
  for (std::size_t c = 0; c < s.contacts.size(); ++c) {
    const std::string name = "contacts[" + std::to_string(c) + "].";
    if (!(e = CheckArray(s.contacts[c].force, (name + "force").c_str())).empty()) return e;
    if (!(e = CheckArray(s.contacts[c].torque, (name + "torque").c_str())).empty()) return e;
    if (static_cast<int>(s.contacts[c].mode) > 2) return name + "mode is not stick/slide/separate";
  }
  if (s.observed_finger_wrenches.size() > 255)
    return "observed_finger_wrenches has more than 255 values";
  for (std::size_t i = 0; i < s.observed_finger_wrenches.size(); ++i) {
    if (!std::isfinite(s.observed_finger_wrenches[i])) {
      return "observed_finger_wrenches[" + std::to_string(i) + "] is not finite";
    }
  }
  return {};
}

std::size_t EncodedSampleBytes(const Sample& s) {
  return 4 + 8 * (1 + 7 + 6 + 7 + 6 + 7 + 6) + s.contacts.size() * (6 * 8 + 1) +
         s.observed_finger_wrenches.size() * 8;
}

void EncodeSampleBody(const Sample& s, std::string* out) {
  // One resize, then plain copies: this runs once per sample at 250 Hz x cells.
  const std::size_t offset = out->size();
  out->resize(offset + EncodedSampleBytes(s));
  char* p = out->data() + offset;
  auto put = [&p](const void* src, std::size_t n) {
    if (n == 0) return;  // src may be an empty vector's null data()
    std::memcpy(p, src, n);
    p += n;
  };
  const unsigned char head[4] = {static_cast<unsigned char>(s.observed_valid ? 1 : 0),
                                 static_cast<unsigned char>(s.contacts.size()),
                                 static_cast<unsigned char>(s.observed_finger_wrenches.size()), 0};
  put(head, 4);
  put(&s.t, 8);
  put(s.object_pose.data(), 7 * 8);
  put(s.object_twist.data(), 6 * 8);
  put(s.pusher_pose.data(), 7 * 8);
  put(s.pusher_twist.data(), 6 * 8);
  for (const auto& c : s.contacts) {
    put(c.force.data(), 3 * 8);
    put(c.torque.data(), 3 * 8);
    const auto mode = static_cast<unsigned char>(c.mode);
    put(&mode, 1);
  }
  put(s.observed_object_pose.data(), 7 * 8);
  put(s.observed_pusher_wrench.data(), 6 * 8);
  put(s.observed_finger_wrenches.data(), s.observed_finger_wrenches.size() * 8);
}

void PatchBlockCount(std::uint32_t count, std::string* block) {
  std::memcpy(block->data() + 4, &count, 4);
}

void EncodeBlockHeader(std::uint32_t count, std::string* out) {
  Put(out, kMagic, 4);
  Put(out, &count, 4);
}

void EncodeSamples(const Sample* samples, std::size_t count, std::string* out) {
  EncodeBlockHeader(static_cast<std::uint32_t>(count), out);
  for (std::size_t i = 0; i < count; ++i) EncodeSampleBody(samples[i], out);
}

std::vector<Sample> DecodeSamples(const void* data, std::size_t size) {
  if (size >= 4 && std::memcmp(data, "AGT2", 4) == 0) {
    const std::string raw = UnpackBlock(data, size);
    return DecodeSamples(raw.data(), raw.size());
  }
  Reader r{static_cast<const unsigned char*>(data), static_cast<const unsigned char*>(data) + size};
  char magic[4];
  r.Get(magic, 4);
  if (std::memcmp(magic, kMagic, 4) != 0) {
    throw StoreError(StoreError::Kind::kCorrupt,
                     "DecodeSamples: not a ground-truth block (bad magic)");
  }
  std::uint32_t n = 0;
  r.Get(&n, 4);
  // Each sample takes at least 4 + 27*8 + 13*8 bytes: refuse counts the block cannot hold.
  if (n > size / (4 + 40 * 8)) {
    throw StoreError(StoreError::Kind::kCorrupt, "DecodeSamples: sample count exceeds block size");
  }
  std::vector<Sample> out(n);
  for (auto& s : out) {
    unsigned char head[4];
    r.Get(head, 4);
    if (head[0] > 1) throw StoreError(StoreError::Kind::kCorrupt, "DecodeSamples: bad flags");
    s.observed_valid = head[0] == 1;
    r.Get(&s.t, 8);
    r.GetArray(&s.object_pose);
    r.GetArray(&s.object_twist);
    r.GetArray(&s.pusher_pose);
    r.GetArray(&s.pusher_twist);
    s.contacts.resize(head[1]);
    for (auto& c : s.contacts) {
      r.GetArray(&c.force);
      r.GetArray(&c.torque);
      unsigned char mode = 0;
      r.Get(&mode, 1);
      if (mode > 2) throw StoreError(StoreError::Kind::kCorrupt, "DecodeSamples: bad contact mode");
      c.mode = static_cast<ContactMode>(mode);
    }
    r.GetArray(&s.observed_object_pose);
    r.GetArray(&s.observed_pusher_wrench);
    s.observed_finger_wrenches.resize(head[2]);
    r.Get(s.observed_finger_wrenches.data(), head[2] * 8u);
  }
  if (r.p != r.end) throw StoreError(StoreError::Kind::kCorrupt, "DecodeSamples: trailing bytes");
  return out;
}

}  // namespace arena::db
