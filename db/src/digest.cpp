// SHA-256 of the export's files through OpenSSL's EVP digest (libcrypto is
// already linked for DDS-Security; no hand-written hash to maintain).
#include <openssl/evp.h>

#include <array>
#include <cstdio>
#include <fstream>
#include <memory>

#include "arena/db/export.hpp"

namespace arena::db {
namespace {

using Ctx = std::unique_ptr<EVP_MD_CTX, decltype(&EVP_MD_CTX_free)>;

Ctx NewSha256() {
  Ctx ctx(EVP_MD_CTX_new(), &EVP_MD_CTX_free);
  if (!ctx || EVP_DigestInit_ex(ctx.get(), EVP_sha256(), nullptr) != 1) {
    throw StoreError(StoreError::Kind::kIo, "sha256: OpenSSL cannot start a SHA-256 digest");
  }
  return ctx;
}

std::string Finish(EVP_MD_CTX* ctx) {
  std::array<unsigned char, EVP_MAX_MD_SIZE> md{};
  unsigned int len = 0;
  if (EVP_DigestFinal_ex(ctx, md.data(), &len) != 1) {
    throw StoreError(StoreError::Kind::kIo, "sha256: OpenSSL cannot finish the digest");
  }
  std::string hex;
  hex.reserve(2 * len);
  char buf[3];
  for (unsigned int i = 0; i < len; ++i) {
    std::snprintf(buf, sizeof buf, "%02x", md[i]);
    hex += buf;
  }
  return hex;
}

}  // namespace

std::string Sha256Hex(const void* data, std::size_t size) {
  Ctx ctx = NewSha256();
  if (EVP_DigestUpdate(ctx.get(), data, size) != 1) {
    throw StoreError(StoreError::Kind::kIo, "sha256: OpenSSL digest update failed");
  }
  return Finish(ctx.get());
}

std::string Sha256File(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw StoreError(StoreError::Kind::kIo, "sha256: cannot read '" + path + "'");
  Ctx ctx = NewSha256();
  std::array<char, 1 << 16> buf{};
  while (in) {
    in.read(buf.data(), buf.size());
    const auto n = in.gcount();
    if (n > 0 && EVP_DigestUpdate(ctx.get(), buf.data(), static_cast<std::size_t>(n)) != 1) {
      throw StoreError(StoreError::Kind::kIo, "sha256: OpenSSL digest update failed");
    }
  }
  if (in.bad()) throw StoreError(StoreError::Kind::kIo, "sha256: cannot read '" + path + "'");
  return Finish(ctx.get());
}

}  // namespace arena::db
