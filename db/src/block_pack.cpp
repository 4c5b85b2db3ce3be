// The packed ground-truth block "AGT2" (layout in db/README.md): a lossless
// re-encoding of an "AGT1" block whose samples all have the same shape.
// Each double field becomes a column over the chunk's samples; a column is
// either constant, or the residuals of its IEEE-754 bit patterns (as 64-bit
// integers) against a first- or second-order predictor, zigzagged, with
// leading zero bytes dropped (a 4-bit length per value). Smooth trajectories
// and constant fields (planar motion, separated contacts, unused axes) lose
// their high bytes; noise keeps its bytes. Unpacking rebuilds the AGT1 block
// byte for byte, so the AGT1 parser remains the one place that turns bytes
// into samples.
#include <bit>
#include <cstdint>
#include <cstring>
#include <memory>
#include <string>
#include <vector>

#include "arena/db/sample.hpp"
#include "arena/db/store.hpp"

// The bit patterns are copied as host integers: the formats are little-endian
// (like AGT1, which copies doubles as they are in memory).
static_assert(__BYTE_ORDER__ == __ORDER_LITTLE_ENDIAN__, "AGT1/AGT2 are little-endian formats");

namespace arena::db {
namespace {

constexpr char kRawMagic[4] = {'A', 'G', 'T', '1'};
constexpr char kPackedMagic[4] = {'A', 'G', 'T', '2'};
constexpr std::size_t kRawHeader = 8;      // magic, u32 count
constexpr std::size_t kPackedHeader = 12;  // magic, u32 count, u8 contacts, u8 finger values, u16 0

// Column kinds (one byte before each column).
enum : unsigned char {
  kConstant = 0,  // byte columns: 1 byte follows; double columns: 8 bytes follow
  kRaw = 1,       // byte columns only: count bytes follow
  kDelta1 = 1,    // double columns: residual against the previous value
  kDelta2 = 2,    // double columns: residual against the linear extrapolation of the two previous
};

[[noreturn]] void CorruptBlock(const std::string& what) {
  throw StoreError(StoreError::Kind::kCorrupt, "DecodeSamples: packed block " + what);
}

// Where each field of a uniform-shape AGT1 row sits (db/README.md, AGT1).
struct Shape {
  int contacts = 0, finger_values = 0;
  std::size_t row = 0;                 // bytes per sample
  std::vector<std::uint32_t> doubles;  // offsets of the double fields in a row, row order
  std::vector<std::uint32_t> bytes;    // offsets of observed_valid and each contact mode
};

Shape MakeShape(int contacts, int finger_values) {
  Shape s;
  s.contacts = contacts;
  s.finger_values = finger_values;
  std::uint32_t o = 0;
  s.bytes.push_back(o);  // observed_valid; the next 3 header bytes are implied by the shape
  o += 4;
  for (int i = 0; i < 27; ++i, o += 8) s.doubles.push_back(o);  // t, poses and twists
  for (int c = 0; c < contacts; ++c) {
    for (int i = 0; i < 6; ++i, o += 8) s.doubles.push_back(o);
    s.bytes.push_back(o);
    o += 1;
  }
  for (int i = 0; i < 13 + finger_values; ++i, o += 8) s.doubles.push_back(o);
  s.row = o;
  return s;
}

// Per-thread scratch that only grows (about 2.3 x the largest raw chunk
// packed on the thread: ~330 kB at 250 samples) and is never zero-filled:
// packing runs once per chunk on the ingest path, and clearing fresh buffers
// per chunk cost ~7 % of the ingest CPU.
template <typename T>
T* Scratch(std::unique_ptr<T[]>* buf, std::size_t* capacity, std::size_t n) {
  if (*capacity < n) {
    buf->reset(new T[n]);  // default-initialised: no fill
    *capacity = n;
  }
  return buf->get();
}

std::uint64_t Zigzag(std::uint64_t r) { return (r << 1) ^ (0 - (r >> 63)); }
std::uint64_t Unzigzag(std::uint64_t z) { return (z >> 1) ^ (0 - (z & 1)); }
int ByteLength(std::uint64_t z) { return (std::bit_width(z) + 7) / 8; }

// Residual of value i of a column under a predictor (wrapping arithmetic on
// the bit patterns: exact and invertible whatever the values are).
std::uint64_t Predict(unsigned char kind, const std::uint64_t* v, std::size_t i) {
  if (i == 0) return 0;
  if (kind == kDelta1 || i == 1) return v[i - 1];
  return 2 * v[i - 1] - v[i - 2];
}

}  // namespace

bool PackBlock(const void* agt1, std::size_t size, std::string* out) {
  const auto* in = static_cast<const unsigned char*>(agt1);
  if (size < kRawHeader || std::memcmp(in, kRawMagic, 4) != 0) return false;
  std::uint32_t count = 0;
  std::memcpy(&count, in + 4, 4);
  if (count == 0 || count > kMaxBlockSamples) return false;
  const unsigned char* rows = in + kRawHeader;
  const int contacts = rows[1], finger_values = rows[2];
  const Shape shape = MakeShape(contacts, finger_values);
  if (size != kRawHeader + count * shape.row || size > kMaxBlockBytes) return false;
  for (std::uint32_t i = 0; i < count; ++i) {  // uniform shape, valid flags: else keep AGT1
    const unsigned char* h = rows + i * shape.row;
    if (h[0] > 1 || h[1] != contacts || h[2] != finger_values || h[3] != 0) return false;
  }

  // Worst case: every column kind byte, every length nibble, 8 bytes per
  // value, plus 8 bytes of slack for the unconditional 8-byte stores below.
  const std::size_t worst = kPackedHeader + shape.bytes.size() * (1 + count) +
                            shape.doubles.size() * (1 + (count + 1) / 2 + 8 * std::size_t{count}) +
                            8;
  thread_local std::unique_ptr<unsigned char[]> bytes_buf;
  thread_local std::size_t bytes_capacity = 0;
  unsigned char* const base = Scratch(&bytes_buf, &bytes_capacity, worst);
  unsigned char* p = base;
  std::memcpy(p, kPackedMagic, 4);
  std::memcpy(p + 4, &count, 4);
  p[8] = static_cast<unsigned char>(contacts);
  p[9] = static_cast<unsigned char>(finger_values);
  p[10] = p[11] = 0;
  p += kPackedHeader;

  for (std::uint32_t off : shape.bytes) {
    const unsigned char first = rows[off];
    bool constant = true;
    for (std::uint32_t i = 1; i < count && constant; ++i)
      constant = rows[i * shape.row + off] == first;
    if (constant) {
      *p++ = kConstant;
      *p++ = first;
    } else {
      *p++ = kRaw;
      for (std::uint32_t i = 0; i < count; ++i) *p++ = rows[i * shape.row + off];
    }
  }

  // Transpose once, row by row, into column-major scratch (each row is read
  // sequentially; the column loops below then run over contiguous words).
  const std::size_t columns = shape.doubles.size();
  thread_local std::unique_ptr<std::uint64_t[]> words_buf;
  thread_local std::size_t words_capacity = 0;
  std::uint64_t* const matrix =
      Scratch(&words_buf, &words_capacity, (columns + 1) * std::size_t{count});
  std::uint64_t* const z = matrix + columns * count;
  for (std::uint32_t i = 0; i < count; ++i) {
    const unsigned char* r = rows + i * shape.row;
    for (std::size_t j = 0; j < columns; ++j)
      std::memcpy(&matrix[j * count + i], r + shape.doubles[j], 8);
  }
  for (std::size_t j = 0; j < columns; ++j) {
    const std::uint64_t* v = &matrix[j * count];
    std::uint32_t same = 1;  // most columns differ at once: stop there
    while (same < count && v[same] == v[0]) ++same;
    const bool constant = same == count;
    if (constant) {
      *p++ = kConstant;
      std::memcpy(p, &v[0], 8);
      p += 8;
      continue;
    }
    // Pick the predictor that leaves fewer bytes over the first 64 values
    // (a chunk's column is one signal: its start tells), then write all.
    std::size_t bytes1 = 0, bytes2 = 0;
    const std::uint32_t probe = count < 64 ? count : 64;
    for (std::uint32_t i = 2; i < probe; ++i) {
      bytes1 += static_cast<std::size_t>(ByteLength(Zigzag(v[i] - v[i - 1])));
      bytes2 += static_cast<std::size_t>(ByteLength(Zigzag(v[i] - 2 * v[i - 1] + v[i - 2])));
    }
    const unsigned char kind = bytes2 < bytes1 ? kDelta2 : kDelta1;
    z[0] = Zigzag(v[0]);
    if (count > 1) z[1] = Zigzag(v[1] - v[0]);
    if (kind == kDelta2) {
      for (std::uint32_t i = 2; i < count; ++i) z[i] = Zigzag(v[i] - 2 * v[i - 1] + v[i - 2]);
    } else {
      for (std::uint32_t i = 2; i < count; ++i) z[i] = Zigzag(v[i] - v[i - 1]);
    }
    *p++ = kind;
    unsigned char* lengths = p;
    p += (count + 1) / 2;
    for (std::uint32_t i = 0; i + 1 < count; i += 2) {
      const int n0 = ByteLength(z[i]), n1 = ByteLength(z[i + 1]);
      lengths[i / 2] = static_cast<unsigned char>(n0 | (n1 << 4));
      // All 8 bytes little-endian (the slack covers them); only n count.
      std::memcpy(p, &z[i], 8);
      p += n0;
      std::memcpy(p, &z[i + 1], 8);
      p += n1;
    }
    if (count % 2 == 1) {
      const int n = ByteLength(z[count - 1]);
      lengths[count / 2] = static_cast<unsigned char>(n);
      std::memcpy(p, &z[count - 1], 8);
      p += n;
    }
  }
  const std::size_t packed = static_cast<std::size_t>(p - base);
  if (packed >= size) return false;  // incompressible: AGT1 is smaller
  out->append(reinterpret_cast<const char*>(base), packed);
  return true;
}

std::string UnpackBlock(const void* agt2, std::size_t size) {
  const auto* in = static_cast<const unsigned char*>(agt2);
  const unsigned char* end = in + size;
  if (size < kPackedHeader || std::memcmp(in, kPackedMagic, 4) != 0)
    CorruptBlock("has a bad header");
  std::uint32_t count = 0;
  std::memcpy(&count, in + 4, 4);
  if (count == 0 || count > kMaxBlockSamples) {
    CorruptBlock("claims " + std::to_string(count) + " samples (allowed 1.." +
                 std::to_string(kMaxBlockSamples) + ")");
  }
  if (in[10] != 0 || in[11] != 0) CorruptBlock("has unknown flags");
  const Shape shape = MakeShape(in[8], in[9]);
  if (kRawHeader + std::size_t{count} * shape.row > kMaxBlockBytes) {
    CorruptBlock("would expand to more than " + std::to_string(kMaxBlockBytes >> 20) + " MiB");
  }
  const unsigned char* p = in + kPackedHeader;
  auto need = [&](std::size_t n) {
    if (static_cast<std::size_t>(end - p) < n) CorruptBlock("is truncated");
  };

  std::string raw(kRawHeader + std::size_t{count} * shape.row, '\0');
  auto* rows = reinterpret_cast<unsigned char*>(raw.data());
  std::memcpy(rows, kRawMagic, 4);
  std::memcpy(rows + 4, &count, 4);
  rows += kRawHeader;
  for (std::uint32_t i = 0; i < count; ++i) {
    rows[i * shape.row + 1] = static_cast<unsigned char>(shape.contacts);
    rows[i * shape.row + 2] = static_cast<unsigned char>(shape.finger_values);
  }

  for (std::uint32_t off : shape.bytes) {
    need(1);
    const unsigned char kind = *p++;
    if (kind == kConstant) {
      need(1);
      const unsigned char b = *p++;
      for (std::uint32_t i = 0; i < count; ++i) rows[i * shape.row + off] = b;
    } else if (kind == kRaw) {
      need(count);
      for (std::uint32_t i = 0; i < count; ++i) rows[i * shape.row + off] = *p++;
    } else {
      CorruptBlock("has an unknown byte-column kind " + std::to_string(kind));
    }
  }

  // Columns are decoded into a matrix, then written out row by row
  // (sequential writes; see PackBlock).
  const std::size_t columns = shape.doubles.size();
  std::vector<std::uint64_t> matrix(columns * count);
  for (std::size_t j = 0; j < columns; ++j) {
    std::uint64_t* v = &matrix[j * count];
    need(1);
    const unsigned char kind = *p++;
    if (kind == kConstant) {
      need(8);
      std::uint64_t c;
      std::memcpy(&c, p, 8);
      p += 8;
      for (std::uint32_t i = 0; i < count; ++i) v[i] = c;
      continue;
    }
    if (kind != kDelta1 && kind != kDelta2)
      CorruptBlock("has an unknown column kind " + std::to_string(kind));
    need((count + 1) / 2);
    const unsigned char* lengths = p;
    p += (count + 1) / 2;
    for (std::uint32_t i = 0; i < count; ++i) {
      const int n = (lengths[i / 2] >> (4 * (i % 2))) & 0xF;
      if (n > 8) CorruptBlock("has a residual of " + std::to_string(n) + " bytes");
      need(static_cast<std::size_t>(n));
      std::uint64_t z = 0;
      if (end - p >= 8) {  // one load, then drop the bytes that are not this value's
        std::memcpy(&z, p, 8);
        if (n < 8) z &= (std::uint64_t{1} << (8 * n)) - 1;
      } else {
        for (int b = 0; b < n; ++b) z |= std::uint64_t{p[b]} << (8 * b);
      }
      p += n;
      v[i] = Unzigzag(z) + Predict(kind, v, i);
    }
  }
  if (p != end) CorruptBlock("has trailing bytes");
  for (std::uint32_t i = 0; i < count; ++i) {
    unsigned char* r = rows + i * shape.row;
    for (std::size_t j = 0; j < columns; ++j)
      std::memcpy(r + shape.doubles[j], &matrix[j * count + i], 8);
  }
  return raw;
}

}  // namespace arena::db
