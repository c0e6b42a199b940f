// Load benchmark of registration serving (issue 6, "How good"): closed-loop clients registering
// cached 2,048-point object pairs (the shipped object model, mode net+refine by default), each
// sending its next request as soon as the previous one is answered.
//
// Parts (--part, default all):
//   inproc   the DynamicBatcher alone driving core::Registrar in this process: 1 and --clients
//            producer threads at max_batch 1 and 16 (max_queue_delay 2 ms and 0), and the
//            registrar called directly from one thread (the in-process baseline).
//   service  the real gRPC server in-process (server/rpsr_server.h) on 127.0.0.1, one channel per
//            client, clouds uploaded once per client and registered by id: the same batching
//            settings at 1 and --clients clients, and the registrar called directly.
// Columns: throughput (answered pairs per second), latency percentiles seen by the clients, mean
// batch size, and added_p50 = the median over calls of (latency - the registrar's own seconds for
// the pair, from the result's timings): what the path around the registrar added (queue wait,
// batch companions' share, thread hand-offs, gRPC). Configurations alternate over --rounds
// rounds, so a machine whose load drifts (a shared build machine) hurts them alike; the table
// gives each round and then the medians over rounds.
//
//   OMP_WAIT_POLICY=PASSIVE build/tests/bench/service_load_bench --clients=16 --seconds=8
#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <functional>
#include <memory>
#include <string>
#include <thread>
#include <vector>

#include "absl/flags/flag.h"
#include "absl/flags/parse.h"
#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "absl/time/clock.h"
#include "absl/time/time.h"
#include "core/data/object_pairs.h"
#include "core/net/blas_info.h"
#include "core/net/openblas_core_choice.h"
#include "core/net/rpsr_net.h"
#include "core/registrar/registrar.h"
#include "core/tree/bh_tree.h"
#include "server/dynamic_batcher.h"
#include "tests/bench/bench_clouds.h"
#ifdef RPSR_SERVICE_LOAD_BENCH_WITH_SERVER
#include "grpcpp/grpcpp.h"
#include "rpsr/v1/registration.grpc.pb.h"
#include "server/rpsr_server.h"
#endif

ABSL_FLAG(std::string, part, "all", "inproc, service or all");
ABSL_FLAG(int, clients, 16, "concurrent closed-loop clients (producer threads)");
ABSL_FLAG(double, seconds, 8.0, "measured seconds per configuration and round");
ABSL_FLAG(double, warmup_seconds, 1.0, "unmeasured seconds before each measurement");
ABSL_FLAG(int, rounds, 3, "rounds over all configurations");
ABSL_FLAG(int, pairs, 16, "distinct object pairs the clients cycle through");
ABSL_FLAG(int, points, 2048, "points per cloud");
ABSL_FLAG(std::string, mode, "net+refine", "registration mode: net, net+refine or refine");
ABSL_FLAG(int, workers, 1, "batcher workers (one LibTorch intra-op thread each)");
ABSL_FLAG(std::string, csv, "", "if set, append one row per configuration and round here");

namespace rpsr {
namespace {

// One closed-loop run: latencies (seconds) of the calls that ended inside the measured window.
struct Measurement {
  std::vector<double> latencies;
  int failed = 0;
  double seconds = 0.0;
  double batch_size_sum = 0.0;  // over the measured calls, when the path reports it
  // Per measured call: its latency less the registrar's own seconds for its pair (as the result's
  // timings report them), i.e. what the path around the registrar added (queueing, batch
  // companions, the service). Empty when the path does not report the registrar's time.
  std::vector<double> added;
  std::string first_error;

  double pairs = 0.0;  // answered pairs (a call may carry several)

  double throughput() const { return pairs / seconds; }
  double Percentile(double q) const { return PercentileOf(latencies, q, 0.0); }
  double mean_batch() const { return latencies.empty() ? 0.0 : batch_size_sum / latencies.size(); }
  double AddedPercentile(double q) const { return PercentileOf(added, q, -1.0); }

 private:
  static double PercentileOf(std::vector<double> values, double q, double if_empty) {
    if (values.empty()) return if_empty;
    std::sort(values.begin(), values.end());
    return values[std::min(values.size() - 1, static_cast<size_t>(q * values.size()))];
  }
};

// A call: returns OK (and the batch size it ran in, 0 if unknown) or the failure.
struct CallInfo {
  int pairs = 1;                    // pairs the call registered
  int batch_size = 0;               // 0: unknown
  double registrar_seconds = -1.0;  // < 0: unknown
};
using Call = std::function<absl::Status(int client, CallInfo* info)>;

// `thread_init` runs first on each client's thread (e.g. LibTorch's per-thread intra-op setting).
Measurement RunClosedLoop(int clients, absl::Duration warmup, absl::Duration measured,
                          const Call& call, const std::function<void()>& thread_init = nullptr) {
  const absl::Time start = absl::Now() + absl::Milliseconds(50);  // let every thread start
  const absl::Time window_begin = start + warmup;
  const absl::Time window_end = window_begin + measured;
  std::vector<Measurement> per_client(clients);
  std::vector<std::thread> threads;
  for (int client = 0; client < clients; ++client) {
    threads.emplace_back([&, client] {
      Measurement& mine = per_client[client];
      if (thread_init) thread_init();
      absl::SleepFor(start - absl::Now());
      for (;;) {
        const absl::Time sent = absl::Now();
        if (sent >= window_end) break;
        CallInfo info;
        const absl::Status status = call(client, &info);
        const absl::Time answered = absl::Now();
        if (answered < window_begin || answered > window_end) continue;
        if (status.ok()) {
          mine.latencies.push_back(absl::ToDoubleSeconds(answered - sent));
          mine.batch_size_sum += info.batch_size;
          mine.pairs += info.pairs;
          if (info.registrar_seconds >= 0) {
            mine.added.push_back(absl::ToDoubleSeconds(answered - sent) - info.registrar_seconds);
          }
        } else {
          if (mine.failed++ == 0) mine.first_error = status.ToString();
        }
      }
    });
  }
  for (auto& thread : threads) thread.join();
  Measurement total;
  total.seconds = absl::ToDoubleSeconds(measured);
  for (const Measurement& mine : per_client) {
    total.latencies.insert(total.latencies.end(), mine.latencies.begin(), mine.latencies.end());
    total.failed += mine.failed;
    total.batch_size_sum += mine.batch_size_sum;
    total.pairs += mine.pairs;
    total.added.insert(total.added.end(), mine.added.begin(), mine.added.end());
    if (total.first_error.empty()) total.first_error = mine.first_error;
  }
  return total;
}

struct ObjectTrees {
  std::vector<core::PointCloud> clouds;  // source, target, source, target, ...
  std::vector<core::Octree> trees;       // the clouds' trees (the server's default depth 6)
};

ObjectTrees MakeObjectTrees(int pairs, int points) {
  ObjectTrees out;
  out.clouds = bench::UnseenObjectClouds(pairs, static_cast<size_t>(points));
  out.trees = bench::TreesOf(out.clouds, core::BarnesHutTreeOptions{});
  return out;
}

struct Row {
  std::string part;
  std::string config;
  int round = 0;
  int clients = 0;
  Measurement measurement;
};

std::string AddedColumn(double seconds) {
  return seconds < -0.5 ? std::string("-") : absl::StrFormat("%.2f", 1e3 * seconds);
}

void PrintRow(const Row& row) {
  const Measurement& m = row.measurement;
  std::printf("%-8s %-44s %5d %7d %9.1f %8.2f %8.2f %8.2f %7.2f %9s %6d\n", row.part.c_str(),
              row.config.c_str(), row.round, row.clients, m.throughput(), 1e3 * m.Percentile(0.5),
              1e3 * m.Percentile(0.9), 1e3 * m.Percentile(0.99), m.mean_batch(),
              AddedColumn(m.AddedPercentile(0.5)).c_str(), m.failed);
  if (m.failed > 0) std::printf("         first error: %s\n", m.first_error.c_str());
  std::fflush(stdout);
  const std::string csv = absl::GetFlag(FLAGS_csv);
  if (!csv.empty()) {
    FILE* file = std::fopen(csv.c_str(), "a");
    if (file == nullptr) return;
    if (std::ftell(file) == 0) {
      std::fprintf(file,
                   "part,configuration,round,clients,pairs_per_s,p50_ms,p90_ms,p99_ms,mean_batch,"
                   "added_p50_ms,failed\n");
    }
    std::fprintf(file, "%s,\"%s\",%d,%d,%.3f,%.4f,%.4f,%.4f,%.3f,%s,%d\n", row.part.c_str(),
                 row.config.c_str(), row.round, row.clients, m.throughput(),
                 1e3 * m.Percentile(0.5), 1e3 * m.Percentile(0.9), 1e3 * m.Percentile(0.99),
                 m.mean_batch(), AddedColumn(m.AddedPercentile(0.5)).c_str(), m.failed);
    std::fclose(file);
  }
}

// added_p50_ms: the median over calls of (latency - the registrar's own seconds for the pair).
void PrintHeader() {
  std::printf("%-8s %-44s %5s %7s %9s %8s %8s %8s %7s %9s %6s\n", "part", "configuration", "round",
              "clients", "pairs/s", "p50_ms", "p90_ms", "p99_ms", "batch", "added_p50", "failed");
}

// Medians over rounds of each configuration, in first-seen order.
void PrintMedians(const std::vector<Row>& rows) {
  std::printf(
      "\nmedians over rounds (added_p50: median over calls of latency minus the registrar's "
      "own time for the pair)\n");
  PrintHeader();
  std::vector<std::string> seen;
  for (const Row& row : rows) {
    const std::string key = row.part + "|" + row.config;
    if (std::find(seen.begin(), seen.end(), key) != seen.end()) continue;
    seen.push_back(key);
    std::vector<const Row*> group;
    for (const Row& other : rows) {
      if (other.part + "|" + other.config == key) group.push_back(&other);
    }
    auto median = [&group](auto value) {
      std::vector<double> values;
      for (const Row* member : group) values.push_back(value(member->measurement));
      std::sort(values.begin(), values.end());
      return values[values.size() / 2];
    };
    std::printf(
        "%-8s %-44s %5s %7d %9.1f %8.2f %8.2f %8.2f %7.2f %9s %6s\n", row.part.c_str(),
        row.config.c_str(), "med", row.clients,
        median([](const Measurement& m) { return m.throughput(); }),
        1e3 * median([](const Measurement& m) { return m.Percentile(0.5); }),
        1e3 * median([](const Measurement& m) { return m.Percentile(0.9); }),
        1e3 * median([](const Measurement& m) { return m.Percentile(0.99); }),
        median([](const Measurement& m) { return m.mean_batch(); }),
        AddedColumn(median([](const Measurement& m) { return m.AddedPercentile(0.5); })).c_str(),
        "");
  }
}

struct BatchingConfig {
  int max_batch;
  absl::Duration max_queue_delay;
  std::string Name() const {
    return absl::StrCat("max_batch=", max_batch, " delay=", absl::FormatDuration(max_queue_delay));
  }
};

const std::vector<BatchingConfig>& BatchingConfigs() {
  static const auto* configs = new std::vector<BatchingConfig>{
      {1, absl::Milliseconds(2)}, {16, absl::Milliseconds(2)}, {16, absl::ZeroDuration()}};
  return *configs;
}

core::RegistrationOptions OptionsFromFlags() {
  auto mode = core::ParseRegistrationMode(absl::GetFlag(FLAGS_mode));
  if (!mode.ok()) {
    std::fprintf(stderr, "%s\n", mode.status().ToString().c_str());
    std::exit(2);
  }
  core::RegistrationOptions options;
  options.mode = *mode;
  return options;
}

// The registrar called directly on one thread: the in-process baseline.
Measurement MeasureDirect(const core::Registrar& registrar, const ObjectTrees& objects,
                          const core::RegistrationOptions& options) {
  const int pairs = static_cast<int>(objects.trees.size() / 2);
  int next = 0;
  return RunClosedLoop(
      1, absl::Seconds(absl::GetFlag(FLAGS_warmup_seconds)),
      absl::Seconds(absl::GetFlag(FLAGS_seconds)),
      [&](int, CallInfo* info) -> absl::Status {
        const int k = next++ % pairs;
        auto result = registrar.Register(objects.trees[2 * k], objects.trees[2 * k + 1], options);
        if (!result.ok()) return result.status();
        info->batch_size = 1;
        info->registrar_seconds = result->timings.total_seconds;
        return absl::OkStatus();
      },
      [] { core::SetNetThreads(1); });
}

// The registrar's RegisterBatch of `batch` pairs called directly on one thread: what batching
// buys at most, without queues or thread hand-offs (latency is the whole batch's).
Measurement MeasureDirectBatch(const core::Registrar& registrar, const ObjectTrees& objects,
                               const core::RegistrationOptions& options, int batch) {
  const int pairs = static_cast<int>(objects.trees.size() / 2);
  std::vector<core::RegistrationRequest> requests;
  for (int i = 0; i < batch; ++i) {
    const int k = i % pairs;
    requests.push_back({&objects.trees[2 * k], &objects.trees[2 * k + 1], options});
  }
  return RunClosedLoop(
      1, absl::Seconds(absl::GetFlag(FLAGS_warmup_seconds)),
      absl::Seconds(absl::GetFlag(FLAGS_seconds)),
      [&](int, CallInfo* info) -> absl::Status {
        for (const auto& result : registrar.RegisterBatch(requests)) {
          if (!result.ok()) return result.status();
        }
        info->pairs = batch;
        info->batch_size = batch;
        return absl::OkStatus();
      },
      [] { core::SetNetThreads(1); });
}

using PairBatcher = server::DynamicBatcher<core::RegistrationRequest, core::RegistrationResult>;

Measurement MeasureInProcessBatcher(const core::Registrar& registrar, const ObjectTrees& objects,
                                    const core::RegistrationOptions& options,
                                    const BatchingConfig& config, int clients) {
  server::DynamicBatcherOptions batcher_options;
  batcher_options.max_batch = config.max_batch;
  batcher_options.max_queue_delay = config.max_queue_delay;
  batcher_options.workers = absl::GetFlag(FLAGS_workers);
  batcher_options.worker_init = [](int) { core::SetNetThreads(1); };
  auto batcher = PairBatcher::Create(
      batcher_options,
      [&registrar](absl::Span<core::RegistrationRequest> requests)
          -> absl::StatusOr<std::vector<absl::StatusOr<core::RegistrationResult>>> {
        return registrar.RegisterBatch(requests);
      });
  if (!batcher.ok()) {
    std::fprintf(stderr, "batcher: %s\n", batcher.status().ToString().c_str());
    std::exit(1);
  }
  const int pairs = static_cast<int>(objects.trees.size() / 2);
  std::vector<int> next(clients, 0);
  const server::DynamicBatcherStats before = (*batcher)->stats();
  Measurement measurement = RunClosedLoop(
      clients, absl::Seconds(absl::GetFlag(FLAGS_warmup_seconds)),
      absl::Seconds(absl::GetFlag(FLAGS_seconds)), [&](int client, CallInfo* info) -> absl::Status {
        const int k = (client + next[client]++) % pairs;
        core::RegistrationRequest request{&objects.trees[2 * k], &objects.trees[2 * k + 1],
                                          options};
        auto result = (*batcher)->Submit(std::move(request)).get();
        if (!result.ok()) return result.status();
        info->registrar_seconds = result->timings.total_seconds;
        return absl::OkStatus();
      });
  const server::DynamicBatcherStats after = (*batcher)->stats();
  // The batcher does not say which batch a request ran in: the mean batch over the whole run
  // (warm-up included) stands for every measured call.
  const double batches = static_cast<double>(after.batches - before.batches);
  const double mean_batch =
      batches > 0 ? static_cast<double>(after.requests_run - before.requests_run) / batches : 0.0;
  measurement.batch_size_sum = mean_batch * measurement.latencies.size();
  return measurement;
}

// Seconds per pair of each stage, the pairs registered one by one and as one batch (the network's
// time of a batch is divided evenly among its pairs): where batching can help. Alternates the two
// ways over 5 repeats (the first warms up) and prints the median of the repeats' means.
void PrintStageTimes(const core::Registrar& registrar, const ObjectTrees& objects,
                     const core::RegistrationOptions& options) {
  const int pairs = static_cast<int>(objects.trees.size() / 2);
  std::vector<core::RegistrationRequest> requests;
  for (int k = 0; k < pairs; ++k) {
    requests.push_back({&objects.trees[2 * k], &objects.trees[2 * k + 1], options});
  }
  // [way][stage] -> per-repeat means; stages: net, refine, confidence, total.
  std::vector<double> means[2][4];
  auto add = [&means, pairs](int way, const std::vector<core::RegistrationTimings>& timings) {
    double sums[4] = {0, 0, 0, 0};
    for (const auto& t : timings) {
      sums[0] += t.net_seconds;
      sums[1] += t.refine_seconds;
      sums[2] += t.confidence_seconds;
      sums[3] += t.total_seconds;
    }
    for (int stage = 0; stage < 4; ++stage) means[way][stage].push_back(sums[stage] / pairs);
  };
  for (int repeat = 0; repeat < 5; ++repeat) {
    std::vector<core::RegistrationTimings> one_by_one;
    for (const auto& request : requests) {
      auto result = registrar.Register(*request.source, *request.target, options);
      if (result.ok()) one_by_one.push_back(result->timings);
    }
    std::vector<core::RegistrationTimings> batched;
    for (const auto& result : registrar.RegisterBatch(requests)) {
      if (result.ok()) batched.push_back(result->timings);
    }
    if (repeat == 0) continue;
    add(0, one_by_one);
    add(1, batched);
  }
  for (int way = 0; way < 2; ++way) {
    double median[4];
    for (int stage = 0; stage < 4; ++stage) {
      std::vector<double>& values = means[way][stage];
      std::sort(values.begin(), values.end());
      median[stage] = values[values.size() / 2];
    }
    std::printf(
        "stage ms per pair (median of 4), %s: net %.2f, refine %.2f, confidence %.2f, "
        "total %.2f\n",
        way == 0 ? "one by one" : absl::StrCat("one batch of ", pairs).c_str(), 1e3 * median[0],
        1e3 * median[1], 1e3 * median[2], 1e3 * median[3]);
  }
  std::fflush(stdout);
}

void RunInProcess(const core::Registrar& registrar, const ObjectTrees& objects,
                  std::vector<Row>* rows) {
  PrintStageTimes(registrar, objects, OptionsFromFlags());
  const core::RegistrationOptions options = OptionsFromFlags();
  const int clients = absl::GetFlag(FLAGS_clients);
  for (int round = 1; round <= absl::GetFlag(FLAGS_rounds); ++round) {
    rows->push_back({"inproc", "registrar direct, 1 thread", round, 1,
                     MeasureDirect(registrar, objects, options)});
    PrintRow(rows->back());
    rows->push_back({"inproc", "registrar RegisterBatch(16) direct", round, 1,
                     MeasureDirectBatch(registrar, objects, options, 16)});
    PrintRow(rows->back());
    for (const BatchingConfig& config : BatchingConfigs()) {
      rows->push_back({"inproc", "batcher " + config.Name() + ", 1 client", round, 1,
                       MeasureInProcessBatcher(registrar, objects, options, config, 1)});
      PrintRow(rows->back());
    }
    for (const BatchingConfig& config : BatchingConfigs()) {
      rows->push_back({"inproc", "batcher " + config.Name(), round, clients,
                       MeasureInProcessBatcher(registrar, objects, options, config, clients)});
      PrintRow(rows->back());
    }
  }
}

#ifdef RPSR_SERVICE_LOAD_BENCH_WITH_SERVER
// One client of the real service: its own channel (and so its own connection), its own session
// and its uploaded pairs.
class ServiceClient {
 public:
  ServiceClient(const std::string& target, int index) {
    grpc::ChannelArguments args;
    // Without it, channels with equal arguments share one connection.
    args.SetInt(GRPC_ARG_USE_LOCAL_SUBCHANNEL_POOL, 1);
    args.SetInt("rpsr.bench_client", index);
    stub_ = v1::RegistrationService::NewStub(
        grpc::CreateCustomChannel(target, grpc::InsecureChannelCredentials(), args));
  }

  absl::Status Prepare(const ObjectTrees& objects) {
    grpc::ClientContext context;
    v1::CreateSessionRequest request;
    v1::CreateSessionResponse response;
    grpc::Status status = stub_->CreateSession(&context, request, &response);
    if (!status.ok()) return absl::UnavailableError("CreateSession: " + status.error_message());
    session_id_ = response.session_id();
    for (const core::PointCloud& cloud : objects.clouds) {
      auto id = Upload(cloud);
      if (!id.ok()) return id.status();
      cloud_ids_.push_back(*id);
    }
    return absl::OkStatus();
  }

  absl::Status Register(int k, const std::string& mode, CallInfo* info) {
    const int pairs = static_cast<int>(cloud_ids_.size() / 2);
    k %= pairs;
    grpc::ClientContext context;
    context.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(60));
    v1::RegisterRequest request;
    request.set_session_id(session_id_);
    request.set_source_cloud_id(cloud_ids_[2 * k]);
    request.set_target_cloud_id(cloud_ids_[2 * k + 1]);
    request.mutable_options()->set_mode(mode);
    v1::RegisterResponse response;
    grpc::Status status = stub_->Register(&context, request, &response);
    if (!status.ok()) {
      return absl::Status(static_cast<absl::StatusCode>(status.error_code()),
                          status.error_message());
    }
    info->batch_size = static_cast<int>(response.result().timings().batch_size());
    info->registrar_seconds = response.result().timings().registrar_seconds();
    return absl::OkStatus();
  }

 private:
  absl::StatusOr<uint64_t> Upload(const core::PointCloud& cloud) {
    grpc::ClientContext context;
    v1::UploadCloudResponse response;
    auto writer = stub_->UploadCloud(&context, &response);
    v1::UploadCloudRequest chunk;
    chunk.set_session_id(session_id_);
    chunk.set_point_count(cloud.size());
    chunk.set_sequence(0);
    std::string xyz(cloud.size() * 12, '\0');  // little-endian float32 (this host is)
    for (size_t i = 0; i < cloud.size(); ++i) {
      std::memcpy(&xyz[12 * i], cloud.points[i].data(), 12);
    }
    chunk.set_xyz(std::move(xyz));
    writer->Write(chunk);
    writer->WritesDone();
    grpc::Status status = writer->Finish();
    if (!status.ok()) return absl::UnavailableError("UploadCloud: " + status.error_message());
    return response.cloud_id();
  }

  std::unique_ptr<v1::RegistrationService::Stub> stub_;
  std::string session_id_;
  std::vector<uint64_t> cloud_ids_;
};

Measurement MeasureService(std::shared_ptr<const core::Registrar> registrar,
                           const ObjectTrees& objects, const BatchingConfig& config, int clients) {
  server::ServerOptions options;
  options.address = "127.0.0.1:0";
  options.metrics_address = "";
  options.registrar = registrar;
  options.log_requests = false;
  options.log_lifecycle = false;
  options.batching.max_batch = config.max_batch;
  options.batching.max_queue_delay = config.max_queue_delay;
  options.batching.workers = absl::GetFlag(FLAGS_workers);
  options.batching.intra_op_threads = 1;
  auto running = server::StartServer(options);
  if (!running.ok()) {
    std::fprintf(stderr, "server: %s\n", running.status().ToString().c_str());
    std::exit(1);
  }
  std::vector<std::unique_ptr<ServiceClient>> service_clients;
  for (int i = 0; i < clients; ++i) {
    service_clients.push_back(std::make_unique<ServiceClient>((*running)->target(), i));
    const absl::Status prepared = service_clients.back()->Prepare(objects);
    if (!prepared.ok()) {
      std::fprintf(stderr, "client %d: %s\n", i, prepared.ToString().c_str());
      std::exit(1);
    }
  }
  const std::string mode = absl::GetFlag(FLAGS_mode);
  std::vector<int> next(clients, 0);
  Measurement measurement = RunClosedLoop(
      clients, absl::Seconds(absl::GetFlag(FLAGS_warmup_seconds)),
      absl::Seconds(absl::GetFlag(FLAGS_seconds)), [&](int client, CallInfo* info) -> absl::Status {
        return service_clients[client]->Register(client + next[client]++, mode, info);
      });
  service_clients.clear();
  (*running)->Shutdown(absl::Seconds(10));
  return measurement;
}

void RunService(std::shared_ptr<const core::Registrar> registrar, const ObjectTrees& objects,
                std::vector<Row>* rows) {
  const core::RegistrationOptions options = OptionsFromFlags();
  const int clients = absl::GetFlag(FLAGS_clients);
  for (int round = 1; round <= absl::GetFlag(FLAGS_rounds); ++round) {
    rows->push_back({"service", "registrar direct, 1 thread", round, 1,
                     MeasureDirect(*registrar, objects, options)});
    PrintRow(rows->back());
    for (const BatchingConfig& config : BatchingConfigs()) {
      rows->push_back({"service", config.Name() + ", 1 client", round, 1,
                       MeasureService(registrar, objects, config, 1)});
      PrintRow(rows->back());
    }
    for (const BatchingConfig& config : BatchingConfigs()) {
      rows->push_back({"service", config.Name(), round, clients,
                       MeasureService(registrar, objects, config, clients)});
      PrintRow(rows->back());
    }
  }
}
#endif  // RPSR_SERVICE_LOAD_BENCH_WITH_SERVER

int Main() {
  const std::string part = absl::GetFlag(FLAGS_part);
  if (part != "inproc" && part != "service" && part != "all") {
    std::fprintf(stderr, "--part must be inproc, service or all, not %s\n", part.c_str());
    return 2;
  }
  core::SetNetThreads(1);
  auto registrar = core::Registrar::Create();
  if (!registrar.ok()) {
    std::fprintf(stderr, "registrar: %s\n", registrar.status().ToString().c_str());
    return 1;
  }
  std::shared_ptr<const core::Registrar> shared_registrar = *std::move(registrar);
  const ObjectTrees objects =
      MakeObjectTrees(absl::GetFlag(FLAGS_pairs), absl::GetFlag(FLAGS_points));
  std::printf("model: %s; mode %s; %d pairs of %d points; workers %d; %u hardware threads\n",
              shared_registrar->model_description().c_str(), absl::GetFlag(FLAGS_mode).c_str(),
              absl::GetFlag(FLAGS_pairs), absl::GetFlag(FLAGS_points), absl::GetFlag(FLAGS_workers),
              std::thread::hardware_concurrency());
  std::printf("blas: %s\n", core::net::BlasDescription().c_str());
  PrintHeader();
  std::vector<Row> rows;
  if (part == "inproc" || part == "all") RunInProcess(*shared_registrar, objects, &rows);
  if (part == "service" || part == "all") {
#ifdef RPSR_SERVICE_LOAD_BENCH_WITH_SERVER
    RunService(shared_registrar, objects, &rows);
#else
    std::printf("service part not built: the server library was not available at configure\n");
    if (part == "service") return 1;
#endif
  }
  PrintMedians(rows);
  return 0;
}

}  // namespace
}  // namespace rpsr

int main(int argc, char** argv) {
  absl::ParseCommandLine(argc, argv);
  rpsr::core::net::MatchOpenBlasCoreToCpu();  // as rpsrd and rpsr do
  return rpsr::Main();
}
