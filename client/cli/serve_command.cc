// rpsr serve: the registration service in this process (the same as rpsrd, with its most used
// flags): serves until SIGINT or SIGTERM, then drains (calls in flight finish) and exits 0.
#include <pthread.h>

#include <csignal>
#include <cstdio>
#include <string>
#include <vector>

#include "absl/flags/flag.h"
#include "client/cli/service_flags.h"
#include "client/cli/shared_flags.h"
#include "client/cli/subcommands.h"
#include "server/rpsr_server.h"

ABSL_FLAG(std::string, address, "0.0.0.0:50051",
          "serve: gRPC listening address host:port (port 0 picks a free one, printed)");
ABSL_FLAG(std::string, metrics_address, "",
          "serve: Prometheus /metrics address host:port; empty: none");
ABSL_FLAG(int, max_batch, 16, "serve: registrations per batched forward pass");
ABSL_FLAG(int, workers, 0,
          "serve: concurrent batches (worker threads); 0: one per hardware thread");

namespace rpsr::client {

int RunServeCommand(const std::vector<std::string>& args) {
  if (!args.empty()) {
    std::fprintf(stderr, "rpsr serve: takes no arguments (see rpsr serve --help)\n");
    return 2;
  }
  // SIGINT and SIGTERM are taken by sigwait below: block them before the server's threads start.
  sigset_t signals;
  sigemptyset(&signals);
  sigaddset(&signals, SIGTERM);
  sigaddset(&signals, SIGINT);
  pthread_sigmask(SIG_BLOCK, &signals, nullptr);

  server::ServerOptions options;
  options.address = absl::GetFlag(FLAGS_address);
  options.metrics_address = absl::GetFlag(FLAGS_metrics_address);
  options.registrar_config = RegistrarConfigFromModelFlag(absl::GetFlag(FLAGS_model));
  options.batching.max_batch = absl::GetFlag(FLAGS_max_batch);
  options.batching.workers = absl::GetFlag(FLAGS_workers);
  options.batching.intra_op_threads = absl::GetFlag(FLAGS_threads);
  if (const std::string token = absl::GetFlag(FLAGS_token); !token.empty()) {
    options.auth_tokens = {token};
  }
  absl::StatusOr<std::unique_ptr<server::RunningServer>> running = server::StartServer(options);
  if (!running.ok()) {
    std::fprintf(stderr, "rpsr serve: %s\n", running.status().ToString().c_str());
    return 1;
  }
  if (absl::GetFlag(FLAGS_json)) {
    std::printf("{\"address\": \"%s\", \"port\": %d, \"metrics_port\": %d}\n",
                (*running)->target().c_str(), (*running)->port(), (*running)->metrics_port());
  } else {
    std::printf("rpsr serve: listening on %s (port %d)%s; Ctrl-C to stop\n",
                (*running)->target().c_str(), (*running)->port(),
                (*running)->metrics_port() > 0
                    ? (", metrics on port " + std::to_string((*running)->metrics_port())).c_str()
                    : "");
  }
  std::fflush(stdout);
  int signal = 0;
  sigwait(&signals, &signal);
  std::fprintf(stderr, "rpsr serve: signal %d, draining\n", signal);
  (*running)->Shutdown(absl::Seconds(30));
  return 0;
}

}  // namespace rpsr::client
