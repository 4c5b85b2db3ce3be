// A corrupt store is never written into: every writing command refuses it
// when it opens the file (exit 3, the reason), and `arena serve` stops with
// exit 3 when its periodic quick check finds damage that appeared while it
// served. Real files garbled on disk, real processes.
#include <sqlite3.h>

#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "service_support.hpp"

namespace arena::test {
namespace {

// Overwrites the cell-pointer array of the first leaf page of `table` (what a
// torn write or a bad sector leaves): the page of its first rows, which
// nothing in a running service reads again, so SQLite goes on appending to
// the file without a word; quick_check reports the page.
void GarbleFirstLeaf(const std::string& db, const std::string& table) {
  sqlite3* h = nullptr;
  ASSERT_EQ(sqlite3_open(db.c_str(), &h), SQLITE_OK);
  sqlite3_stmt* s = nullptr;
  ASSERT_EQ(sqlite3_prepare_v2(h, "PRAGMA wal_checkpoint(TRUNCATE)", -1, &s, nullptr), SQLITE_OK);
  while (sqlite3_step(s) == SQLITE_ROW) {
  }
  sqlite3_finalize(s);
  const std::string q = "SELECT rootpage FROM sqlite_master WHERE name = '" + table + "'";
  ASSERT_EQ(sqlite3_prepare_v2(h, q.c_str(), -1, &s, nullptr), SQLITE_OK);
  ASSERT_EQ(sqlite3_step(s), SQLITE_ROW);
  std::int64_t page = sqlite3_column_int(s, 0);
  sqlite3_finalize(s);
  ASSERT_EQ(sqlite3_prepare_v2(h, "PRAGMA page_size", -1, &s, nullptr), SQLITE_OK);
  ASSERT_EQ(sqlite3_step(s), SQLITE_ROW);
  const std::int64_t page_size = sqlite3_column_int(s, 0);
  sqlite3_finalize(s);
  sqlite3_close(h);
  ASSERT_GT(page, 1);
  std::fstream f(db, std::ios::in | std::ios::out | std::ios::binary);
  auto byte = [&](std::int64_t at) {
    f.seekg(at);
    return static_cast<unsigned char>(f.get());
  };
  // Down the leftmost branch: an interior table page (0x05) holds cell
  // pointers from byte 12; each cell starts with its left child's number.
  for (int depth = 0; byte((page - 1) * page_size) == 0x05 && depth < 8; ++depth) {
    const std::int64_t base = (page - 1) * page_size;
    const std::int64_t cell = byte(base + 12) << 8 | byte(base + 13);
    page = static_cast<std::int64_t>(byte(base + cell)) << 24 | byte(base + cell + 1) << 16 |
           byte(base + cell + 2) << 8 | byte(base + cell + 3);
  }
  ASSERT_EQ(byte((page - 1) * page_size), 0x0D) << "not a table leaf";
  f.seekp((page - 1) * page_size + 8);  // a leaf's cell pointers start at byte 8
  const std::string junk(64, '\xee');
  f.write(junk.data(), static_cast<std::streamsize>(junk.size()));
  ASSERT_TRUE(f.good());
}

std::string Sha(const std::string& path) { return ReadFile(path); }  // small files: compare bytes

class StoreIntegrity : public ::testing::Test {
 protected:
  void SetUp() override {
    db_ = dir_ / "lab.db";
    ASSERT_EQ(RunArena({"submit", TestCampaign("e2e60.json"), "--db", db_}, dir_ / "submit.out",
                       std::chrono::seconds(30)),
              0)
        << ReadFile(dir_ / "submit.out");
  }
  TempDir dir_;
  std::string db_;
};

TEST_F(StoreIntegrity, EveryWritingCommandRefusesACorruptStoreAndWritesNothing) {
  GarbleFirstLeaf(db_, "trials");
  const std::string before = Sha(db_);
  const std::string domain = std::to_string(TestDomain(31));
  struct Case {
    std::vector<std::string> args;
  };
  const std::vector<Case> cases = {
      {{"serve", "--db", db_, "--domain", domain}},
      {{"submit", TestCampaign("e2e60.json"), "--db", db_}},
      {{"pause", "1", "--db", db_}},
      {{"cancel", "1", "--db", db_}},
      {{"cells", "release", "c1", "--db", db_}},
      {{"evaluate", "--db", db_, "--campaign", "1"}},
  };
  int refused = 0;
  for (const auto& c : cases) {
    const std::string out = dir_ / ("cmd" + std::to_string(refused) + ".out");
    const int rc = RunArena(c.args, out, std::chrono::seconds(60));
    EXPECT_EQ(rc, 3) << c.args[0] << ": " << ReadFile(out);
    EXPECT_NE(ReadFile(out).find("corrupt"), std::string::npos)
        << c.args[0] << ": " << ReadFile(out);
    refused += rc == 3;
    EXPECT_EQ(Sha(db_), before) << c.args[0] << " wrote into the corrupt store";
  }
  EXPECT_FALSE(std::filesystem::exists(db_ + "-wal") &&
               std::filesystem::file_size(db_ + "-wal") > 0);
  std::printf("corrupt store: %d of %zu writing commands refused it (exit 3)\n", refused,
              cases.size());
}

TEST_F(StoreIntegrity, ServeStopsWhenTheStoreIsDamagedWhileServing) {
  const std::string domain = std::to_string(TestDomain(32));
  // No cell on the domain: the trials stay planned, the service beats.
  auto serve =
      StartArena({"serve", "--db", db_, "--domain", domain, "--integrity-check-period", "0.5"},
                 dir_ / "serve.out");
  ASSERT_TRUE(WaitUntil(
      [&] {
        auto s = OpenReadOnly(db_);
        return s->LatestService().has_value();
      },
      std::chrono::seconds(30)))
      << ReadFile(dir_ / "serve.out");
  std::this_thread::sleep_for(std::chrono::seconds(1));
  EXPECT_FALSE(serve->Wait(std::chrono::milliseconds(10)).has_value())
      << "a sound store stopped it";
  GarbleFirstLeaf(db_, "trials");
  const auto st = serve->Wait(std::chrono::seconds(20));
  ASSERT_TRUE(st.has_value()) << "serve kept running on a corrupt store: "
                              << ReadFile(dir_ / "serve.out");
  EXPECT_TRUE(WIFEXITED(*st) && WEXITSTATUS(*st) == 3) << ReadFile(dir_ / "serve.out");
  EXPECT_NE(ReadFile(dir_ / "serve.out").find("corrupt"), std::string::npos)
      << ReadFile(dir_ / "serve.out");
}

}  // namespace
}  // namespace arena::test
