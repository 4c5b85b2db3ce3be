// arena query's engine: read-only SQL, filter shortcuts, output formats.
#include <nlohmann/json.hpp>

#include "arena/db/query.hpp"
#include "db_test_util.hpp"

namespace arena::db {
namespace {

using testing::MakeCampaign;
using testing::MakeTrials;
using testing::RunTrialToDone;
using testing::TempDir;

class QueryTest : public ::testing::Test {
 protected:
  void SetUp() override {
    path_ = dir_.File("q.db");
    auto store = Store::Open(path_);
    store->UpsertCell("c", {"point", "line"});
    store->CreateCampaign(MakeCampaign("one"), MakeTrials(6));
    store->CreateCampaign(MakeCampaign("two"), MakeTrials(3, "line"));
    for (int i = 0; i < 4; ++i) {
      auto t = store->ClaimNextTrial("c");
      RunTrialToDone(*store, *t, 20);
    }
    auto t = store->ClaimNextTrial("c");
    store->FailTrial(t->trial_id, t->attempt, "refused by cell", arena::db::TrialEnd::kRefused);
    StoreOptions ro;
    ro.read_only = true;
    ro_ = Store::Open(path_, ro);
  }
  TempDir dir_;
  std::string path_;
  std::unique_ptr<Store> ro_;
};

TEST_F(QueryTest, SelectReturnsColumnsAndTypedValues) {
  const auto r = RunQuery(
      *ro_, "SELECT id, name, priority, 0.5 AS half, NULL AS none_ FROM campaigns ORDER BY id");
  ASSERT_EQ(r.columns, (std::vector<std::string>{"id", "name", "priority", "half", "none_"}));
  ASSERT_EQ(r.rows.size(), 2u);
  EXPECT_EQ(std::get<std::int64_t>(r.rows[0][0]), 1);
  EXPECT_EQ(std::get<std::string>(r.rows[1][1]), "two");
  EXPECT_EQ(std::get<double>(r.rows[0][3]), 0.5);
  EXPECT_TRUE(std::holds_alternative<std::monostate>(r.rows[0][4]));
}

TEST_F(QueryTest, FilterShortcutsCompose) {
  QueryFilter f;
  f.campaign_id = 1;
  f.where = "grip_force > 6.5";
  const auto r = RunQuery(*ro_, "", f);  // default: trial_results
  EXPECT_EQ(r.rows.size(), 4u);          // grip 7, 8, 9, 10 of campaign 1
  QueryFilter g;
  g.outcome = "refused";
  const auto refused = RunQuery(*ro_, "SELECT trial_id, outcome FROM trial_results", g);
  ASSERT_EQ(refused.rows.size(), 1u);
  EXPECT_EQ(std::get<std::int64_t>(refused.rows[0][0]), 5);
  QueryFilter h;
  h.outcome = "x' OR 1=1 --";  // bound, never spliced
  EXPECT_TRUE(RunQuery(*ro_, "", h).rows.empty());
  EXPECT_EQ(ComposeQuery("SELECT 1;", {}), "SELECT 1");
}

TEST_F(QueryTest, WritesAreRefused) {
  for (const char* sql :
       {"DELETE FROM trials", "UPDATE campaigns SET state = 'paused'",
        "INSERT INTO cells(id, last_seen, created_at, updated_at) VALUES('x',0,0,0)",
        "DROP TABLE trials", "CREATE TABLE x(a)", "PRAGMA user_version = 7",
        "PRAGMA query_only = 0", "ATTACH DATABASE 'other.db' AS o", "VACUUM"}) {
    try {
      RunQuery(*ro_, sql);
      ADD_FAILURE() << "not refused: " << sql;
    } catch (const StoreError& e) {
      EXPECT_TRUE(e.kind() == StoreError::Kind::kReadOnly ||
                  e.kind() == StoreError::Kind::kBadInput)
          << sql << ": " << e.what();
    }
  }
  EXPECT_THROW(RunQuery(*ro_, "SELECT 1; DELETE FROM trials"), StoreError);
  EXPECT_THROW(RunQuery(*ro_, "SELEC nonsense"), StoreError);
  // A read-write store is refused outright.
  auto rw = Store::Open(path_);
  EXPECT_THROW(RunQuery(*rw, "SELECT 1"), StoreError);
  // Nothing changed.
  EXPECT_EQ(RunQuery(*ro_, "SELECT COUNT(*) FROM trials").rows[0][0], Value(std::int64_t{9}));
  EXPECT_EQ(RunQuery(*ro_, "PRAGMA user_version").rows[0][0],
            Value(std::int64_t{Store::SchemaVersion()}));
}

// fts3_tokenizer('simple') returns the address of SQLite's tokenizer module
// (and with a second argument would install one): an attack primitive that
// SELECT alone reaches. The authorizer refuses such functions by name.
TEST_F(QueryTest, FunctionsThatTouchMemoryOrFilesAreRefused) {
  for (const char* sql :
       {"SELECT fts3_tokenizer('simple')", "SELECT hex(fts3_tokenizer('simple'))",
        "SELECT FTS3_Tokenizer('porter')", "SELECT load_extension('/tmp/x.so')",
        "SELECT fts5(NULL)", "SELECT name FROM campaigns WHERE fts3_tokenizer('simple') IS NULL",
        "SELECT sqlite_compileoption_get(0)", "SELECT readfile('/etc/passwd')"}) {
    try {
      const auto r = RunQuery(*ro_, sql);
      ADD_FAILURE() << "not refused: " << sql;
    } catch (const StoreError& e) {
      EXPECT_EQ(e.kind(), StoreError::Kind::kBadInput) << sql;
      const std::string what = e.what();
      // Refused by the authorizer, not merely unknown to this SQLite.
      if (std::string(sql).find("readfile") == std::string::npos) {
        EXPECT_NE(what.find("not authorized"), std::string::npos) << sql << ": " << what;
      }
    }
  }
  // Functions that only compute on their arguments still work.
  const auto r = RunQuery(*ro_,
                          "SELECT abs(-2), printf('%d', 3), json_extract('{\"a\":1}', '$.a'), "
                          "length(sqlite_version()) > 0, count(*) FROM campaigns");
  ASSERT_EQ(r.rows.size(), 1u);
  EXPECT_EQ(r.rows[0][0], Value(std::int64_t{2}));
  EXPECT_EQ(r.rows[0][4], Value(std::int64_t{2}));
}

TEST_F(QueryTest, FormatsTableCsvJson) {
  const auto r =
      RunQuery(*ro_, "SELECT id, name, 0.1 + 0.2 AS x, 'a,\"b\"' AS q FROM campaigns ORDER BY id");
  const std::string table = FormatTable(r);
  EXPECT_NE(table.find("id  name"), std::string::npos) << table;
  EXPECT_NE(table.find("(2 rows)"), std::string::npos);
  const std::string csv = FormatCsv(r);
  EXPECT_EQ(csv.substr(0, csv.find('\n')), "id,name,x,q");
  EXPECT_NE(csv.find("1,one,0.30000000000000004,\"a,\"\"b\"\"\""), std::string::npos) << csv;
  const auto j = nlohmann::json::parse(FormatJson(r));
  ASSERT_EQ(j.size(), 2u);
  EXPECT_EQ(j[1]["name"], "two");
  EXPECT_EQ(j[0]["x"].get<double>(), 0.1 + 0.2);
}

TEST_F(QueryTest, DriftViewAndSummaryAreQueryable) {
  const auto d = RunQuery(*ro_, "SELECT campaign_id, cell_id, trials FROM start_state_drift");
  // Trials 1..4 have the start their streams measured, trial 5 (claimed, not
  // run) the one the reset before it observed.
  ASSERT_EQ(d.rows.size(), 1u);
  EXPECT_EQ(d.rows[0][2], Value(std::int64_t{5}));
  const auto s = RunQuery(*ro_, "SELECT samples FROM gt_summary");
  EXPECT_EQ(s.rows.size(), 4u);
}

}  // namespace
}  // namespace arena::db
