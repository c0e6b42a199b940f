// A fixed set of worker threads, each prepared once by an init callback (e.g. LibTorch's intra-op
// threads: core::SetNetThreads) and then running one body until the body returns. The dynamic
// batcher's workers are such a pool: each worker's body forms batches from the shared queue and
// runs them.
//
// The pool knows nothing of what its workers do: stopping them is the body's business (return
// when told to), and Join waits for that.
#ifndef RPSR_SERVER_WORKER_POOL_H_
#define RPSR_SERVER_WORKER_POOL_H_

#include <functional>
#include <memory>
#include <string>
#include <thread>
#include <vector>

#include "absl/status/statusor.h"

namespace rpsr::server {

struct WorkerPoolOptions {
  // Number of threads, >= 1.
  int workers = 1;
  // Runs first on each worker's own thread, with the worker's index in [0, workers). Empty: none.
  std::function<void(int worker_index)> init;
  // Thread names are "<name_prefix><index>" (truncated to the 15 characters Linux keeps), as seen
  // by top -H, gdb and perf.
  std::string name_prefix = "rpsr-worker-";
};

class WorkerPool {
 public:
  // Starts options.workers threads, each running init(i) then body(i). InvalidArgument when
  // workers < 1 or body is empty.
  static absl::StatusOr<std::unique_ptr<WorkerPool>> Start(const WorkerPoolOptions& options,
                                                           std::function<void(int)> body);
  // Joins (the bodies must have been told to return, or this blocks).
  ~WorkerPool();
  WorkerPool(const WorkerPool&) = delete;
  WorkerPool& operator=(const WorkerPool&) = delete;

  // Waits until every body has returned. Safe to call more than once, from one thread at a time
  // and never from a worker's own.
  void Join();

  int size() const { return static_cast<int>(threads_.size()); }

 private:
  WorkerPool() = default;
  std::vector<std::thread> threads_;
};

}  // namespace rpsr::server

#endif  // RPSR_SERVER_WORKER_POOL_H_
