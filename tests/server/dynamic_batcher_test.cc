// DynamicBatcher: batches form up to max_batch, a lone request waits about max_queue_delay, the
// bounded queue refuses at once, expired and cancelled requests never run, batch failures reach
// every member, Stop drains or rejects, and under many producers every request is answered
// exactly once. Timing bounds are generous: the machines running this are shared and noisy.
#include "server/dynamic_batcher.h"

#include <atomic>
#include <chrono>
#include <condition_variable>
#include <future>
#include <memory>
#include <mutex>
#include <set>
#include <stdexcept>
#include <thread>
#include <vector>

#include "absl/status/status.h"
#include "absl/synchronization/notification.h"
#include "absl/time/clock.h"
#include "absl/time/time.h"
#include "gmock/gmock.h"
#include "gtest/gtest.h"

namespace rpsr::server {
namespace {

using ::testing::Each;
using ::testing::ElementsAre;
using Batcher = DynamicBatcher<int, int>;

// A batch function that squares each request and records the batches it saw.
class RecordingSquarer {
 public:
  Batcher::BatchFunction Function() {
    return [this](absl::Span<int> requests) -> absl::StatusOr<std::vector<absl::StatusOr<int>>> {
      std::vector<absl::StatusOr<int>> results;
      {
        std::lock_guard<std::mutex> lock(mu_);
        batches_.emplace_back(requests.begin(), requests.end());
      }
      for (int value : requests) results.push_back(value * value);
      return results;
    };
  }
  std::vector<std::vector<int>> batches() const {
    std::lock_guard<std::mutex> lock(mu_);
    return batches_;
  }
  std::vector<int> seen() const {
    std::vector<int> all;
    for (const auto& batch : batches()) all.insert(all.end(), batch.begin(), batch.end());
    return all;
  }

 private:
  mutable std::mutex mu_;
  std::vector<std::vector<int>> batches_;
};

// A batch function whose first call blocks until released, so a test can fill the queue behind
// a busy worker. Later calls pass through.
class GatedSquarer {
 public:
  Batcher::BatchFunction Function() {
    return [this](absl::Span<int> requests) -> absl::StatusOr<std::vector<absl::StatusOr<int>>> {
      if (!first_called_.exchange(true)) {
        entered_.Notify();
        release_.WaitForNotification();
      }
      return recorder_.Function()(requests);
    };
  }
  void WaitUntilBusy() { entered_.WaitForNotification(); }
  void Release() { release_.Notify(); }
  const RecordingSquarer& recorder() const { return recorder_; }

 private:
  std::atomic<bool> first_called_{false};
  absl::Notification entered_;
  absl::Notification release_;
  RecordingSquarer recorder_;
};

std::unique_ptr<Batcher> MakeBatcher(const DynamicBatcherOptions& options,
                                     Batcher::BatchFunction function,
                                     DynamicBatcherHooks hooks = {}) {
  auto batcher = Batcher::Create(options, std::move(function), std::move(hooks));
  EXPECT_TRUE(batcher.ok()) << batcher.status();
  return batcher.ok() ? *std::move(batcher) : nullptr;
}

absl::StatusOr<int> Get(std::future<absl::StatusOr<int>>& future) {
  if (future.wait_for(std::chrono::seconds(30)) != std::future_status::ready) {
    return absl::DeadlineExceededError("test: no answer within 30 s");
  }
  return future.get();
}

TEST(DynamicBatcherTest, DefaultsAreTheDocumentedOnes) {
  DynamicBatcherOptions options;
  EXPECT_EQ(options.max_batch, 16);
  EXPECT_EQ(options.max_queue_delay, absl::ZeroDuration());
  EXPECT_EQ(options.max_queue, 1024);
  EXPECT_EQ(options.workers, 1);
  EXPECT_TRUE(options.drain_on_stop);
}

TEST(DynamicBatcherTest, CreateRejectsOptionsOutOfRange) {
  RecordingSquarer squarer;
  for (auto change : std::vector<std::function<void(DynamicBatcherOptions&)>>{
           [](DynamicBatcherOptions& o) { o.max_batch = 0; },
           [](DynamicBatcherOptions& o) { o.max_queue = 0; },
           [](DynamicBatcherOptions& o) { o.workers = 0; },
           [](DynamicBatcherOptions& o) { o.max_queue_delay = absl::Milliseconds(-1); }}) {
    DynamicBatcherOptions options;
    change(options);
    EXPECT_EQ(Batcher::Create(options, squarer.Function()).status().code(),
              absl::StatusCode::kInvalidArgument);
  }
  EXPECT_EQ(Batcher::Create({}, nullptr).status().code(), absl::StatusCode::kInvalidArgument);
}

TEST(DynamicBatcherTest, FullBatchesRunWithoutWaitingForTheDelay) {
  GatedSquarer gated;
  DynamicBatcherOptions options;
  options.max_batch = 4;
  options.max_queue_delay = absl::Seconds(60);  // only a full batch can go before the test ends
  auto batcher = MakeBatcher(options, gated.Function());
  std::vector<std::future<absl::StatusOr<int>>> futures;
  for (int i = 0; i < 4; ++i) futures.push_back(batcher->Submit(i));
  gated.WaitUntilBusy();
  // Behind the busy worker 8 more gather; they leave as two full batches when it is free.
  for (int i = 4; i < 12; ++i) futures.push_back(batcher->Submit(i));
  const absl::Time released = absl::Now();
  gated.Release();
  for (int i = 0; i < 12; ++i) {
    auto result = Get(futures[i]);
    ASSERT_TRUE(result.ok()) << result.status();
    EXPECT_EQ(*result, i * i);
  }
  EXPECT_LT(absl::Now() - released, absl::Seconds(20));
  EXPECT_THAT(
      gated.recorder().batches(),
      ElementsAre(ElementsAre(0, 1, 2, 3), ElementsAre(4, 5, 6, 7), ElementsAre(8, 9, 10, 11)));
}

TEST(DynamicBatcherTest, LoneRequestRunsAfterAboutTheQueueDelay) {
  RecordingSquarer squarer;
  DynamicBatcherOptions options;
  options.max_queue_delay = absl::Milliseconds(100);
  auto batcher = MakeBatcher(options, squarer.Function());
  const absl::Time start = absl::Now();
  auto future = batcher->Submit(7);
  auto result = Get(future);
  const absl::Duration waited = absl::Now() - start;
  ASSERT_TRUE(result.ok()) << result.status();
  EXPECT_EQ(*result, 49);
  // It waited for companions (a little less allowed for clock granularity) but not for ever.
  EXPECT_GE(waited, absl::Milliseconds(90));
  EXPECT_LT(waited, absl::Seconds(10));
  EXPECT_THAT(squarer.batches(), ElementsAre(ElementsAre(7)));
}

TEST(DynamicBatcherTest, MaxBatchOneNeverWaits) {
  RecordingSquarer squarer;
  DynamicBatcherOptions options;
  options.max_batch = 1;
  options.max_queue_delay = absl::Seconds(60);
  auto batcher = MakeBatcher(options, squarer.Function());
  auto future = batcher->Submit(3);
  auto result = Get(future);
  ASSERT_TRUE(result.ok()) << result.status();
  EXPECT_EQ(*result, 9);
}

TEST(DynamicBatcherTest, FullQueueAnswersResourceExhaustedAtOnce) {
  GatedSquarer gated;
  DynamicBatcherOptions options;
  options.max_batch = 1;
  options.max_queue = 2;
  auto batcher = MakeBatcher(options, gated.Function());
  std::vector<std::future<absl::StatusOr<int>>> accepted;
  accepted.push_back(batcher->Submit(0));
  gated.WaitUntilBusy();  // request 0 runs; the queue is empty again
  accepted.push_back(batcher->Submit(1));
  accepted.push_back(batcher->Submit(2));

  bool called = false;
  const absl::Time start = absl::Now();
  const absl::Status refused =
      batcher->Enqueue(3, {}, [&called](absl::StatusOr<int>) { called = true; });
  EXPECT_LT(absl::Now() - start, absl::Seconds(1));
  EXPECT_EQ(refused.code(), absl::StatusCode::kResourceExhausted) << refused;
  EXPECT_EQ(batcher->stats().rejected_queue_full, 1u);
  EXPECT_EQ(batcher->stats().queue_depth, 2);

  gated.Release();
  for (auto& future : accepted) EXPECT_TRUE(Get(future).ok());
  batcher->Stop();
  EXPECT_FALSE(called);  // a refused request's callback is never called
  EXPECT_THAT(gated.recorder().seen(), ElementsAre(0, 1, 2));
}

TEST(DynamicBatcherTest, FullQueueFirstDropsRequestsThatWouldNotRun) {
  GatedSquarer gated;
  DynamicBatcherOptions options;
  options.max_batch = 1;
  options.max_queue = 1;
  auto batcher = MakeBatcher(options, gated.Function());
  auto running = batcher->Submit(0);
  gated.WaitUntilBusy();
  std::atomic<bool> cancel{false};
  auto cancelled =
      batcher->Submit(1, {absl::InfiniteFuture(), [&cancel] { return cancel.load(); }});
  cancel = true;
  auto admitted = batcher->Submit(2);  // takes the slot the cancelled request held
  EXPECT_EQ(Get(cancelled).status().code(), absl::StatusCode::kCancelled);
  gated.Release();
  EXPECT_TRUE(Get(running).ok());
  auto result = Get(admitted);
  ASSERT_TRUE(result.ok()) << result.status();
  EXPECT_EQ(*result, 4);
}

TEST(DynamicBatcherTest, ExpiredAndCancelledRequestsNeverReachTheBatchFunction) {
  GatedSquarer gated;
  DynamicBatcherOptions options;
  options.max_batch = 8;
  options.max_queue_delay = absl::ZeroDuration();
  auto batcher = MakeBatcher(options, gated.Function());
  auto blocker = batcher->Submit(0);
  gated.WaitUntilBusy();

  std::atomic<bool> cancel{false};
  auto expiring = batcher->Submit(1, {absl::Now() + absl::Milliseconds(50), nullptr});
  auto cancelled =
      batcher->Submit(2, {absl::InfiniteFuture(), [&cancel] { return cancel.load(); }});
  auto kept = batcher->Submit(3, {absl::Now() + absl::Seconds(120), nullptr});
  cancel = true;
  absl::SleepFor(absl::Milliseconds(100));  // past request 1's deadline
  gated.Release();

  EXPECT_TRUE(Get(blocker).ok());
  EXPECT_EQ(Get(expiring).status().code(), absl::StatusCode::kDeadlineExceeded);
  EXPECT_EQ(Get(cancelled).status().code(), absl::StatusCode::kCancelled);
  auto result = Get(kept);
  ASSERT_TRUE(result.ok()) << result.status();
  EXPECT_EQ(*result, 9);
  EXPECT_THAT(gated.recorder().seen(), ElementsAre(0, 3));
  const DynamicBatcherStats stats = batcher->stats();
  EXPECT_EQ(stats.deadline_exceeded, 1u);
  EXPECT_EQ(stats.cancelled, 1u);
  EXPECT_EQ(stats.requests_run, 2u);
}

TEST(DynamicBatcherTest, RequestsDeadOnArrivalAreRefusedWithoutACallback) {
  RecordingSquarer squarer;
  auto batcher = MakeBatcher({}, squarer.Function());
  bool called = false;
  auto done = [&called](absl::StatusOr<int>) { called = true; };
  EXPECT_EQ(batcher->Enqueue(1, {absl::Now() - absl::Seconds(1), nullptr}, done).code(),
            absl::StatusCode::kDeadlineExceeded);
  EXPECT_EQ(batcher->Enqueue(2, {absl::InfiniteFuture(), [] { return true; }}, done).code(),
            absl::StatusCode::kCancelled);
  batcher->Stop();
  EXPECT_FALSE(called);
  EXPECT_TRUE(squarer.seen().empty());
}

TEST(DynamicBatcherTest, BatchFunctionFailureFailsEveryRequestOfTheBatch) {
  DynamicBatcherOptions options;
  options.max_batch = 3;
  options.max_queue_delay = absl::Seconds(60);
  auto batcher =
      MakeBatcher(options, [](absl::Span<int>) -> absl::StatusOr<std::vector<absl::StatusOr<int>>> {
        return absl::InternalError("forward pass failed");
      });
  std::vector<std::future<absl::StatusOr<int>>> futures;
  for (int i = 0; i < 3; ++i) futures.push_back(batcher->Submit(i));
  for (auto& future : futures) {
    const absl::Status status = Get(future).status();
    EXPECT_EQ(status.code(), absl::StatusCode::kInternal);
    EXPECT_EQ(status.message(), "forward pass failed");
  }
  EXPECT_EQ(batcher->stats().requests_failed, 3u);
}

TEST(DynamicBatcherTest, ThrownExceptionsAndWrongResultCountsBecomeInternalErrors) {
  DynamicBatcherOptions options;
  options.max_batch = 1;
  auto throwing =
      MakeBatcher(options, [](absl::Span<int>) -> absl::StatusOr<std::vector<absl::StatusOr<int>>> {
        throw std::runtime_error("boom");
      });
  auto thrown = throwing->Submit(1);
  const absl::Status status = Get(thrown).status();
  EXPECT_EQ(status.code(), absl::StatusCode::kInternal);
  EXPECT_THAT(std::string(status.message()), ::testing::HasSubstr("boom"));

  auto short_answer =
      MakeBatcher(options, [](absl::Span<int>) -> absl::StatusOr<std::vector<absl::StatusOr<int>>> {
        return std::vector<absl::StatusOr<int>>{};
      });
  auto missing = short_answer->Submit(1);
  EXPECT_EQ(Get(missing).status().code(), absl::StatusCode::kInternal);
}

TEST(DynamicBatcherTest, PerRequestStatusesPassThrough) {
  DynamicBatcherOptions options;
  options.max_batch = 2;
  options.max_queue_delay = absl::Seconds(60);
  auto batcher = MakeBatcher(
      options, [](absl::Span<int> requests) -> absl::StatusOr<std::vector<absl::StatusOr<int>>> {
        std::vector<absl::StatusOr<int>> results;
        for (int value : requests) {
          if (value < 0) {
            results.push_back(absl::InvalidArgumentError("negative"));
          } else {
            results.push_back(value);
          }
        }
        return results;
      });
  auto bad = batcher->Submit(-1);
  auto good = batcher->Submit(5);
  EXPECT_EQ(Get(bad).status().code(), absl::StatusCode::kInvalidArgument);
  auto result = Get(good);
  ASSERT_TRUE(result.ok()) << result.status();
  EXPECT_EQ(*result, 5);
}

TEST(DynamicBatcherTest, StopDrainsTheQueueThenRefusesNewRequests) {
  GatedSquarer gated;
  DynamicBatcherOptions options;
  options.max_batch = 4;
  options.max_queue_delay = absl::Seconds(60);  // draining must not wait for companions
  auto batcher = MakeBatcher(options, gated.Function());
  std::vector<std::future<absl::StatusOr<int>>> futures;
  for (int i = 0; i < 4; ++i) futures.push_back(batcher->Submit(i));
  gated.WaitUntilBusy();
  for (int i = 4; i < 10; ++i) futures.push_back(batcher->Submit(i));
  std::thread stopper([&batcher] { batcher->Stop(); });
  absl::SleepFor(absl::Milliseconds(20));
  gated.Release();
  stopper.join();
  // Stop returned: every accepted request has its answer.
  for (int i = 0; i < 10; ++i) {
    ASSERT_EQ(futures[i].wait_for(std::chrono::seconds(0)), std::future_status::ready);
    auto result = futures[i].get();
    ASSERT_TRUE(result.ok()) << result.status();
    EXPECT_EQ(*result, i * i);
  }
  auto late = batcher->Submit(11);
  EXPECT_EQ(Get(late).status().code(), absl::StatusCode::kUnavailable);
  batcher->Stop();  // idempotent
}

TEST(DynamicBatcherTest, StopWithoutDrainRejectsQueuedButFinishesRunningBatches) {
  GatedSquarer gated;
  DynamicBatcherOptions options;
  options.max_batch = 1;
  options.drain_on_stop = false;
  auto batcher = MakeBatcher(options, gated.Function());
  auto running = batcher->Submit(0);
  gated.WaitUntilBusy();
  std::vector<std::future<absl::StatusOr<int>>> queued;
  for (int i = 1; i < 6; ++i) queued.push_back(batcher->Submit(i));
  std::thread stopper([&batcher] { batcher->Stop(); });
  // The queued ones are answered while the running batch still blocks.
  for (auto& future : queued) {
    EXPECT_EQ(Get(future).status().code(), absl::StatusCode::kUnavailable);
  }
  gated.Release();
  stopper.join();
  auto result = Get(running);
  ASSERT_TRUE(result.ok()) << result.status();
  EXPECT_EQ(*result, 0);
  EXPECT_THAT(gated.recorder().seen(), ElementsAre(0));
  EXPECT_EQ(batcher->stats().rejected_stopped, 5u);
}

TEST(DynamicBatcherTest, WorkersRunTheirInitOnTheirOwnThreadAndShareTheQueue) {
  std::mutex mu;
  std::set<int> init_indices;
  std::set<std::thread::id> worker_threads;
  std::set<std::thread::id> batch_threads;
  DynamicBatcherOptions options;
  options.workers = 3;
  options.max_batch = 1;
  options.worker_init = [&](int index) {
    std::lock_guard<std::mutex> lock(mu);
    init_indices.insert(index);
    worker_threads.insert(std::this_thread::get_id());
  };
  auto batcher = MakeBatcher(
      options, [&](absl::Span<int> requests) -> absl::StatusOr<std::vector<absl::StatusOr<int>>> {
        {
          std::lock_guard<std::mutex> lock(mu);
          batch_threads.insert(std::this_thread::get_id());
        }
        absl::SleepFor(absl::Milliseconds(5));  // long enough for other workers to take some
        return std::vector<absl::StatusOr<int>>(requests.begin(), requests.end());
      });
  std::vector<std::future<absl::StatusOr<int>>> futures;
  for (int i = 0; i < 30; ++i) futures.push_back(batcher->Submit(i));
  for (auto& future : futures) EXPECT_TRUE(Get(future).ok());
  batcher->Stop();
  std::lock_guard<std::mutex> lock(mu);
  EXPECT_EQ(init_indices, (std::set<int>{0, 1, 2}));
  EXPECT_EQ(worker_threads.size(), 3u);
  for (const auto& id : batch_threads) EXPECT_TRUE(worker_threads.count(id)) << "not a worker";
  EXPECT_GE(batch_threads.size(), 2u);  // several workers took batches
}

// A due batch is shared among the workers: with two idle, a full queue of 16 runs as two batches
// of 8 at once, not one of 16 while the other worker idles; the rest of a split does not wait for
// the queue delay again (it is 60 s here).
TEST(DynamicBatcherTest, IdleWorkersShareADueBatch) {
  DynamicBatcherOptions options;
  options.workers = 2;
  options.max_batch = 16;
  options.max_queue_delay = absl::Seconds(60);
  std::mutex mu;
  std::condition_variable both_running;
  std::set<std::thread::id> threads;
  RecordingSquarer recorder;
  auto batcher = MakeBatcher(
      options, [&](absl::Span<int> requests) -> absl::StatusOr<std::vector<absl::StatusOr<int>>> {
        {
          // Each batch waits (at most 10 s) for a second one to run beside it, so a fast first
          // worker cannot come back for the rest itself before the other wakes.
          std::unique_lock<std::mutex> lock(mu);
          threads.insert(std::this_thread::get_id());
          both_running.notify_all();
          both_running.wait_for(lock, std::chrono::seconds(10),
                                [&] { return threads.size() >= 2; });
        }
        return recorder.Function()(requests);
      });
  std::vector<std::future<absl::StatusOr<int>>> futures;
  for (int i = 0; i < 16; ++i) futures.push_back(batcher->Submit(i));
  for (int i = 0; i < 16; ++i) {
    absl::StatusOr<int> answer = Get(futures[i]);
    ASSERT_TRUE(answer.ok()) << answer.status();
    EXPECT_EQ(*answer, i * i);
  }
  const std::vector<std::vector<int>> batches = recorder.batches();
  ASSERT_EQ(batches.size(), 2u);
  EXPECT_EQ(batches[0].size(), 8u);
  EXPECT_EQ(batches[1].size(), 8u);
  std::lock_guard<std::mutex> lock(mu);
  EXPECT_EQ(threads.size(), 2u);
  batcher->Stop();
}

// A busy worker keeps its share: with one of two workers blocked in a batch, the free one takes
// 8 of 16 due requests at a time, not all 16 (whose members would all wait for the whole batch).
TEST(DynamicBatcherTest, BusyWorkersKeepTheirShareSoBatchesStayShort) {
  DynamicBatcherOptions options;
  options.workers = 2;
  options.max_batch = 16;
  options.max_queue_delay = absl::Seconds(60);
  GatedSquarer gated;
  auto batcher = MakeBatcher(options, gated.Function());
  std::vector<std::future<absl::StatusOr<int>>> futures;
  for (int i = 0; i < 16; ++i) futures.push_back(batcher->Submit(i));
  gated.WaitUntilBusy();  // one worker holds 8 of them in its blocked batch
  auto wait_until_seen = [&](size_t count) {
    const absl::Time give_up = absl::Now() + absl::Seconds(30);
    while (gated.recorder().seen().size() < count && absl::Now() < give_up) {
      absl::SleepFor(absl::Milliseconds(1));
    }
    return gated.recorder().seen().size();
  };
  ASSERT_EQ(wait_until_seen(8), 8u);  // the other worker ran its 8
  for (int i = 16; i < 32; ++i) futures.push_back(batcher->Submit(i));
  // The free worker runs the next 16 as two batches of 8 while the other is still blocked.
  EXPECT_EQ(wait_until_seen(24), 24u);
  gated.Release();
  for (auto& future : futures) EXPECT_TRUE(Get(future).ok());
  for (const auto& batch : gated.recorder().batches()) EXPECT_LE(batch.size(), 8u);
  EXPECT_EQ(gated.recorder().seen().size(), 32u);
  batcher->Stop();
}

TEST(DynamicBatcherTest, HooksSeeEveryRequestAndBatch) {
  std::atomic<int> waits{0};
  std::atomic<int> batched_requests{0};
  std::atomic<int> batches{0};
  std::atomic<int> last_depth{-1};
  std::atomic<int> max_depth{0};
  DynamicBatcherHooks hooks;
  hooks.queue_wait = [&](double seconds) {
    EXPECT_GE(seconds, 0.0);
    ++waits;
  };
  hooks.batch_done = [&](int size, double seconds) {
    EXPECT_GE(seconds, 0.0);
    batched_requests += size;
    ++batches;
  };
  hooks.queue_depth = [&](int depth) {
    last_depth = depth;
    if (depth > max_depth) max_depth = depth;
  };
  GatedSquarer gated;
  DynamicBatcherOptions options;
  options.max_batch = 4;
  options.max_queue_delay = absl::Milliseconds(1);
  auto batcher = MakeBatcher(options, gated.Function(), hooks);
  std::vector<std::future<absl::StatusOr<int>>> futures;
  futures.push_back(batcher->Submit(0));
  gated.WaitUntilBusy();
  for (int i = 1; i < 10; ++i) futures.push_back(batcher->Submit(i));
  gated.Release();
  for (auto& future : futures) EXPECT_TRUE(Get(future).ok());
  batcher->Stop();
  EXPECT_EQ(waits, 10);
  EXPECT_EQ(batched_requests, 10);
  EXPECT_EQ(batches, static_cast<int>(gated.recorder().batches().size()));
  EXPECT_EQ(max_depth, 9);
  EXPECT_EQ(last_depth, 0);
}

// Many producers, several workers, a small queue (producers retry on RESOURCE_EXHAUSTED, as a
// client would), some requests cancelled or with short deadlines: each request is answered
// exactly once, with its own result or a status saying why not, and the counts add up.
TEST(DynamicBatcherTest, ManyProducersEveryRequestAnsweredExactlyOnce) {
  constexpr int kProducers = 8;
  constexpr int kPerProducer = 400;
  constexpr int kTotal = kProducers * kPerProducer;
  std::vector<std::atomic<int>> answers(kTotal);
  std::atomic<int> wrong{0};
  std::atomic<int> ok{0};
  std::atomic<int> full_refusals{0};
  std::atomic<int> batch_calls_with_oversize{0};

  DynamicBatcherOptions options;
  options.workers = 3;
  options.max_batch = 8;
  options.max_queue = 64;  // small: producers meet a full queue
  options.max_queue_delay = absl::Microseconds(200);
  auto batcher = MakeBatcher(
      options, [&](absl::Span<int> requests) -> absl::StatusOr<std::vector<absl::StatusOr<int>>> {
        if (requests.size() > 8) ++batch_calls_with_oversize;
        std::vector<absl::StatusOr<int>> results;
        for (int id : requests) {
          if (id % 97 == 0) {
            results.push_back(absl::InvalidArgumentError("multiple of 97"));
          } else {
            results.push_back(id + 1);
          }
        }
        return results;
      });

  // Only these may fail: multiples of 97 (the batch function says so), of 11 (50 us deadline)
  // and of 13 (cancelled right after they are queued).
  auto may_fail = [](int id) { return id % 97 == 0 || id % 11 == 0 || id % 13 == 0; };
  int must_succeed = 0;
  for (int id = 0; id < kTotal; ++id) must_succeed += !may_fail(id);

  std::vector<std::thread> producers;
  std::vector<std::shared_ptr<std::atomic<bool>>> cancel_flags;
  for (int i = 0; i < kTotal; ++i) cancel_flags.push_back(std::make_shared<std::atomic<bool>>());
  for (int p = 0; p < kProducers; ++p) {
    producers.emplace_back([&, p] {
      for (int k = 0; k < kPerProducer; ++k) {
        const int id = p * kPerProducer + k;
        const absl::Time deadline =
            id % 11 == 0 ? absl::Now() + absl::Microseconds(50) : absl::InfiniteFuture();
        for (;;) {
          BatchRequestControl control;
          control.deadline = deadline;
          if (id % 13 == 0) {
            control.is_cancelled = [flag = cancel_flags[id]] { return flag->load(); };
          }
          const absl::Status queued =
              batcher->Enqueue(id, std::move(control), [&, id](absl::StatusOr<int> result) {
                answers[id].fetch_add(1);
                if (result.ok()) {
                  ++ok;
                  if (*result != id + 1) ++wrong;
                } else if (!may_fail(id)) {
                  ++wrong;
                }
              });
          if (queued.code() == absl::StatusCode::kResourceExhausted) {
            ++full_refusals;
            std::this_thread::sleep_for(std::chrono::microseconds(100));
            continue;  // no callback comes for a refused request: try again
          }
          if (!queued.ok()) {
            answers[id].fetch_add(1);  // refused at arrival, answered by the status
            if (!may_fail(id)) ++wrong;
          }
          break;
        }
        if (id % 13 == 0) cancel_flags[id]->store(true);
      }
    });
  }
  for (auto& producer : producers) producer.join();
  batcher->Stop();

  int answered_once = 0;
  for (const auto& count : answers) answered_once += count.load() == 1;
  EXPECT_EQ(answered_once, kTotal);
  EXPECT_EQ(wrong, 0);
  EXPECT_EQ(batch_calls_with_oversize, 0);
  EXPECT_GE(ok, must_succeed);
  const DynamicBatcherStats stats = batcher->stats();
  // Each request ran, or expired, or was cancelled (at arrival or in the queue); every refusal
  // for a full queue was retried; none was refused for stopping (Stop came after the last one).
  EXPECT_EQ(stats.requests_run + stats.deadline_exceeded + stats.cancelled,
            static_cast<uint64_t>(kTotal));
  EXPECT_EQ(stats.rejected_queue_full, static_cast<uint64_t>(full_refusals.load()));
  EXPECT_EQ(stats.rejected_stopped, 0u);
  EXPECT_EQ(stats.queue_depth, 0);
  EXPECT_EQ(stats.busy_workers, 0);
  EXPECT_EQ(static_cast<int>(stats.requests_run - stats.requests_failed), ok.load());
  EXPECT_GT(stats.batches, 0u);
  EXPECT_LT(stats.batches, stats.requests_run);  // some batches held more than one request
}

}  // namespace
}  // namespace rpsr::server
