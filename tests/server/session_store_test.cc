#include "server/session_store.h"

#include <memory>
#include <vector>

#include "absl/strings/str_cat.h"
#include "gmock/gmock.h"
#include "gtest/gtest.h"
#include "server/cloud_assembler.h"

namespace rpsr::server {
namespace {

using ::testing::HasSubstr;

std::shared_ptr<const core::Octree> Tree(int n, float offset = 0.0f) {
  std::vector<Eigen::Vector3f> points;
  for (int i = 0; i < n; ++i) {
    points.emplace_back(offset + 0.01f * i, std::sin(0.3f * i), std::cos(0.7f * i));
  }
  auto tree = BuildCloudTree(points, 6, 1'000'000);
  EXPECT_TRUE(tree.ok()) << tree.status();
  return *tree;
}

class SessionStoreTest : public ::testing::Test {
 protected:
  SessionStore MakeStore(const CacheOptions& options) {
    SessionStoreHooks hooks;
    hooks.hit = [this] { ++hits_; };
    hooks.miss = [this] { ++misses_; };
    hooks.evicted = [this](absl::string_view reason, uint64_t bytes) {
      evicted_.push_back(absl::StrCat(reason, ":", bytes));
    };
    hooks.occupancy = [this](size_t sessions, size_t clouds, uint64_t bytes) {
      sessions_ = sessions;
      clouds_ = clouds;
      bytes_ = bytes;
    };
    return SessionStore(options, hooks, [this] { return now_; });
  }
  SessionSettings Settings(absl::Duration ttl = absl::Minutes(1)) {
    SessionSettings settings;
    settings.ttl = ttl;
    return settings;
  }

  absl::Time now_ = absl::FromUnixSeconds(1'000'000);
  int hits_ = 0;
  int misses_ = 0;
  std::vector<std::string> evicted_;
  size_t sessions_ = 0;
  size_t clouds_ = 0;
  uint64_t bytes_ = 0;
};

TEST_F(SessionStoreTest, KeepsTreesAndCountsHitsMissesAndBytes) {
  SessionStore store = MakeStore({});
  auto session = store.CreateSession(Settings());
  ASSERT_TRUE(session.ok());
  EXPECT_EQ(session->size(), 32u);  // 128 bits in hex
  auto tree = Tree(500);
  auto id = store.AddCloud(*session, "", tree);
  ASSERT_TRUE(id.ok());
  auto got = store.GetCloud(*session, "", *id);
  ASSERT_TRUE(got.ok());
  EXPECT_EQ(got->get(), tree.get());
  EXPECT_EQ(hits_, 1);
  EXPECT_EQ(bytes_, tree->MemoryBytes());
  EXPECT_EQ(clouds_, 1u);
  EXPECT_EQ(sessions_, 1u);
  EXPECT_EQ(store.GetCloud(*session, "", *id + 1).status().code(), absl::StatusCode::kNotFound);
  EXPECT_EQ(misses_, 1);
  EXPECT_EQ(store.stats().hits, 1u);
}

TEST_F(SessionStoreTest, EvictsTheLeastRecentlyUsedCloudOfAnySessionBeyondTheBudget) {
  auto tree = Tree(500);
  CacheOptions options;
  options.memory_budget_bytes = tree->MemoryBytes() * 5 / 2;
  SessionStore store = MakeStore(options);
  const std::string s1 = *store.CreateSession(Settings());
  const std::string s2 = *store.CreateSession(Settings());
  const uint64_t a = *store.AddCloud(s1, "", Tree(500));
  const uint64_t b = *store.AddCloud(s2, "", Tree(500, 1.0f));
  ASSERT_TRUE(store.GetCloud(s1, "", a).ok());  // b is now the least recently used
  const uint64_t c = *store.AddCloud(s1, "", Tree(500, 2.0f));
  EXPECT_TRUE(store.GetCloud(s1, "", a).ok());
  EXPECT_TRUE(store.GetCloud(s1, "", c).ok());
  const absl::Status gone = store.GetCloud(s2, "", b).status();
  EXPECT_EQ(gone.code(), absl::StatusCode::kNotFound);
  EXPECT_EQ(gone.message(), absl::StrCat("cloud ", b, " of session ", s2,
                                         " was evicted (memory budget); upload it again"));
  ASSERT_EQ(evicted_.size(), 1u);
  EXPECT_THAT(evicted_[0], HasSubstr("memory_budget:"));
  EXPECT_EQ(store.stats().evicted_for_memory, 1u);
  EXPECT_LE(store.stats().bytes, options.memory_budget_bytes);
}

TEST_F(SessionStoreTest, RefusesATreeLargerThanTheWholeBudget) {
  CacheOptions options;
  options.memory_budget_bytes = 1000;
  SessionStore store = MakeStore(options);
  const std::string s = *store.CreateSession(Settings());
  EXPECT_EQ(store.AddCloud(s, "", Tree(500)).status().code(), absl::StatusCode::kResourceExhausted);
}

TEST_F(SessionStoreTest, SessionsExpireAfterTheirTimeToLiveWithoutUse) {
  SessionStore store = MakeStore({});
  const std::string s = *store.CreateSession(Settings(absl::Seconds(10)));
  const uint64_t id = *store.AddCloud(s, "", Tree(100));
  now_ += absl::Seconds(8);
  ASSERT_TRUE(store.GetCloud(s, "", id).ok());  // use refreshes the time to live
  now_ += absl::Seconds(8);
  ASSERT_TRUE(store.UseSession(s, "").ok());
  now_ += absl::Seconds(11);
  EXPECT_EQ(store.ExpireIdleSessions(), 1u);
  EXPECT_EQ(sessions_, 0u);
  EXPECT_EQ(bytes_, 0u);
  const absl::Status gone = store.GetCloud(s, "", id).status();
  EXPECT_EQ(gone.code(), absl::StatusCode::kNotFound);
  EXPECT_THAT(gone.message(),
              HasSubstr("expired (unused for longer than its time to live of 10 s)"));
  EXPECT_THAT(evicted_, ::testing::ElementsAre(HasSubstr("session_expired")));
}

TEST_F(SessionStoreTest, AnExpiredSessionIsReportedEvenBeforeTheSweep) {
  SessionStore store = MakeStore({});
  const std::string s = *store.CreateSession(Settings(absl::Seconds(1)));
  now_ += absl::Seconds(2);
  EXPECT_THAT(store.UseSession(s, "").status().message(), HasSubstr("expired"));
  EXPECT_EQ(store.stats().sessions_expired, 1u);
}

TEST_F(SessionStoreTest, ForeignSessionsAndCloudsArePermissionDenied) {
  SessionStore store = MakeStore({});
  SessionSettings alice = Settings();
  alice.owner = "alice";
  const std::string a = *store.CreateSession(alice);
  SessionSettings bob = Settings();
  bob.owner = "bob";
  const std::string b = *store.CreateSession(bob);
  const uint64_t bobs = *store.AddCloud(b, "bob", Tree(100));
  EXPECT_EQ(store.UseSession(a, "bob").status().code(), absl::StatusCode::kPermissionDenied);
  const absl::Status foreign = store.GetCloud(a, "alice", bobs).status();
  EXPECT_EQ(foreign.code(), absl::StatusCode::kPermissionDenied);
  EXPECT_THAT(foreign.message(), HasSubstr("belongs to another session"));
}

TEST_F(SessionStoreTest, EnforcesSessionAndCloudCounts) {
  CacheOptions options;
  options.max_sessions = 2;
  options.max_clouds_per_session = 1;
  SessionStore store = MakeStore(options);
  const std::string s = *store.CreateSession(Settings());
  ASSERT_TRUE(store.CreateSession(Settings()).ok());
  EXPECT_EQ(store.CreateSession(Settings()).status().code(), absl::StatusCode::kResourceExhausted);
  ASSERT_TRUE(store.AddCloud(s, "", Tree(100)).ok());
  const absl::Status full = store.AddCloud(s, "", Tree(100)).status();
  EXPECT_EQ(full.code(), absl::StatusCode::kResourceExhausted);
  EXPECT_THAT(full.message(), HasSubstr("holds the most clouds it may (1)"));
}

TEST_F(SessionStoreTest, CloseAndReleaseFreeAndAreRemembered) {
  SessionStore store = MakeStore({});
  const std::string s = *store.CreateSession(Settings());
  const uint64_t a = *store.AddCloud(s, "", Tree(100));
  const uint64_t b = *store.AddCloud(s, "", Tree(100, 1.0f));
  ASSERT_TRUE(store.ReleaseCloud(s, "", a).ok());
  EXPECT_THAT(store.GetCloud(s, "", a).status().message(), HasSubstr("was released"));
  EXPECT_EQ(store.ReleaseCloud(s, "", a).code(), absl::StatusCode::kNotFound);
  auto closed = store.CloseSession(s, "");
  ASSERT_TRUE(closed.ok());
  EXPECT_EQ(*closed, 1u);
  EXPECT_EQ(bytes_, 0u);
  EXPECT_THAT(store.UseSession(s, "").status().message(), HasSubstr("was closed"));
  EXPECT_THAT(store.UseSession("nope", "").status().message(), HasSubstr("unknown"));
  (void)b;
}

}  // namespace
}  // namespace rpsr::server
