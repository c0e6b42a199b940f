// rpsrd: the rpsr registration service (proto/rpsr/v1/registration.proto).
//
//   rpsrd --address 0.0.0.0:50051 --metrics_address 0.0.0.0:9464
//
// Health (grpc.health.v1) says NOT_SERVING until the model is loaded and while draining. SIGTERM
// or SIGINT drains: health turns NOT_SERVING, calls in flight finish (up to --shutdown_grace),
// then the process exits 0. Logs are key=value lines on stderr.
#include <pthread.h>
#include <unistd.h>

#include <atomic>
#include <csignal>
#include <cstdint>
#include <cstdio>
#include <fstream>
#include <string>
#include <thread>
#include <vector>

#include "absl/flags/flag.h"
#include "absl/flags/parse.h"
#include "absl/flags/usage.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/strip.h"
#include "absl/time/time.h"
#include "core/net/openblas_core_choice.h"
#include "server/rpsr_server.h"
#include "server/structured_log.h"

namespace {
const rpsr::server::ServerOptions kDefaults;
const rpsr::server::CacheOptions kCache;
const rpsr::server::BatchingOptions kBatching;
}  // namespace

ABSL_FLAG(std::string, address, kDefaults.address,
          "gRPC listening address host:port (port 0 picks one)");
ABSL_FLAG(std::string, metrics_address, kDefaults.metrics_address,
          "Prometheus /metrics address host:port; empty disables it");
ABSL_FLAG(std::string, model, kDefaults.registrar_config.model,
          "Embedded model to serve (core/models/<name>: objects, objects-small)");
ABSL_FLAG(std::string, model_path, "", "Weights file (.rpsrw) instead of an embedded model");
ABSL_FLAG(std::string, confidence_path, "",
          "Confidence calibration file; empty: the one shipped with the model");
ABSL_FLAG(uint64_t, cache_memory_bytes, kCache.memory_budget_bytes,
          "Memory budget of all cached trees, bytes; LRU eviction beyond it");
ABSL_FLAG(uint32_t, max_sessions, kCache.max_sessions, "Most live sessions");
ABSL_FLAG(uint32_t, max_clouds_per_session, kCache.max_clouds_per_session,
          "Most cached clouds per session");
ABSL_FLAG(absl::Duration, default_ttl, kCache.default_ttl,
          "Session time to live after its last use, when CreateSession asks for none");
ABSL_FLAG(absl::Duration, max_ttl, kCache.max_ttl, "Longest time to live a session may ask for");
ABSL_FLAG(int, max_batch, kBatching.max_batch, "Registrations per batched forward pass");
ABSL_FLAG(absl::Duration, max_queue_delay, kBatching.max_queue_delay,
          "Longest a registration waits for companions");
ABSL_FLAG(int, max_queue, kBatching.max_queue,
          "Registrations waiting at most; more are answered RESOURCE_EXHAUSTED");
ABSL_FLAG(int, workers, kBatching.workers,
          "Concurrent batches (worker threads); 0: one per hardware thread (CPU inference; with "
          "a GPU use 1-2 so that batches form)");
ABSL_FLAG(int, intra_op_threads, kBatching.intra_op_threads, "LibTorch threads per worker");
ABSL_FLAG(int, prepared_targets, kBatching.prepared_targets,
          "Prepared targets kept at most, for cached clouds registered against again (an "
          "object's ~260 KB, a 120k-point scan's ~890 KB); 0: none");
ABSL_FLAG(uint64_t, prepared_target_bytes, kBatching.prepared_target_bytes,
          "Memory of the prepared targets kept at most, in bytes (beside --cache_memory_bytes); "
          "0: none");
ABSL_FLAG(uint64_t, max_points_per_cloud, kDefaults.max_points_per_cloud,
          "Most points in one uploaded cloud or Track frame");
ABSL_FLAG(uint64_t, max_inline_points, kDefaults.max_inline_points,
          "Most points of a cloud sent inline in Register");
ABSL_FLAG(uint32_t, max_open_streams, kDefaults.max_open_streams,
          "UploadCloud and Track streams open at once");
ABSL_FLAG(uint64_t, max_message_bytes, kDefaults.max_message_bytes,
          "Largest gRPC message received, bytes");
ABSL_FLAG(int, default_tree_depth, kDefaults.default_tree_max_depth,
          "Tree depth of sessions that ask for none");
ABSL_FLAG(int, min_tree_depth, kDefaults.min_tree_max_depth,
          "Shallowest tree a session may ask for");
ABSL_FLAG(int, max_tree_depth, kDefaults.max_tree_max_depth, "Deepest tree a session may ask for");
ABSL_FLAG(std::string, tls_cert, "", "PEM certificate chain; with --tls_key enables TLS");
ABSL_FLAG(std::string, tls_key, "", "PEM private key of --tls_cert");
ABSL_FLAG(std::string, auth_tokens_file, "",
          "File of accepted bearer tokens, one a line ('#' comments); empty: no authentication");
ABSL_FLAG(absl::Duration, shutdown_grace, absl::Seconds(30),
          "On SIGTERM, how long calls in flight may take before they are cancelled");
ABSL_FLAG(absl::Duration, drain_notice, absl::ZeroDuration(),
          "On SIGTERM, how long health says NOT_SERVING (new calls UNAVAILABLE) before the server "
          "stops accepting connections");
ABSL_FLAG(bool, reflection, true, "Serve gRPC server reflection");
ABSL_FLAG(bool, log_requests, true,
          "One log line per call (the server's own events -- listening, model loaded, draining, "
          "stopped -- are logged either way)");

namespace {

absl::StatusOr<std::vector<std::string>> ReadTokens(const std::string& path) {
  std::ifstream in(path);
  if (!in) return absl::NotFoundError(absl::StrCat("cannot read --auth_tokens_file ", path));
  std::vector<std::string> tokens;
  std::string line;
  while (std::getline(in, line)) {
    absl::string_view token = absl::StripAsciiWhitespace(line);
    if (token.empty() || token.front() == '#') continue;
    tokens.emplace_back(token);
  }
  if (tokens.empty()) {
    return absl::InvalidArgumentError(absl::StrCat("--auth_tokens_file ", path, " has no token"));
  }
  return tokens;
}

}  // namespace

int main(int argc, char** argv) {
  absl::SetProgramUsageMessage(
      "the rpsr registration service (gRPC rpsr.v1.RegistrationService).\n"
      "  rpsrd [--address 0.0.0.0:50051] [--metrics_address 0.0.0.0:9464] [flags]");
  absl::ParseCommandLine(argc, argv);
  // Before any thread runs: OpenBLAS's kernels for CPUs its Debian version does not know.
  const rpsr::core::net::OpenBlasCoreChoice blas = rpsr::core::net::MatchOpenBlasCoreToCpu();
  if (blas.switched) {
    rpsr::server::LogEvent(
        "info", "blas_kernels",
        {{"detected", blas.detected}, {"running", blas.running}, {"reason", blas.reason}});
  }

  // Signals are taken by sigwait in main only: block them before any thread starts.
  sigset_t signals;
  sigemptyset(&signals);
  sigaddset(&signals, SIGTERM);
  sigaddset(&signals, SIGINT);
  pthread_sigmask(SIG_BLOCK, &signals, nullptr);

  rpsr::server::ServerOptions options;
  options.address = absl::GetFlag(FLAGS_address);
  options.metrics_address = absl::GetFlag(FLAGS_metrics_address);
  options.registrar_config.model = absl::GetFlag(FLAGS_model);
  options.registrar_config.model_path = absl::GetFlag(FLAGS_model_path);
  options.registrar_config.confidence_path = absl::GetFlag(FLAGS_confidence_path);
  options.wait_for_model = false;  // listen at once; health says NOT_SERVING while loading
  options.cache.memory_budget_bytes = absl::GetFlag(FLAGS_cache_memory_bytes);
  options.cache.max_sessions = absl::GetFlag(FLAGS_max_sessions);
  options.cache.max_clouds_per_session = absl::GetFlag(FLAGS_max_clouds_per_session);
  options.cache.default_ttl = absl::GetFlag(FLAGS_default_ttl);
  options.cache.max_ttl = absl::GetFlag(FLAGS_max_ttl);
  options.batching.max_batch = absl::GetFlag(FLAGS_max_batch);
  options.batching.max_queue_delay = absl::GetFlag(FLAGS_max_queue_delay);
  options.batching.max_queue = absl::GetFlag(FLAGS_max_queue);
  options.batching.workers = absl::GetFlag(FLAGS_workers);
  options.batching.intra_op_threads = absl::GetFlag(FLAGS_intra_op_threads);
  options.batching.prepared_targets = absl::GetFlag(FLAGS_prepared_targets);
  options.batching.prepared_target_bytes = absl::GetFlag(FLAGS_prepared_target_bytes);
  options.max_points_per_cloud = absl::GetFlag(FLAGS_max_points_per_cloud);
  options.max_inline_points = absl::GetFlag(FLAGS_max_inline_points);
  options.max_open_streams = absl::GetFlag(FLAGS_max_open_streams);
  options.max_message_bytes = absl::GetFlag(FLAGS_max_message_bytes);
  options.default_tree_max_depth = absl::GetFlag(FLAGS_default_tree_depth);
  options.min_tree_max_depth = absl::GetFlag(FLAGS_min_tree_depth);
  options.max_tree_max_depth = absl::GetFlag(FLAGS_max_tree_depth);
  options.tls_cert_file = absl::GetFlag(FLAGS_tls_cert);
  options.tls_key_file = absl::GetFlag(FLAGS_tls_key);
  options.drain_notice = absl::GetFlag(FLAGS_drain_notice);
  options.enable_reflection = absl::GetFlag(FLAGS_reflection);
  options.log_requests = absl::GetFlag(FLAGS_log_requests);
  if (const std::string path = absl::GetFlag(FLAGS_auth_tokens_file); !path.empty()) {
    absl::StatusOr<std::vector<std::string>> tokens = ReadTokens(path);
    if (!tokens.ok()) {
      rpsr::server::LogEvent("error", "start_failed",
                             {{"error", std::string(tokens.status().message())}});
      return 2;
    }
    options.auth_tokens = *std::move(tokens);
  }

  absl::StatusOr<std::unique_ptr<rpsr::server::RunningServer>> server =
      rpsr::server::StartServer(options);
  if (!server.ok()) {
    rpsr::server::LogEvent("error", "start_failed",
                           {{"error", std::string(server.status().message())}});
    return 1;
  }

  // A failed model load ends the process (after the same orderly shutdown as a signal).
  std::atomic<bool> load_failed{false};
  std::thread watcher([&] {
    if (!(*server)->WaitForModel().ok()) {
      load_failed = true;
      kill(getpid(), SIGTERM);
    }
  });

  int signal = 0;
  sigwait(&signals, &signal);
  rpsr::server::LogEvent("info", "signal", {{"signal", signal == SIGTERM ? "SIGTERM" : "SIGINT"}});
  (*server)->Shutdown(absl::GetFlag(FLAGS_shutdown_grace));
  watcher.join();
  return load_failed ? 1 : 0;
}
