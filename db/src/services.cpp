// The store's service records (one service per store, its heartbeat) and the
// check that the file opened is still the file at its path. Tables:
// db/README.md (services, store_meta).
#include <sys/stat.h>

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <cstring>
#include <stdexcept>
#include <string>
#include <thread>

#include "arena/db/store.hpp"
#include "sqlite_util.hpp"

namespace arena::db {

using detail::Tx;

namespace {
constexpr const char* kServiceCols =
    "SELECT session, pid, host, domain, started_at, last_beat, stopped_at FROM services";

ServiceRecord ReadService(const detail::Stmt& s) {
  ServiceRecord r;
  r.session = s.Text(0);
  r.pid = s.Int(1);
  r.host = s.Text(2);
  r.domain = static_cast<int>(s.Int(3));
  r.started_at = s.Real(4);
  r.last_beat = s.Real(5);
  if (!s.IsNull(6)) r.stopped_at = s.Real(6);
  return r;
}
}  // namespace

std::string Store::StoreId() const {
  auto s = impl_->Prepare("SELECT value FROM store_meta WHERE key = 'store_id'");
  return s->Step() ? s->Text(0) : std::string();
}

std::optional<ServiceRecord> Store::RegisterService(
    const ServiceRecord& me, double fresh_s,
    const std::function<bool(const ServiceRecord&)>& holder_alive) {
  impl_->RequireWritable("RegisterService");
  if (me.session.empty() || me.host.empty())
    throw StoreError(StoreError::Kind::kBadInput, "RegisterService: session and host are needed");
  Tx tx(impl_->db, true);  // two services starting at once: one of them waits here, then sees
  const double now = impl_->Now();
  auto q = impl_->Prepare(std::string(kServiceCols) +
                          " WHERE stopped_at IS NULL AND last_beat > ? AND session <> ?"
                          " ORDER BY last_beat DESC");
  q->Bind(1, now - fresh_s).Bind(2, me.session);
  while (q->Step()) {
    ServiceRecord other = ReadService(*q);
    if (!holder_alive || holder_alive(other)) return other;  // rolled back: nothing written
  }
  auto s = impl_->Prepare(
      "INSERT INTO services(session, pid, host, domain, started_at, last_beat) "
      "VALUES(?1,?2,?3,?4,?5,?5)");
  s->Bind(1, me.session).Bind(2, me.pid).Bind(3, me.host).Bind(4, me.domain).Bind(5, now).Run();
  tx.Commit();
  return std::nullopt;
}

void Store::ServiceBeat(const std::string& session, const std::vector<std::string>& cells_alive) {
  impl_->RequireWritable("ServiceBeat");
  Tx tx(impl_->db, true);
  const double now = impl_->Now();
  auto s = impl_->Prepare("UPDATE services SET last_beat = ? WHERE session = ?");
  s->Bind(1, now).Bind(2, session).Run();
  auto c = impl_->Prepare("UPDATE cells SET last_seen = ? WHERE id = ?");
  for (const auto& id : cells_alive) {
    c->Bind(1, now).Bind(2, id).Run();
    c->Reset();
  }
  tx.Commit();
}

void Store::ServiceStopped(const std::string& session) {
  impl_->RequireWritable("ServiceStopped");
  auto s = impl_->Prepare("UPDATE services SET stopped_at = ?1, last_beat = ?1 WHERE session = ?2");
  s->Bind(1, impl_->Now()).Bind(2, session).Run();
}

std::optional<ServiceRecord> Store::LatestService() const {
  auto s =
      impl_->Prepare(std::string(kServiceCols) + " ORDER BY started_at DESC, rowid DESC LIMIT 1");
  if (!s->Step()) return std::nullopt;
  return ReadService(*s);
}

void Store::SetBusyTimeout(int ms) {
  if (ms < 0)
    throw std::invalid_argument("busy timeout: must be >= 0 ms, got " + std::to_string(ms));
  sqlite3_busy_timeout(impl_->db, ms);
  impl_->options.busy_timeout_ms = ms;
}

void Store::CheckFileIdentity() const {
  struct stat st {};
  if (::stat(impl_->path.c_str(), &st) != 0) {
    const int err = errno;
    throw StoreError(StoreError::Kind::kIo, "the store '" + impl_->path +
                                                "' was deleted or renamed while in use (" +
                                                std::strerror(err) + ")");
  }
  if (impl_->file_ino != 0 && (static_cast<unsigned long long>(st.st_ino) != impl_->file_ino ||
                               static_cast<unsigned long long>(st.st_dev) != impl_->file_dev)) {
    throw StoreError(StoreError::Kind::kIo,
                     "the store '" + impl_->path + "' was replaced by another file while in use");
  }
}

void RetryWhileBusy(const std::function<void()>& write,
                    const std::function<bool(double, const std::string&)>& on_wait) {
  const auto start = std::chrono::steady_clock::now();
  double pause_s = 0.1;
  for (;;) {
    try {
      write();
      return;
    } catch (const StoreError& e) {
      if (e.kind() != StoreError::Kind::kBusy) throw;
      const double waited =
          std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
      if (on_wait && !on_wait(waited, e.what())) throw;
    }
    std::this_thread::sleep_for(std::chrono::duration<double>(pause_s));
    pause_s = std::min(2.0, pause_s * 2);
  }
}

}  // namespace arena::db
