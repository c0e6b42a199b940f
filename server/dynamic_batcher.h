// Dynamic batching across clients (issue 6), after Triton's dynamic batcher: requests from all
// callers wait in one bounded queue at most `max_queue_delay` for up to `max_batch` companions and
// then run as one batch through a caller-given batch function on a pool of workers.
//
// It knows nothing of gRPC or tensors: Request and Response are any movable types, and a request's
// deadline and cancellation are plain values the caller derives from its transport.
//
// Semantics (Triton's, unless noted):
// - A free worker takes a batch as soon as max_batch requests wait, or when the oldest waiting
//   request has waited max_queue_delay, whichever comes first; with max_batch = 1 nothing waits.
//   A worker that is busy forms no batch: requests that arrive meanwhile gather for the next free
//   worker, which takes them at once if the oldest has waited long enough (so under load batches
//   grow without added delay).
// - The queue is bounded: a request that finds it full is refused at once with RESOURCE_EXHAUSTED
//   (after dropping expired and cancelled requests, which would otherwise hold slots).
// - A request whose deadline has passed, or whose cancellation check says so, leaves the queue
//   without running: DEADLINE_EXCEEDED or CANCELLED. Checked at enqueue and when a worker takes
//   requests; a request already in a running batch runs to the end (one forward pass cannot
//   drop a member midway).
// - A failing batch function (a non-OK status, a thrown exception, or the wrong number of results)
//   fails every request of the batch with that status; per-request statuses pass through as they
//   are.
// - Stop() either drains (runs everything queued, without waiting for companions) or rejects what
//   is queued with UNAVAILABLE; either way batches already running finish, and every accepted
//   request is answered exactly once before Stop returns.
// - Not Triton's: what is due is split once among the workers. A worker that finds n requests
//   due takes ceil(n / workers) of them (at most max_batch), and the rest stays due at once, in
//   shares of the same size, for the next free workers. On a CPU a batch costs what its requests
//   cost one by one, and a request is answered when its whole batch is done: one worker taking
//   all 16 of 16 clients' requests made them wait for all 16 while the other worker finished
//   early and idled. tests/bench/service_load_bench, 2 workers, 16 clients, max_batch 16: p99
//   491 ms when only the idle workers shared, 151 ms with this rule (159 ms at max_batch 1; 165
//   against 141 pairs/s in that run). With a GPU, where batches pay, run one or two workers.
// Not taken from Triton: preferred batch sizes, priorities, and per-request queue policies.
//
// Completion: a callback, called exactly once on a worker's thread (or on Stop's or an Enqueue's
// thread for requests dropped there), never with the batcher's lock held, so it may call back into
// the batcher or finish a gRPC reactor; or a std::future through Submit.
#ifndef RPSR_SERVER_DYNAMIC_BATCHER_H_
#define RPSR_SERVER_DYNAMIC_BATCHER_H_

#include <algorithm>
#include <atomic>
#include <condition_variable>
#include <cstdint>
#include <deque>
#include <exception>
#include <functional>
#include <future>
#include <memory>
#include <mutex>
#include <string>
#include <utility>
#include <vector>

#include "absl/functional/any_invocable.h"
#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "absl/strings/str_cat.h"
#include "absl/time/clock.h"
#include "absl/time/time.h"
#include "absl/types/span.h"
#include "server/worker_pool.h"

namespace rpsr::server {

struct DynamicBatcherOptions {
  // Most requests in one call of the batch function, >= 1. 16 is where the network's time per
  // pair stops falling much on one CPU core (tests/bench/rpsr_net_bench).
  int max_batch = 16;
  // Longest a request waits for companions once it is the oldest in the queue, >= 0. Zero runs
  // whatever is queued as soon as a worker is free (Triton's default); batches still form under
  // load, from the requests that gather while every worker is busy. A lone request pays the
  // whole delay (tests/bench/service_load_bench: ~2.2 ms added at 2 ms, ~0.1-0.2 ms at 0).
  absl::Duration max_queue_delay = absl::ZeroDuration();
  // Most requests waiting (not counting running batches), >= 1; one more is RESOURCE_EXHAUSTED.
  int max_queue = 1024;
  // Worker threads, each running one batch at a time, >= 1.
  int workers = 1;
  // Runs once on each worker's thread before it takes work, e.g. to set LibTorch's intra-op
  // threads (core::SetNetThreads). Empty: nothing.
  std::function<void(int worker_index)> worker_init;
  // Stop(): true runs everything queued first; false answers it UNAVAILABLE.
  bool drain_on_stop = true;
};

// Metrics hooks, each optional. They run on the batcher's threads: keep them cheap (a histogram's
// Observe, a gauge's Set).
struct DynamicBatcherHooks {
  // Per request that leaves the queue to run: seconds from Enqueue until its batch started.
  std::function<void(double seconds)> queue_wait;
  // Per batch: how many requests it held and the seconds the batch function took.
  std::function<void(int batch_size, double seconds)> batch_done;
  // The number of waiting requests, after each change. Called with the queue's lock held, so
  // values arrive in order; must not call back into the batcher.
  std::function<void(int depth)> queue_depth;
};

// Counts since the batcher started (a snapshot: counters read one by one).
struct DynamicBatcherStats {
  uint64_t accepted = 0;             // entered the queue
  uint64_t rejected_queue_full = 0;  // RESOURCE_EXHAUSTED at Enqueue
  uint64_t rejected_stopped = 0;     // UNAVAILABLE: at Enqueue after Stop, or queued at Stop
  uint64_t deadline_exceeded = 0;    // at Enqueue or left the queue without running
  uint64_t cancelled = 0;            // at Enqueue or left the queue without running
  uint64_t batches = 0;              // calls of the batch function
  uint64_t requests_run = 0;         // requests that went through the batch function
  uint64_t requests_failed = 0;      // of those, answered with a non-OK status
  int queue_depth = 0;               // waiting now
  int busy_workers = 0;              // running a batch now
};

// What the batcher needs to know about a request besides the request itself.
struct BatchRequestControl {
  // After this, the request is not started (DEADLINE_EXCEEDED).
  absl::Time deadline = absl::InfiniteFuture();
  // True once the caller gave up (e.g. grpc::CallbackServerContext::IsCancelled, or an atomic
  // flag set by a reactor's OnCancel). Called with the queue's lock held, possibly several times:
  // keep it cheap and non-blocking. Empty: never cancelled.
  std::function<bool()> is_cancelled;
};

template <typename Request, typename Response>
class DynamicBatcher {
 public:
  using Result = absl::StatusOr<Response>;
  // Runs one batch: one result per request, in order. A non-OK return (or a thrown exception)
  // fails the whole batch. Called on a worker's thread; several workers call it at once, so it
  // must be thread-safe. It may move from the requests.
  using BatchFunction = std::function<absl::StatusOr<std::vector<Result>>(absl::Span<Request>)>;
  using Done = absl::AnyInvocable<void(Result)>;

  // InvalidArgument for options out of range or an empty batch function.
  static absl::StatusOr<std::unique_ptr<DynamicBatcher>> Create(
      const DynamicBatcherOptions& options, BatchFunction batch_function,
      DynamicBatcherHooks hooks = {}) {
    if (options.max_batch < 1 || options.max_queue < 1 || options.workers < 1 ||
        options.max_queue_delay < absl::ZeroDuration()) {
      return absl::InvalidArgumentError(absl::StrCat(
          "DynamicBatcher: need max_batch >= 1, max_queue >= 1, workers >= 1 and "
          "max_queue_delay >= 0; got max_batch ",
          options.max_batch, ", max_queue ", options.max_queue, ", workers ", options.workers,
          ", max_queue_delay ", absl::FormatDuration(options.max_queue_delay)));
    }
    if (!batch_function) return absl::InvalidArgumentError("DynamicBatcher: no batch function");
    std::unique_ptr<DynamicBatcher> batcher(
        new DynamicBatcher(options, std::move(batch_function), std::move(hooks)));
    WorkerPoolOptions pool_options;
    pool_options.workers = options.workers;
    pool_options.init = options.worker_init;
    pool_options.name_prefix = "rpsr-batch-";
    DynamicBatcher* self = batcher.get();
    auto pool = WorkerPool::Start(pool_options, [self](int) { self->WorkerLoop(); });
    if (!pool.ok()) return pool.status();
    batcher->pool_ = *std::move(pool);
    return batcher;
  }

  // Stops (as Stop()) if not yet stopped.
  ~DynamicBatcher() { Stop(); }
  DynamicBatcher(const DynamicBatcher&) = delete;
  DynamicBatcher& operator=(const DynamicBatcher&) = delete;

  // OK: the request is queued and `done` will be called exactly once. Otherwise `done` is never
  // called and the status says why at once: RESOURCE_EXHAUSTED (queue full), UNAVAILABLE
  // (stopping), DEADLINE_EXCEEDED or CANCELLED (already so at arrival).
  absl::Status Enqueue(Request request, BatchRequestControl control, Done done) {
    const absl::Time now = absl::Now();
    std::vector<Entry> dropped;
    absl::Status refusal;
    {
      std::lock_guard<std::mutex> lock(mu_);
      if (stopping_) {
        refusal = absl::UnavailableError("the batcher is stopping; no new requests");
        rejected_stopped_.fetch_add(1, std::memory_order_relaxed);
      } else if (now >= control.deadline) {
        refusal = absl::DeadlineExceededError("deadline passed before the request was queued");
        deadline_exceeded_.fetch_add(1, std::memory_order_relaxed);
      } else if (control.is_cancelled && control.is_cancelled()) {
        refusal = absl::CancelledError("request cancelled before it was queued");
        cancelled_.fetch_add(1, std::memory_order_relaxed);
      } else {
        if (static_cast<int>(queue_.size()) >= options_.max_queue) DropStaleLocked(now, &dropped);
        if (static_cast<int>(queue_.size()) >= options_.max_queue) {
          refusal = absl::ResourceExhaustedError(
              absl::StrCat("batch queue full (", options_.max_queue,
                           " requests waiting); retry later or raise the queue limit"));
          rejected_queue_full_.fetch_add(1, std::memory_order_relaxed);
        } else {
          queue_.push_back(Entry{std::move(request), std::move(control), std::move(done), now});
          accepted_.fetch_add(1, std::memory_order_relaxed);
          const int depth = static_cast<int>(queue_.size());
          // A new oldest request starts a worker's timer; a full batch needs a worker now. In
          // between, the waiting worker's timer already covers the new request.
          if (depth == 1 || depth == options_.max_batch) work_cv_.notify_one();
          ReportDepthLocked();
        }
      }
    }
    AnswerDropped(dropped, now);
    return refusal;
  }

  // As Enqueue, with the result (or the refusal) in a future.
  std::future<Result> Submit(Request request, BatchRequestControl control = {}) {
    auto promise = std::make_shared<std::promise<Result>>();
    std::future<Result> future = promise->get_future();
    absl::Status queued = Enqueue(std::move(request), std::move(control), [promise](Result result) {
      promise->set_value(std::move(result));
    });
    if (!queued.ok()) promise->set_value(Result(std::move(queued)));
    return future;
  }

  // Refuses new requests (UNAVAILABLE), drains or rejects the queue (options.drain_on_stop), lets
  // running batches finish and joins the workers. Every accepted request has been answered when
  // it returns. Idempotent; must not be called from a batch function or a done callback.
  void Stop() {
    std::lock_guard<std::mutex> stop_lock(stop_mu_);
    if (stopped_) return;
    std::deque<Entry> rejected;
    {
      std::lock_guard<std::mutex> lock(mu_);
      stopping_ = true;
      if (!options_.drain_on_stop) {
        rejected.swap(queue_);
        ReportDepthLocked();
      }
      work_cv_.notify_all();
    }
    for (Entry& entry : rejected) {
      rejected_stopped_.fetch_add(1, std::memory_order_relaxed);
      entry.done(Result(absl::UnavailableError("the batcher stopped before the request ran")));
    }
    if (pool_ != nullptr) pool_->Join();
    stopped_ = true;
  }

  DynamicBatcherStats stats() const {
    DynamicBatcherStats stats;
    stats.accepted = accepted_.load(std::memory_order_relaxed);
    stats.rejected_queue_full = rejected_queue_full_.load(std::memory_order_relaxed);
    stats.rejected_stopped = rejected_stopped_.load(std::memory_order_relaxed);
    stats.deadline_exceeded = deadline_exceeded_.load(std::memory_order_relaxed);
    stats.cancelled = cancelled_.load(std::memory_order_relaxed);
    stats.batches = batches_.load(std::memory_order_relaxed);
    stats.requests_run = requests_run_.load(std::memory_order_relaxed);
    stats.requests_failed = requests_failed_.load(std::memory_order_relaxed);
    std::lock_guard<std::mutex> lock(mu_);
    stats.queue_depth = static_cast<int>(queue_.size());
    stats.busy_workers = busy_workers_;
    return stats;
  }

  const DynamicBatcherOptions& options() const { return options_; }

 private:
  struct Entry {
    Request request;
    BatchRequestControl control;
    Done done;
    absl::Time enqueued;
  };

  DynamicBatcher(const DynamicBatcherOptions& options, BatchFunction batch_function,
                 DynamicBatcherHooks hooks)
      : options_(options), batch_function_(std::move(batch_function)), hooks_(std::move(hooks)) {}

  static bool IsStale(const Entry& entry, absl::Time now) {
    return now >= entry.control.deadline ||
           (entry.control.is_cancelled && entry.control.is_cancelled());
  }

  // Moves every expired or cancelled request out of the queue into `dropped`.
  void DropStaleLocked(absl::Time now, std::vector<Entry>* dropped) {
    auto keep = queue_.begin();
    for (auto it = queue_.begin(); it != queue_.end(); ++it) {
      if (IsStale(*it, now)) {
        dropped->push_back(std::move(*it));
      } else {
        if (keep != it) *keep = std::move(*it);
        ++keep;
      }
    }
    if (keep != queue_.end()) {
      queue_.erase(keep, queue_.end());
      ReportDepthLocked();
    }
  }

  // Moves expired or cancelled requests at the front of the queue into `dropped`, so the front is
  // a request that will run (its age sets when the next batch goes).
  void DropStaleFrontLocked(absl::Time now, std::vector<Entry>* dropped) {
    bool changed = false;
    while (!queue_.empty() && IsStale(queue_.front(), now)) {
      dropped->push_back(std::move(queue_.front()));
      queue_.pop_front();
      changed = true;
    }
    if (changed) ReportDepthLocked();
  }

  void ReportDepthLocked() {
    if (hooks_.queue_depth) hooks_.queue_depth(static_cast<int>(queue_.size()));
  }

  // Answers requests that left the queue without running. `now` is when they were found stale.
  void AnswerDropped(std::vector<Entry>& dropped, absl::Time now) {
    for (Entry& entry : dropped) {
      const std::string waited = absl::StrCat(
          " after waiting ", absl::FormatDuration(now - entry.enqueued), " in the batch queue");
      if (now >= entry.control.deadline) {
        deadline_exceeded_.fetch_add(1, std::memory_order_relaxed);
        entry.done(Result(absl::DeadlineExceededError(absl::StrCat("deadline passed", waited))));
      } else {
        cancelled_.fetch_add(1, std::memory_order_relaxed);
        entry.done(Result(absl::CancelledError(absl::StrCat("request cancelled", waited))));
      }
    }
    dropped.clear();
  }

  // Each worker: wait for a batch to form, take it, run it; return once stopping and empty.
  void WorkerLoop() {
    std::vector<Entry> batch;
    std::vector<Entry> dropped;
    batch.reserve(options_.max_batch);
    for (;;) {
      absl::Time now;
      {
        std::unique_lock<std::mutex> lock(mu_);
        for (;;) {
          while (queue_.empty() && !stopping_) work_cv_.wait(lock);
          now = absl::Now();
          DropStaleFrontLocked(now, &dropped);
          if (queue_.empty()) {
            split_left_ = 0;
            if (!dropped.empty()) break;  // answer them outside the lock, then wait again
            if (stopping_) return;
            continue;
          }
          if (static_cast<int>(queue_.size()) >= options_.max_batch || stopping_ ||
              split_left_ > 0) {
            break;
          }
          const absl::Time dispatch_at = queue_.front().enqueued + options_.max_queue_delay;
          if (now >= dispatch_at) break;
          work_cv_.wait_until(lock, absl::ToChronoTime(dispatch_at));
        }
        // This worker's share of what is due, split once among every worker, busy or not (see
        // the header); the rest of a split stays due at once, in shares of the same size.
        if (split_left_ == 0) {
          const int due = std::min(options_.max_batch, static_cast<int>(queue_.size()));
          split_left_ = due;
          split_share_ = (due + options_.workers - 1) / options_.workers;
        }
        int taken = 0;
        while (!queue_.empty() && static_cast<int>(batch.size()) < split_share_) {
          Entry& front = queue_.front();
          if (IsStale(front, now)) {
            dropped.push_back(std::move(front));
          } else {
            batch.push_back(std::move(front));
          }
          queue_.pop_front();
          ++taken;
        }
        split_left_ = queue_.empty() ? 0 : std::max(0, split_left_ - taken);
        ReportDepthLocked();
        if (!batch.empty()) ++busy_workers_;
        // What is left needs another worker: at once when full or left due by a split, else when
        // its oldest has waited max_queue_delay.
        if (!queue_.empty()) work_cv_.notify_one();
      }
      AnswerDropped(dropped, now);
      if (batch.empty()) continue;
      RunBatch(batch);
      batch.clear();
      {
        std::lock_guard<std::mutex> lock(mu_);
        --busy_workers_;
      }
    }
  }

  void RunBatch(std::vector<Entry>& batch) {
    const absl::Time start = absl::Now();
    std::vector<Request> requests;
    requests.reserve(batch.size());
    for (Entry& entry : batch) {
      if (hooks_.queue_wait) hooks_.queue_wait(absl::ToDoubleSeconds(start - entry.enqueued));
      requests.push_back(std::move(entry.request));
    }
    absl::StatusOr<std::vector<Result>> results;
    try {
      results = batch_function_(absl::MakeSpan(requests));
    } catch (const std::exception& error) {
      results = absl::InternalError(absl::StrCat("batch function threw: ", error.what()));
    } catch (...) {
      results = absl::InternalError("batch function threw a non-standard exception");
    }
    const double seconds = absl::ToDoubleSeconds(absl::Now() - start);
    if (results.ok() && results->size() != batch.size()) {
      results = absl::InternalError(absl::StrCat("batch function returned ", results->size(),
                                                 " results for ", batch.size(), " requests"));
    }
    std::vector<Result> answers;
    answers.reserve(batch.size());
    uint64_t failed = 0;
    for (size_t i = 0; i < batch.size(); ++i) {
      answers.push_back(results.ok() ? std::move((*results)[i]) : Result(results.status()));
      if (!answers.back().ok()) ++failed;
    }
    // Counted before anyone is answered, so a caller holding its answer sees it in stats().
    batches_.fetch_add(1, std::memory_order_relaxed);
    requests_run_.fetch_add(batch.size(), std::memory_order_relaxed);
    requests_failed_.fetch_add(failed, std::memory_order_relaxed);
    if (hooks_.batch_done) hooks_.batch_done(static_cast<int>(batch.size()), seconds);
    for (size_t i = 0; i < batch.size(); ++i) batch[i].done(std::move(answers[i]));
  }

  const DynamicBatcherOptions options_;
  const BatchFunction batch_function_;
  const DynamicBatcherHooks hooks_;
  std::unique_ptr<WorkerPool> pool_;

  // std::mutex rather than absl::Mutex: ThreadSanitizer sees through pthreads, not through an
  // uninstrumented Abseil library (tests/server runs this under TSan). Methods named *Locked
  // need mu_ held.
  mutable std::mutex mu_;
  std::condition_variable work_cv_;
  std::deque<Entry> queue_;  // guarded by mu_
  bool stopping_ = false;    // guarded by mu_
  // Guarded by mu_: requests at the queue's front still due from a split, and each worker's share.
  int split_left_ = 0;
  int split_share_ = 0;
  int busy_workers_ = 0;  // guarded by mu_

  std::mutex stop_mu_;    // serialises Stop()
  bool stopped_ = false;  // guarded by stop_mu_

  std::atomic<uint64_t> accepted_{0};
  std::atomic<uint64_t> rejected_queue_full_{0};
  std::atomic<uint64_t> rejected_stopped_{0};
  std::atomic<uint64_t> deadline_exceeded_{0};
  std::atomic<uint64_t> cancelled_{0};
  std::atomic<uint64_t> batches_{0};
  std::atomic<uint64_t> requests_run_{0};
  std::atomic<uint64_t> requests_failed_{0};
};

}  // namespace rpsr::server

#endif  // RPSR_SERVER_DYNAMIC_BATCHER_H_
