// Naming a place in a JSON document in an error message ("fingers[1].mu"),
// shared by the scene reader and the campaign reader so both speak alike.
// Everything taken from the input is made printable ASCII and bounded: an
// error message must itself be valid UTF-8 and safe to print.
#pragma once

#include <array>
#include <charconv>
#include <cmath>
#include <cstddef>
#include <string>
#include <string_view>

namespace arena::mechanics::json_path {

// Shortest text that reads back to the same double ("-0.2", "1e-09").
inline std::string Num(double value) {
  if (std::isnan(value)) return "NaN";
  if (std::isinf(value)) return value > 0 ? "Infinity" : "-Infinity";
  std::array<char, 32> buf{};
  const auto res = std::to_chars(buf.data(), buf.data() + buf.size(), value);
  return std::string(buf.data(), res.ptr);
}

// Input text in a message: non-printable bytes become '?', at most max_bytes.
inline std::string Printable(std::string_view text, std::size_t max_bytes) {
  std::string out;
  for (std::size_t i = 0; i < text.size() && i < max_bytes; ++i) {
    const unsigned char c = static_cast<unsigned char>(text[i]);
    out += (c < 0x20 || c >= 0x7f) ? '?' : static_cast<char>(c);
  }
  if (text.size() > max_bytes) out += "...";
  return out;
}

// path.key (keys are user input too).
inline std::string Join(const std::string& path, std::string_view key) {
  const std::string safe = Printable(key, 64);
  return path.empty() ? safe : path + "." + safe;
}

// path[i]
inline std::string Index(const std::string& path, std::size_t i) {
  return path + "[" + std::to_string(i) + "]";
}

}  // namespace arena::mechanics::json_path
