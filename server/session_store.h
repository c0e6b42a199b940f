// The per-session tree cache (issue 6): a cloud's Barnes-Hut tree is built once at upload and
// kept here, not its points, so a client can register it many times without sending it again.
//
// Sessions group a client's clouds with their own tree depth and time to live; the memory of all
// trees together is bounded by a budget in bytes (Octree::MemoryBytes), beyond which the least
// recently used clouds of any session are evicted. A session that is not used for its time to
// live expires with its clouds.
//
// What is gone is remembered (a bounded record of evicted clouds and expired or closed sessions)
// so that NOT_FOUND can say why and what to do: "cloud 7 of session 3f2a... was evicted (memory
// budget); upload it again". Trees are shared: a registration holding a tree keeps it alive even
// if the cache evicts it meanwhile.
//
// Thread-safe. Knows nothing of gRPC: errors are absl statuses with the codes the service passes
// on (NOT_FOUND, PERMISSION_DENIED, RESOURCE_EXHAUSTED, INVALID_ARGUMENT).
#ifndef RPSR_SERVER_SESSION_STORE_H_
#define RPSR_SERVER_SESSION_STORE_H_

#include <cstdint>
#include <deque>
#include <functional>
#include <list>
#include <memory>
#include <string>
#include <utility>

#include "absl/base/thread_annotations.h"
#include "absl/container/flat_hash_map.h"
#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "absl/strings/string_view.h"
#include "absl/synchronization/mutex.h"
#include "absl/time/time.h"
#include "core/tree/bh_tree.h"
#include "server/rpsr_server.h"

namespace rpsr::server {

// Per-session settings fixed at creation.
struct SessionSettings {
  int tree_max_depth = 6;
  absl::Duration ttl = absl::Minutes(10);
  // Who may use the session: the bearer token that created it ("" without authentication).
  std::string owner;
};

// Cache events, for metrics. Each optional; called with the store's lock held: keep them cheap
// (a counter's Increment) and never call back into the store.
struct SessionStoreHooks {
  std::function<void()> hit;
  std::function<void()> miss;
  // A cloud left the cache by `reason` ("memory_budget", "session_expired", "session_closed",
  // "released"), freeing `bytes`.
  std::function<void(absl::string_view reason, uint64_t bytes)> evicted;
  // After every change: sessions, clouds and bytes held.
  std::function<void(size_t sessions, size_t clouds, uint64_t bytes)> occupancy;
};

struct SessionStoreStats {
  size_t sessions = 0;
  size_t clouds = 0;
  uint64_t bytes = 0;
  uint64_t hits = 0;
  uint64_t misses = 0;
  uint64_t evicted_for_memory = 0;  // clouds
  uint64_t sessions_expired = 0;
};

class SessionStore {
 public:
  using Clock = std::function<absl::Time()>;

  // `clock` defaults to absl::Now (tests pass a fake one).
  explicit SessionStore(const CacheOptions& options, SessionStoreHooks hooks = {},
                        Clock clock = nullptr);
  SessionStore(const SessionStore&) = delete;
  SessionStore& operator=(const SessionStore&) = delete;

  // A new session with a random id (128 bits, hex). RESOURCE_EXHAUSTED when max_sessions live
  // sessions exist (after expiring idle ones). settings.ttl is taken as given (the caller applies
  // the defaults and caps).
  absl::StatusOr<std::string> CreateSession(const SessionSettings& settings);

  // Frees the session and its clouds; returns how many clouds it held.
  absl::StatusOr<size_t> CloseSession(absl::string_view session_id, absl::string_view caller);

  // The session's settings, refreshing its time to live. NOT_FOUND (never existed, expired,
  // closed: the message says which), PERMISSION_DENIED (another caller's session).
  absl::StatusOr<SessionSettings> UseSession(absl::string_view session_id,
                                             absl::string_view caller);

  // Caches `tree` in the session and returns its cloud id (unique across the server). Evicts
  // least recently used clouds of any session to stay within the memory budget.
  // RESOURCE_EXHAUSTED when the session holds max_clouds_per_session clouds or the tree alone is
  // larger than the budget.
  absl::StatusOr<uint64_t> AddCloud(absl::string_view session_id, absl::string_view caller,
                                    std::shared_ptr<const core::Octree> tree);

  // The cached tree (a hit refreshes its recency and the session's time to live). NOT_FOUND says
  // whether the cloud was evicted, released, or never uploaded; PERMISSION_DENIED when the id is a
  // cloud of another session.
  absl::StatusOr<std::shared_ptr<const core::Octree>> GetCloud(absl::string_view session_id,
                                                               absl::string_view caller,
                                                               uint64_t cloud_id);

  absl::Status ReleaseCloud(absl::string_view session_id, absl::string_view caller,
                            uint64_t cloud_id);

  // Expires every session idle for longer than its time to live (the service calls it
  // periodically so that memory is freed without traffic). Returns how many expired.
  size_t ExpireIdleSessions();

  SessionStoreStats stats() const;

 private:
  struct Cloud {
    std::shared_ptr<const core::Octree> tree;
    uint64_t bytes = 0;
    std::list<std::pair<std::string, uint64_t>>::iterator lru;  // into lru_
  };
  struct Session {
    SessionSettings settings;
    absl::Time last_used;
    absl::flat_hash_map<uint64_t, Cloud> clouds;
  };
  // Why a cloud or a session is gone, for NOT_FOUND messages.
  struct Gone {
    std::string session_id;  // for clouds: the session that held it
    std::string reason;
  };

  absl::StatusOr<Session*> FindLocked(absl::string_view session_id, absl::string_view caller,
                                      absl::Time now) ABSL_EXCLUSIVE_LOCKS_REQUIRED(mu_);
  void RemoveSessionLocked(absl::flat_hash_map<std::string, Session>::iterator it,
                           absl::string_view cloud_reason, const std::string& why)
      ABSL_EXCLUSIVE_LOCKS_REQUIRED(mu_);
  void RemoveCloudLocked(Session& session, uint64_t cloud_id, absl::string_view reason,
                         const std::string& why) ABSL_EXCLUSIVE_LOCKS_REQUIRED(mu_);
  size_t ExpireLocked(absl::Time now) ABSL_EXCLUSIVE_LOCKS_REQUIRED(mu_);
  void RememberCloudLocked(uint64_t cloud_id, Gone gone) ABSL_EXCLUSIVE_LOCKS_REQUIRED(mu_);
  void RememberSessionLocked(const std::string& session_id, std::string reason)
      ABSL_EXCLUSIVE_LOCKS_REQUIRED(mu_);
  void ReportOccupancyLocked() ABSL_EXCLUSIVE_LOCKS_REQUIRED(mu_);
  std::string NewSessionIdLocked() ABSL_EXCLUSIVE_LOCKS_REQUIRED(mu_);

  const CacheOptions options_;
  const SessionStoreHooks hooks_;
  const Clock clock_;

  mutable absl::Mutex mu_;
  absl::flat_hash_map<std::string, Session> sessions_ ABSL_GUARDED_BY(mu_);
  // Every cached cloud, most recently used first: (session id, cloud id).
  std::list<std::pair<std::string, uint64_t>> lru_ ABSL_GUARDED_BY(mu_);
  // Which session holds each cached cloud (to tell a foreign id from an unknown one).
  absl::flat_hash_map<uint64_t, std::string> cloud_owner_ ABSL_GUARDED_BY(mu_);
  uint64_t bytes_ ABSL_GUARDED_BY(mu_) = 0;
  uint64_t next_cloud_id_ ABSL_GUARDED_BY(mu_) = 1;
  // Bounded memory of what is gone (oldest forgotten first).
  absl::flat_hash_map<uint64_t, Gone> gone_clouds_ ABSL_GUARDED_BY(mu_);
  std::deque<uint64_t> gone_cloud_order_ ABSL_GUARDED_BY(mu_);
  absl::flat_hash_map<std::string, std::string> gone_sessions_ ABSL_GUARDED_BY(mu_);
  std::deque<std::string> gone_session_order_ ABSL_GUARDED_BY(mu_);

  uint64_t hits_ ABSL_GUARDED_BY(mu_) = 0;
  uint64_t misses_ ABSL_GUARDED_BY(mu_) = 0;
  uint64_t evicted_for_memory_ ABSL_GUARDED_BY(mu_) = 0;
  uint64_t sessions_expired_ ABSL_GUARDED_BY(mu_) = 0;
};

}  // namespace rpsr::server

#endif  // RPSR_SERVER_SESSION_STORE_H_
