// Why this exists: civetweb (under prometheus-cpp's Exposer) creates its threads with a fixed
// 100 KiB stack (Debian builds it with USE_STACK_SIZE=102400). glibc puts a thread's static TLS on
// its stack, and a process that links LibTorch carries ~110 KiB of it (OpenBLAS 60 KiB, glog 30
// KiB, libtorch_cpu 10 KiB, ...), so pthread_create fails with EINVAL and the Exposer throws
// "null context when constructing CivetServer". Measured with gdb on rpsrd: setstacksize(102400).
//
// The fix: the server binary defines pthread_attr_setstacksize (exported with
// --export-dynamic-symbol, see server/CMakeLists.txt), which raises any request below
// kThreadStackFloorBytes to it and forwards to glibc's. Requests above the floor pass unchanged.
#ifndef RPSR_SERVER_THREAD_STACK_FLOOR_H_
#define RPSR_SERVER_THREAD_STACK_FLOOR_H_

#include <cstddef>

namespace rpsr::server {

inline constexpr size_t kThreadStackFloorBytes = size_t{1} << 20;

// How many stack-size requests were raised to the floor so far (referencing it also keeps the
// interposer's object file in every binary that links rpsr_server).
int RaisedThreadStackRequests();

}  // namespace rpsr::server

#endif  // RPSR_SERVER_THREAD_STACK_FLOOR_H_
