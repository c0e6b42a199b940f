// Uploading a 120k-point LiDAR scan to rpsrd (issue 6: at most 15 ms on loopback, tree included):
// the real server in-process on 127.0.0.1 and rpsr::Client, as a user would call it. One upload
// = the chunked client stream, the server's checks, the depth-9 tree build and the answer.
// Counters: ms per upload, the server's tree build (ms) and the chunks sent.
//
//   OMP_WAIT_POLICY=PASSIVE build/tests/bench/upload_bench --benchmark_counters_tabular=true
#include <cstdio>
#include <cstdlib>
#include <memory>
#include <string>
#include <vector>

#include "benchmark/benchmark.h"
#include "client/rpsr_client.h"
#include "core/synth/lidar_sequence.h"
#include "server/rpsr_server.h"

namespace rpsr {
namespace {

[[noreturn]] void Die(const absl::Status& status) {
  std::fprintf(stderr, "upload_bench: %s\n", status.ToString().c_str());
  std::abort();
}

const std::vector<Eigen::Vector3f>& Scan() {
  static const auto* points = [] {
    core::LidarSequenceOptions options;
    options.frame_count = 1;
    options.seed = 7;
    auto simulator = core::LidarSequenceSimulator::Create(options);
    if (!simulator.ok()) std::abort();
    return new std::vector<Eigen::Vector3f>(simulator->SimulateFrame(0).cloud.points);
  }();
  return *points;
}

server::RunningServer& Server() {
  static server::RunningServer* running = [] {
    server::ServerOptions options;
    options.address = "127.0.0.1:0";
    options.metrics_address = "";
    auto started = server::StartServer(options);
    if (!started.ok()) Die(started.status());
    return started->release();
  }();
  return *running;
}

// A new connection to the server and a LiDAR session on it (trees to depth 9, no copy of the
// points kept in the client).
struct Connection {
  std::unique_ptr<client::Client> client;
  std::unique_ptr<client::Session> session;
};
Connection Connect(uint64_t chunk_points) {
  client::ClientOptions options;
  options.address = "127.0.0.1:" + std::to_string(Server().port());
  options.chunk_points = chunk_points;
  auto connected = client::Client::Connect(options);
  if (!connected.ok()) Die(connected.status());
  client::SessionOptions session_options;
  session_options.tree_max_depth = 9;
  session_options.keep_points_for_reupload = false;
  auto session = (*connected)->CreateSession(session_options);
  if (!session.ok()) Die(session.status());
  return {*std::move(connected), *std::move(session)};
}

// Arg 0: points per upload message.
void BM_Upload120kScan(benchmark::State& state) {
  const uint64_t chunk_points = static_cast<uint64_t>(state.range(0));
  Connection connection = Connect(chunk_points);
  client::Session* session = connection.session.get();
  const std::vector<Eigen::Vector3f>& points = Scan();
  double build_seconds = 0.0;
  for (auto _ : state) {
    auto uploaded = session->Upload(points);
    if (!uploaded.ok()) {
      state.SkipWithError(std::string(uploaded.status().message()).c_str());
      break;
    }
    build_seconds += uploaded->tree.build_seconds;
    state.PauseTiming();
    (void)session->Release(uploaded->cloud_id);
    state.ResumeTiming();
  }
  state.counters["points"] = static_cast<double>(points.size());
  state.counters["chunks"] = static_cast<double>((points.size() + chunk_points - 1) / chunk_points);
  state.counters["tree_build_ms"] =
      benchmark::Counter(1e3 * build_seconds, benchmark::Counter::kAvgIterations);
}
BENCHMARK(BM_Upload120kScan)
    ->Arg(16384)
    ->Arg(65536)
    ->Arg(131072)
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime();

// The first upload of a fresh connection and session (connection set-up and HTTP/2 flow-control
// windows not yet grown are part of it; connecting itself is not timed).
void BM_FirstUploadOnNewConnection(benchmark::State& state) {
  const std::vector<Eigen::Vector3f>& points = Scan();
  for (auto _ : state) {
    state.PauseTiming();
    Connection connection = Connect(/*chunk_points=*/0);
    state.ResumeTiming();
    auto uploaded = connection.session->Upload(points);
    if (!uploaded.ok()) {
      state.SkipWithError(std::string(uploaded.status().message()).c_str());
      break;
    }
    state.PauseTiming();
    connection.session.reset();  // closes the session, then the connection, untimed
    connection.client.reset();
    state.ResumeTiming();
  }
}
BENCHMARK(BM_FirstUploadOnNewConnection)->Unit(benchmark::kMillisecond)->UseRealTime();

}  // namespace
}  // namespace rpsr

BENCHMARK_MAIN();
