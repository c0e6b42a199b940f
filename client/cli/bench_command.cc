// rpsr bench --server ADDR --clients N --duration S: load on a running server. Each of N client
// threads opens its own connection and session, uploads the pair once (default: the shipped
// object pair) and registers it by id as fast as answers come, for S seconds. Reports the
// throughput, latency percentiles (p50, p90, p99, max, client side), error counts by status
// code, and the server's mean batch size and queue wait.
// Exit codes: 0 done (errors are reported, not fatal), 1 could not start, 2 bad flags.
#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <map>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include "absl/flags/flag.h"
#include "absl/status/status.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "client/cli/cli_progress.h"
#include "client/cli/registration_report.h"
#include "client/cli/sample_pairs.h"
#include "client/cli/service_flags.h"
#include "client/cli/shared_flags.h"
#include "client/cli/subcommands.h"
#include "client/rpsr_client.h"
#include "core/io/point_cloud_io.h"

ABSL_FLAG(int, clients, 4, "bench: concurrent clients (threads, each with its own session)");
ABSL_FLAG(double, duration, 10.0, "bench: seconds of load");
ABSL_FLAG(std::string, source, "", "bench: source cloud file (default: the shipped object pair)");
ABSL_FLAG(std::string, target, "", "bench: target cloud file (default: the shipped object pair)");

namespace rpsr::client {
namespace {

int Fail(int code, const std::string& message) {
  std::fprintf(stderr, "rpsr bench: %s\n", message.c_str());
  return code;
}

struct ClientTally {
  std::vector<double> latencies_s;
  std::map<std::string, int> errors;  // status code name -> count
  double batch_size_sum = 0.0;
  double queue_seconds_sum = 0.0;
};

double Percentile(std::vector<double>& sorted, double q) {
  if (sorted.empty()) return 0.0;
  const size_t k = static_cast<size_t>(q * static_cast<double>(sorted.size() - 1) + 0.5);
  return sorted[std::min(k, sorted.size() - 1)];
}

}  // namespace

int RunBenchCommand(const std::vector<std::string>& args) {
  if (!args.empty()) return Fail(2, "takes no arguments (see rpsr bench --help)");
  if (absl::GetFlag(FLAGS_server).empty()) return Fail(2, "--server ADDR is required");
  const int clients = absl::GetFlag(FLAGS_clients);
  const double duration = absl::GetFlag(FLAGS_duration);
  if (clients < 1 || clients > 1024) return Fail(2, "--clients must be in 1..1024");
  if (!(duration > 0)) return Fail(2, "--duration must be positive");
  std::string source_path = absl::GetFlag(FLAGS_source);
  std::string target_path = absl::GetFlag(FLAGS_target);
  if (source_path.empty() != target_path.empty()) {
    return Fail(2, "give both --source and --target, or neither");
  }
  core::PointCloud source_cloud;
  core::PointCloud target_cloud;
  if (source_path.empty()) {
    absl::StatusOr<SamplePair> pair = LoadSamplePair(absl::GetFlag(FLAGS_data), "object");
    if (!pair.ok()) return Fail(1, absl::StrCat("no sample pair: ", pair.status().message()));
    source_cloud = std::move(pair->source);
    target_cloud = std::move(pair->target);
  } else {
    absl::StatusOr<core::PointCloud> read = core::ReadPointCloud(source_path);
    if (!read.ok()) return Fail(1, std::string(read.status().message()));
    source_cloud = *std::move(read);
    read = core::ReadPointCloud(target_path);
    if (!read.ok()) return Fail(1, std::string(read.status().message()));
    target_cloud = *std::move(read);
  }
  const core::PointCloud* source = &source_cloud;
  const core::PointCloud* target = &target_cloud;
  absl::StatusOr<ClientOptions> client_options = ClientOptionsFromFlags();
  if (!client_options.ok()) return Fail(2, std::string(client_options.status().message()));
  // Retrying hides errors from the tally: a bench counts each answer as it comes.
  client_options->retry.max_attempts = 1;

  // Connect and upload before the clock starts.
  std::vector<std::unique_ptr<Client>> connections;
  std::vector<std::unique_ptr<Session>> sessions;
  std::vector<std::pair<uint64_t, uint64_t>> pair_ids;
  std::string mode;
  SessionOptions session_options;
  session_options.tree_max_depth = ChooseTreeDepth(*source, *target, ExplicitTreeDepthFlag());
  for (int c = 0; c < clients; ++c) {
    absl::StatusOr<std::unique_ptr<Client>> client = Client::Connect(*client_options);
    if (!client.ok()) return Fail(1, client.status().ToString());
    if (c == 0) {
      absl::StatusOr<ServerInfo> info = (*client)->GetServerInfo();
      if (!info.ok()) return Fail(1, absl::StrCat("GetServerInfo: ", info.status().ToString()));
      mode = ChooseMode(*source, *target, ExplicitModeFlag(), info->model_name, nullptr);
    }
    absl::StatusOr<std::unique_ptr<Session>> session = (*client)->CreateSession(session_options);
    if (!session.ok()) return Fail(1, absl::StrCat("CreateSession: ", session.status().ToString()));
    absl::StatusOr<UploadedCloud> s = (*session)->Upload(source->points);
    absl::StatusOr<UploadedCloud> t = (*session)->Upload(target->points);
    if (!s.ok() || !t.ok()) {
      return Fail(1, absl::StrCat("upload: ", (s.ok() ? t.status() : s.status()).ToString()));
    }
    pair_ids.push_back({s->cloud_id, t->cloud_id});
    connections.push_back(*std::move(client));
    sessions.push_back(*std::move(session));
  }

  RegisterOptions register_options;
  register_options.mode = mode;
  ApplyRegistrationFlags(register_options);
  std::vector<ClientTally> tallies(static_cast<size_t>(clients));
  std::atomic<int64_t> answered{0};
  const auto start = std::chrono::steady_clock::now();
  const auto end = start + std::chrono::duration_cast<std::chrono::steady_clock::duration>(
                               std::chrono::duration<double>(duration));
  std::vector<std::thread> threads;
  for (int c = 0; c < clients; ++c) {
    threads.emplace_back([&, c] {
      ClientTally& tally = tallies[static_cast<size_t>(c)];
      while (std::chrono::steady_clock::now() < end) {
        const auto sent = std::chrono::steady_clock::now();
        absl::StatusOr<RegistrationResult> result =
            sessions[c]->Register(pair_ids[c].first, pair_ids[c].second, register_options);
        const double latency =
            std::chrono::duration<double>(std::chrono::steady_clock::now() - sent).count();
        if (result.ok()) {
          tally.latencies_s.push_back(latency);
          tally.batch_size_sum += result->timings.batch_size;
          tally.queue_seconds_sum += result->timings.queue_seconds;
        } else {
          ++tally.errors[absl::StatusCodeToString(result.status().code())];
        }
        answered.fetch_add(1, std::memory_order_relaxed);
      }
    });
  }
  const bool json = absl::GetFlag(FLAGS_json);
  ProgressBar bar("bench");
  while (std::chrono::steady_clock::now() < end) {
    std::this_thread::sleep_for(std::chrono::milliseconds(250));
    const double elapsed =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    if (!json) {
      bar.Update(std::min(elapsed, duration), duration, duration - elapsed,
                 absl::StrFormat("%lld answers, %.1f/s", static_cast<long long>(answered.load()),
                                 answered.load() / std::max(elapsed, 1e-9)));
    }
  }
  for (std::thread& thread : threads) thread.join();
  if (!json) bar.Finish();
  const double elapsed =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();

  std::vector<double> latencies;
  std::map<std::string, int> errors;
  double batch_size_sum = 0.0;
  double queue_seconds_sum = 0.0;
  int error_count = 0;
  for (const ClientTally& tally : tallies) {
    latencies.insert(latencies.end(), tally.latencies_s.begin(), tally.latencies_s.end());
    for (const auto& [code, count] : tally.errors) {
      errors[code] += count;
      error_count += count;
    }
    batch_size_sum += tally.batch_size_sum;
    queue_seconds_sum += tally.queue_seconds_sum;
  }
  std::sort(latencies.begin(), latencies.end());
  const size_t ok = latencies.size();
  const double throughput = ok / elapsed;
  const double p50 = 1e3 * Percentile(latencies, 0.50);
  const double p90 = 1e3 * Percentile(latencies, 0.90);
  const double p99 = 1e3 * Percentile(latencies, 0.99);
  const double max = latencies.empty() ? 0.0 : 1e3 * latencies.back();
  const double mean_batch = ok > 0 ? batch_size_sum / ok : 0.0;
  const double mean_queue_ms = ok > 0 ? 1e3 * queue_seconds_sum / ok : 0.0;
  std::string error_text;
  for (const auto& [code, count] : errors) {
    absl::StrAppend(&error_text, error_text.empty() ? "" : ", ", json ? "\"" : "", code,
                    json ? "\": " : " ", count);
  }
  if (json) {
    std::printf(
        "{\"server\": %s, \"clients\": %d, \"duration_s\": %.3f, \"mode\": %s, \"source_points\": "
        "%zu, \"target_points\": %zu, \"tree_depth\": %d, \"requests_ok\": %zu, \"errors\": %d, "
        "\"errors_by_code\": {%s}, \"throughput_per_s\": %.3f, \"latency_ms\": {\"p50\": %.3f, "
        "\"p90\": %.3f, \"p99\": %.3f, \"max\": %.3f}, \"mean_batch_size\": %.3f, "
        "\"mean_queue_ms\": %.3f}\n",
        JsonString(absl::GetFlag(FLAGS_server)).c_str(), clients, elapsed, JsonString(mode).c_str(),
        source->size(), target->size(), session_options.tree_max_depth, ok, error_count,
        error_text.c_str(), throughput, p50, p90, p99, max, mean_batch, mean_queue_ms);
  } else {
    std::printf("server %s, %d clients, %.1f s, mode %s, %zu -> %zu points, tree depth %d\n",
                absl::GetFlag(FLAGS_server).c_str(), clients, elapsed, mode.c_str(), source->size(),
                target->size(), session_options.tree_max_depth);
    std::printf("requests: %zu ok, %d errors%s%s%s\n", ok, error_count,
                error_text.empty() ? "" : " (", error_text.c_str(), error_text.empty() ? "" : ")");
    std::printf("throughput: %.1f registrations/s\n", throughput);
    std::printf("latency (client side): p50 %.1f ms, p90 %.1f ms, p99 %.1f ms, max %.1f ms\n", p50,
                p90, p99, max);
    std::printf("server: mean batch size %.2f, mean queue wait %.2f ms\n", mean_batch,
                mean_queue_ms);
  }
  return 0;
}

}  // namespace rpsr::client
