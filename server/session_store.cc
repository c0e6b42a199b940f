#include "server/session_store.h"

#include <algorithm>
#include <random>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"

namespace rpsr::server {
namespace {

// How many gone clouds and sessions are remembered for precise NOT_FOUND messages. A few
// hundred kilobytes at most; older ones get the generic message.
constexpr size_t kRememberedClouds = 65536;
constexpr size_t kRememberedSessions = 4096;

std::string Seconds(absl::Duration d) {
  return absl::StrFormat("%.3g s", absl::ToDoubleSeconds(d));
}

}  // namespace

SessionStore::SessionStore(const CacheOptions& options, SessionStoreHooks hooks, Clock clock)
    : options_(options),
      hooks_(std::move(hooks)),
      clock_(clock ? std::move(clock) : Clock([] { return absl::Now(); })) {}

std::string SessionStore::NewSessionIdLocked() {
  // 128 bits from the OS's random source: ids are capabilities (without authentication, holding
  // the id is what grants use of a session), so they must not be guessable.
  std::random_device random;
  for (;;) {
    std::string id;
    for (int i = 0; i < 4; ++i) absl::StrAppendFormat(&id, "%08x", random());
    if (!sessions_.contains(id) && !gone_sessions_.contains(id)) return id;
  }
}

absl::StatusOr<std::string> SessionStore::CreateSession(const SessionSettings& settings) {
  absl::MutexLock lock(&mu_);
  const absl::Time now = clock_();
  ExpireLocked(now);
  if (sessions_.size() >= options_.max_sessions) {
    return absl::ResourceExhaustedError(
        absl::StrCat("the server holds the most sessions it may (", options_.max_sessions,
                     "); close sessions you no longer use, or retry when idle ones have expired"));
  }
  std::string id = NewSessionIdLocked();
  Session& session = sessions_[id];
  session.settings = settings;
  session.last_used = now;
  ReportOccupancyLocked();
  return id;
}

absl::StatusOr<SessionStore::Session*> SessionStore::FindLocked(absl::string_view session_id,
                                                                absl::string_view caller,
                                                                absl::Time now) {
  if (session_id.empty()) {
    return absl::InvalidArgumentError("no session id given; create one with CreateSession");
  }
  auto it = sessions_.find(session_id);
  if (it != sessions_.end() && now - it->second.last_used > it->second.settings.ttl) {
    // Expired but not yet swept: expire it now so the answer says so.
    ++sessions_expired_;
    RemoveSessionLocked(it, "session_expired",
                        absl::StrCat("expired (unused for longer than its time to live of ",
                                     Seconds(it->second.settings.ttl), ")"));
    it = sessions_.end();
  }
  if (it == sessions_.end()) {
    auto gone = gone_sessions_.find(session_id);
    if (gone != gone_sessions_.end()) {
      return absl::NotFoundError(absl::StrCat("session ", session_id, " ", gone->second,
                                              "; create a new session and upload again"));
    }
    return absl::NotFoundError(absl::StrCat("session ", session_id,
                                            " is unknown to this server (never created here, "
                                            "or gone long ago); create a session first"));
  }
  if (it->second.settings.owner != caller) {
    return absl::PermissionDeniedError(
        absl::StrCat("session ", session_id, " belongs to another client"));
  }
  it->second.last_used = now;
  return &it->second;
}

absl::StatusOr<size_t> SessionStore::CloseSession(absl::string_view session_id,
                                                  absl::string_view caller) {
  absl::MutexLock lock(&mu_);
  const absl::Time now = clock_();
  absl::StatusOr<Session*> session = FindLocked(session_id, caller, now);
  if (!session.ok()) return session.status();
  const size_t clouds = (*session)->clouds.size();
  RemoveSessionLocked(sessions_.find(session_id), "session_closed", "was closed");
  return clouds;
}

absl::StatusOr<SessionSettings> SessionStore::UseSession(absl::string_view session_id,
                                                         absl::string_view caller) {
  absl::MutexLock lock(&mu_);
  absl::StatusOr<Session*> session = FindLocked(session_id, caller, clock_());
  if (!session.ok()) return session.status();
  return (*session)->settings;
}

absl::StatusOr<uint64_t> SessionStore::AddCloud(absl::string_view session_id,
                                                absl::string_view caller,
                                                std::shared_ptr<const core::Octree> tree) {
  if (tree == nullptr) return absl::InvalidArgumentError("AddCloud: no tree");
  const uint64_t bytes = tree->MemoryBytes();
  absl::MutexLock lock(&mu_);
  const absl::Time now = clock_();
  ExpireLocked(now);
  absl::StatusOr<Session*> found = FindLocked(session_id, caller, now);
  if (!found.ok()) return found.status();
  Session& session = **found;
  if (session.clouds.size() >= options_.max_clouds_per_session) {
    return absl::ResourceExhaustedError(absl::StrCat(
        "session ", session_id, " holds the most clouds it may (", options_.max_clouds_per_session,
        "); release clouds you no longer need (ReleaseCloud) or use another session"));
  }
  if (bytes > options_.memory_budget_bytes) {
    return absl::ResourceExhaustedError(absl::StrCat(
        "the cloud's tree takes ", bytes, " bytes, more than the server's whole cache (",
        options_.memory_budget_bytes, " bytes); use a smaller tree depth or fewer points"));
  }
  // Evict least recently used clouds (of any session, this one's included) until it fits.
  while (bytes_ + bytes > options_.memory_budget_bytes && !lru_.empty()) {
    const auto [victim_session, victim_cloud] = lru_.back();
    ++evicted_for_memory_;
    RemoveCloudLocked(sessions_.at(victim_session), victim_cloud, "memory_budget",
                      "was evicted (memory budget)");
  }
  const uint64_t id = next_cloud_id_++;
  lru_.emplace_front(std::string(session_id), id);
  Cloud& cloud = session.clouds[id];
  cloud.tree = std::move(tree);
  cloud.bytes = bytes;
  cloud.lru = lru_.begin();
  cloud_owner_[id] = std::string(session_id);
  bytes_ += bytes;
  ReportOccupancyLocked();
  return id;
}

absl::StatusOr<std::shared_ptr<const core::Octree>> SessionStore::GetCloud(
    absl::string_view session_id, absl::string_view caller, uint64_t cloud_id) {
  absl::MutexLock lock(&mu_);
  absl::StatusOr<Session*> found = FindLocked(session_id, caller, clock_());
  if (!found.ok()) return found.status();
  Session& session = **found;
  auto it = session.clouds.find(cloud_id);
  if (it != session.clouds.end()) {
    ++hits_;
    if (hooks_.hit) hooks_.hit();
    lru_.splice(lru_.begin(), lru_, it->second.lru);
    return it->second.tree;
  }
  ++misses_;
  if (hooks_.miss) hooks_.miss();
  auto owner = cloud_owner_.find(cloud_id);
  if (owner != cloud_owner_.end()) {
    return absl::PermissionDeniedError(
        absl::StrCat("cloud ", cloud_id, " belongs to another session, not to ", session_id));
  }
  auto gone = gone_clouds_.find(cloud_id);
  if (gone != gone_clouds_.end()) {
    if (gone->second.session_id != session_id) {
      return absl::PermissionDeniedError(
          absl::StrCat("cloud ", cloud_id, " belonged to another session, not to ", session_id));
    }
    return absl::NotFoundError(absl::StrCat("cloud ", cloud_id, " of session ", session_id, " ",
                                            gone->second.reason, "; upload it again"));
  }
  if (cloud_id == 0 || cloud_id >= next_cloud_id_) {
    return absl::NotFoundError(absl::StrCat("cloud ", cloud_id, " was never uploaded (session ",
                                            session_id, "); upload it first"));
  }
  return absl::NotFoundError(absl::StrCat("cloud ", cloud_id, " is not held by session ",
                                          session_id, " (gone long ago); upload it again"));
}

absl::Status SessionStore::ReleaseCloud(absl::string_view session_id, absl::string_view caller,
                                        uint64_t cloud_id) {
  absl::MutexLock lock(&mu_);
  absl::StatusOr<Session*> found = FindLocked(session_id, caller, clock_());
  if (!found.ok()) return found.status();
  Session& session = **found;
  if (!session.clouds.contains(cloud_id)) {
    auto gone = gone_clouds_.find(cloud_id);
    if (gone != gone_clouds_.end() && gone->second.session_id == session_id) {
      return absl::NotFoundError(
          absl::StrCat("cloud ", cloud_id, " of session ", session_id, " ", gone->second.reason));
    }
    return absl::NotFoundError(
        absl::StrCat("cloud ", cloud_id, " is not held by session ", session_id));
  }
  RemoveCloudLocked(session, cloud_id, "released", "was released");
  ReportOccupancyLocked();
  return absl::OkStatus();
}

size_t SessionStore::ExpireIdleSessions() {
  absl::MutexLock lock(&mu_);
  return ExpireLocked(clock_());
}

size_t SessionStore::ExpireLocked(absl::Time now) {
  size_t expired = 0;
  for (auto it = sessions_.begin(); it != sessions_.end();) {
    auto next = std::next(it);
    if (now - it->second.last_used > it->second.settings.ttl) {
      ++expired;
      ++sessions_expired_;
      RemoveSessionLocked(it, "session_expired",
                          absl::StrCat("expired (unused for longer than its time to live of ",
                                       Seconds(it->second.settings.ttl), ")"));
    }
    it = next;
  }
  return expired;
}

void SessionStore::RemoveCloudLocked(Session& session, uint64_t cloud_id, absl::string_view reason,
                                     const std::string& why) {
  auto it = session.clouds.find(cloud_id);
  if (it == session.clouds.end()) return;
  const uint64_t bytes = it->second.bytes;
  std::string session_id = it->second.lru->first;
  lru_.erase(it->second.lru);
  session.clouds.erase(it);
  cloud_owner_.erase(cloud_id);
  bytes_ -= bytes;
  if (hooks_.evicted) hooks_.evicted(reason, bytes);
  RememberCloudLocked(cloud_id, Gone{std::move(session_id), why});
  ReportOccupancyLocked();
}

void SessionStore::RemoveSessionLocked(absl::flat_hash_map<std::string, Session>::iterator it,
                                       absl::string_view cloud_reason, const std::string& why) {
  Session& session = it->second;
  std::vector<uint64_t> ids;
  ids.reserve(session.clouds.size());
  for (const auto& [id, cloud] : session.clouds) ids.push_back(id);
  const std::string cloud_why = absl::StrCat("is gone: its session ", why);
  for (uint64_t id : ids) RemoveCloudLocked(session, id, cloud_reason, cloud_why);
  RememberSessionLocked(it->first, why);
  sessions_.erase(it);
  ReportOccupancyLocked();
}

void SessionStore::RememberCloudLocked(uint64_t cloud_id, Gone gone) {
  if (gone_clouds_.insert_or_assign(cloud_id, std::move(gone)).second) {
    gone_cloud_order_.push_back(cloud_id);
  }
  while (gone_cloud_order_.size() > kRememberedClouds) {
    gone_clouds_.erase(gone_cloud_order_.front());
    gone_cloud_order_.pop_front();
  }
}

void SessionStore::RememberSessionLocked(const std::string& session_id, std::string reason) {
  if (gone_sessions_.insert_or_assign(session_id, std::move(reason)).second) {
    gone_session_order_.push_back(session_id);
  }
  while (gone_session_order_.size() > kRememberedSessions) {
    gone_sessions_.erase(gone_session_order_.front());
    gone_session_order_.pop_front();
  }
}

void SessionStore::ReportOccupancyLocked() {
  if (hooks_.occupancy) hooks_.occupancy(sessions_.size(), cloud_owner_.size(), bytes_);
}

SessionStoreStats SessionStore::stats() const {
  absl::MutexLock lock(&mu_);
  SessionStoreStats stats;
  stats.sessions = sessions_.size();
  stats.clouds = cloud_owner_.size();
  stats.bytes = bytes_;
  stats.hits = hits_;
  stats.misses = misses_;
  stats.evicted_for_memory = evicted_for_memory_;
  stats.sessions_expired = sessions_expired_;
  return stats;
}

}  // namespace rpsr::server
