// The rpsr registration service in-process: StartServer() brings up the gRPC service of
// proto/rpsr/v1/registration.proto (sessions with a tree cache, chunked uploads, batched
// registration, the Track stream), grpc.health.v1, server reflection and a Prometheus /metrics
// endpoint, and returns a handle with the bound ports. rpsrd (server/rpsrd_main.cc) is a thin
// main over it; tests, benchmarks and the CLI's `rpsr demo` / `rpsr serve` start it in-process.
#ifndef RPSR_SERVER_RPSR_SERVER_H_
#define RPSR_SERVER_RPSR_SERVER_H_

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "absl/status/statusor.h"
#include "absl/time/time.h"
#include "core/registrar/registrar.h"

namespace rpsr::server {

// Limits of the per-session tree cache (see session_store.h).
struct CacheOptions {
  // All cached trees together, bytes (Octree::MemoryBytes). Beyond it the least recently used
  // clouds of any session are evicted.
  uint64_t memory_budget_bytes = 2ull << 30;
  uint32_t max_sessions = 1024;
  uint32_t max_clouds_per_session = 4096;
  // Session time to live after its last use, when CreateSession asks for none (0), and the most a
  // session may ask for.
  absl::Duration default_ttl = absl::Minutes(10);
  absl::Duration max_ttl = absl::Hours(24);
};

// Registration batching across clients (Triton semantics; see dynamic_batcher.h).
struct BatchingOptions {
  int max_batch = 16;
  // Zero: on a CPU a batch costs about what its pairs cost one by one (tests/bench/
  // service_load_bench), so waiting for companions only adds latency; batches still form from the
  // requests that gather while the workers are busy. Raise it where batching pays (a GPU).
  absl::Duration max_queue_delay = absl::ZeroDuration();
  int max_queue = 1024;
  // Concurrent batches, and LibTorch intra-op threads each (DEPS.md: one per worker is best).
  // workers 0: one per hardware thread, so a server uses its machine by default (on this 2-core
  // machine 16 clients got 1.9x the pairs per second of one worker:
  // tests/bench/notes/service-load-notes.md, Two workers). That is right for CPU inference, where a
  // batch costs what its pairs cost one by one; with a GPU, where batches pay, run 1-2 workers: the
  // workers split what is due (dynamic_batcher.h), so many workers form small batches.
  int workers = 0;
  int intra_op_threads = 1;
  // Prepared targets kept for cached clouds registered against again (PreparedTargetCache): at
  // most this many and this many bytes (beside the cache's trees, cache.max_memory_bytes; an
  // object's is ~260 KB, a 120k-point scan's ~890 KB, with the network's encoding); 0: none.
  // 160 MiB holds 512 objects' (service_load_bench cycles through 256 targets: an LRU smaller than
  // that would serve none) or ~185 scans'.
  int prepared_targets = 512;
  uint64_t prepared_target_bytes = uint64_t{160} << 20;
};

struct ServerOptions {
  // host:port for gRPC; port 0 picks a free port (see RunningServer::port()).
  std::string address = "0.0.0.0:50051";
  // host:port of the Prometheus exposer (/metrics); port 0 picks a free port; empty: none.
  std::string metrics_address = "0.0.0.0:9464";

  // The model. When `registrar` is set it is used as is (shared, e.g. with an in-process
  // benchmark) and registrar_config is ignored.
  core::RegistrarConfig registrar_config;
  std::shared_ptr<const core::Registrar> registrar;
  // true: StartServer returns once the model is loaded (or its load error). false: it returns at
  // once, health is NOT_SERVING and Register answers UNAVAILABLE until the model is loaded.
  bool wait_for_model = true;

  CacheOptions cache;
  BatchingOptions batching;

  // Input limits.
  uint64_t max_points_per_cloud = 2'000'000;
  uint64_t max_inline_points = 16'384;  // per inline cloud of Register
  // UploadCloud and Track streams open at once; one more is RESOURCE_EXHAUSTED. Each holds up to
  // max_points_per_cloud points while a cloud arrives, so this bounds that memory.
  uint32_t max_open_streams = 256;
  // Largest gRPC message received, bytes (the default gRPC limit is 4 MiB; upload in chunks).
  uint64_t max_message_bytes = 4u << 20;
  // Tree depth of sessions that ask for none, and the range a session may ask for.
  int default_tree_max_depth = 6;
  int min_tree_max_depth = 5;
  int max_tree_max_depth = 12;

  // TLS: both files (PEM) or neither (plaintext).
  std::string tls_cert_file;
  std::string tls_key_file;
  // Bearer tokens accepted in "authorization: Bearer <token>" metadata; empty: no authentication.
  // A session is bound to the token that created it.
  std::vector<std::string> auth_tokens;

  // On Shutdown: how long health says NOT_SERVING and new calls are answered UNAVAILABLE before
  // gRPC stops accepting connections, so that load balancers watching health move traffic away
  // first (calls in flight go on throughout). 0: stop accepting at once. Skipped by a server that
  // never said SERVING (its model never loaded): no balancer sends it traffic.
  absl::Duration drain_notice = absl::ZeroDuration();

  bool enable_reflection = true;
  // Structured logs (key=value lines on stderr) of each call; off in tests.
  bool log_requests = true;
  // The server's own events on stderr (listening, model loaded, draining, stopped), independent of
  // log_requests (an operator who turns the per-call lines off still sees the server start and
  // stop). Off where a program embeds the server and owns its output (rpsr demo) and in tests.
  bool log_lifecycle = true;
};

class ServerState;

// A running server. Destroying it shuts it down (as Shutdown with the default grace).
class RunningServer {
 public:
  ~RunningServer();
  RunningServer(const RunningServer&) = delete;
  RunningServer& operator=(const RunningServer&) = delete;

  int port() const;          // bound gRPC port
  int metrics_port() const;  // bound metrics port; 0 when metrics are off
  // "127.0.0.1:<port>" when the server listens on all interfaces, else its host with the port.
  std::string target() const;

  // Graceful shutdown: health turns NOT_SERVING, new calls are refused (UNAVAILABLE), queued and
  // running registrations finish (up to `grace`, after which calls are cancelled), then the
  // server stops. Idempotent; safe from any thread but a handler's.
  void Shutdown(absl::Duration grace = absl::Seconds(30));
  // Blocks until Shutdown has completed (e.g. from another thread on SIGTERM).
  void Wait();
  // Whether the model is loaded (health SERVING, unless draining).
  bool ready() const;
  // Blocks until the model is loaded (OK) or its load failed (the error); at once when
  // StartServer waited for the model.
  absl::Status WaitForModel();

 private:
  friend absl::StatusOr<std::unique_ptr<RunningServer>> StartServer(const ServerOptions& options);
  explicit RunningServer(std::unique_ptr<ServerState> state);
  std::unique_ptr<ServerState> state_;
};

// Validates the options (InvalidArgument naming the field), loads the model (unless
// wait_for_model is false), binds the ports (Unavailable when one is taken) and starts serving.
absl::StatusOr<std::unique_ptr<RunningServer>> StartServer(const ServerOptions& options);

// rpsr's version as reported by GetServerInfo.
const char* ServerVersion();

}  // namespace rpsr::server

#endif  // RPSR_SERVER_RPSR_SERVER_H_
