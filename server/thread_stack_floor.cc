#include "server/thread_stack_floor.h"

#include <dlfcn.h>
#include <pthread.h>

#include <algorithm>
#include <atomic>

namespace rpsr::server {
namespace {
std::atomic<int> raised{0};
}  // namespace

int RaisedThreadStackRequests() { return raised.load(); }

}  // namespace rpsr::server

extern "C" int pthread_attr_setstacksize(pthread_attr_t* attr, size_t stack_size) {
  using Function = int (*)(pthread_attr_t*, size_t);
  static const Function glibc =
      reinterpret_cast<Function>(dlsym(RTLD_NEXT, "pthread_attr_setstacksize"));
  if (stack_size < rpsr::server::kThreadStackFloorBytes) {
    rpsr::server::raised.fetch_add(1);
    stack_size = rpsr::server::kThreadStackFloorBytes;
  }
  return glibc(attr, stack_size);
}
