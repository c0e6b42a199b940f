#include "server/worker_pool.h"

#include <pthread.h>

#include <memory>
#include <utility>

#include "absl/status/status.h"
#include "absl/strings/str_cat.h"

namespace rpsr::server {

absl::StatusOr<std::unique_ptr<WorkerPool>> WorkerPool::Start(const WorkerPoolOptions& options,
                                                              std::function<void(int)> body) {
  if (options.workers < 1) {
    return absl::InvalidArgumentError(
        absl::StrCat("WorkerPool: workers must be >= 1, got ", options.workers));
  }
  if (!body) return absl::InvalidArgumentError("WorkerPool: no body to run");
  std::unique_ptr<WorkerPool> pool(new WorkerPool);
  pool->threads_.reserve(options.workers);
  for (int index = 0; index < options.workers; ++index) {
    pool->threads_.emplace_back(
        [index, init = options.init, body, name = absl::StrCat(options.name_prefix, index)] {
          // Linux keeps 15 characters and a terminating zero; longer names fail to set.
          pthread_setname_np(pthread_self(), name.substr(0, 15).c_str());
          if (init) init(index);
          body(index);
        });
  }
  return pool;
}

WorkerPool::~WorkerPool() { Join(); }

void WorkerPool::Join() {
  for (std::thread& thread : threads_) {
    if (thread.joinable()) thread.join();
  }
}

}  // namespace rpsr::server
