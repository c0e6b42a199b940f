#include "server/service_metrics.h"

#include <string>

namespace rpsr::server {
namespace {

// Latencies from half a millisecond (a cached Register's service overhead) to 10 s (a deep
// tree of a 2M-point cloud).
prometheus::Histogram::BucketBoundaries SecondsBuckets() {
  return {0.0005, 0.001, 0.002, 0.005, 0.01, 0.02, 0.05, 0.1, 0.2, 0.5, 1.0, 2.0, 5.0, 10.0};
}

}  // namespace

absl::string_view StatusCodeName(int code) {
  static constexpr absl::string_view kNames[] = {"OK",
                                                 "CANCELLED",
                                                 "UNKNOWN",
                                                 "INVALID_ARGUMENT",
                                                 "DEADLINE_EXCEEDED",
                                                 "NOT_FOUND",
                                                 "ALREADY_EXISTS",
                                                 "PERMISSION_DENIED",
                                                 "RESOURCE_EXHAUSTED",
                                                 "FAILED_PRECONDITION",
                                                 "ABORTED",
                                                 "OUT_OF_RANGE",
                                                 "UNIMPLEMENTED",
                                                 "INTERNAL",
                                                 "UNAVAILABLE",
                                                 "DATA_LOSS",
                                                 "UNAUTHENTICATED"};
  if (code < 0 || code >= static_cast<int>(std::size(kNames))) return "UNKNOWN";
  return kNames[code];
}

ServiceMetrics::ServiceMetrics() : registry_(std::make_shared<prometheus::Registry>()) {
  prometheus::Registry& r = *registry_;
  requests_ = &prometheus::BuildCounter()
                   .Name("rpsr_requests_total")
                   .Help("Finished calls by method and gRPC status code")
                   .Register(r);
  request_duration_ = &prometheus::BuildHistogram()
                           .Name("rpsr_request_duration_seconds")
                           .Help("Time from a call's receipt to its answer, by method")
                           .Register(r);
  auto histogram = [&](const char* name, const char* help) {
    return &prometheus::BuildHistogram().Name(name).Help(help).Register(r).Add({},
                                                                               SecondsBuckets());
  };
  queue_wait_ = histogram("rpsr_queue_wait_seconds",
                          "Time a registration waited in the batch queue before its batch ran");
  tree_build_ = histogram("rpsr_tree_build_seconds",
                          "Time to decode a cloud's points and build its Barnes-Hut tree");
  network_ = histogram("rpsr_network_seconds",
                       "Network time per registered pair (a batch's time divided among its pairs)");
  refinement_ = histogram("rpsr_refinement_seconds", "Tree refinement time per registered pair");
  auto& registrations = prometheus::BuildCounter()
                            .Name("rpsr_registrations_total")
                            .Help(
                                "Registered pairs by outcome (valid, held, invalid) and line rule "
                                "(on, off)")
                            .Register(r);
  const char* const outcomes[] = {"valid", "held", "invalid"};
  for (int outcome = 0; outcome < 3; ++outcome) {
    for (int line_rule = 0; line_rule < 2; ++line_rule) {
      answers_[outcome][line_rule] = &registrations.Add(
          {{"outcome", outcomes[outcome]}, {"line_rule", line_rule == 1 ? "on" : "off"}});
    }
  }
  // Finer near 1, where a caller's acceptance threshold usually sits.
  confidence_ =
      &prometheus::BuildHistogram()
           .Name("rpsr_registration_confidence")
           .Help("Calibrated confidence of the registered pairs' answers")
           .Register(r)
           .Add({}, prometheus::Histogram::BucketBoundaries{0.1, 0.3, 0.5, 0.7, 0.9, 0.95, 0.99});
  batch_size_ = &prometheus::BuildHistogram()
                     .Name("rpsr_batch_size")
                     .Help("Registrations per batch run by a worker")
                     .Register(r)
                     .Add({}, prometheus::Histogram::BucketBoundaries{1, 2, 4, 8, 16, 32, 64});
  queue_depth_ = &prometheus::BuildGauge()
                      .Name("rpsr_queue_depth")
                      .Help("Registrations waiting in the batch queue")
                      .Register(r)
                      .Add({});
  cache_hits_ = &prometheus::BuildCounter()
                     .Name("rpsr_cache_hits_total")
                     .Help("Look-ups of a cached cloud that found it")
                     .Register(r)
                     .Add({});
  cache_misses_ = &prometheus::BuildCounter()
                       .Name("rpsr_cache_misses_total")
                       .Help("Look-ups of a cloud id that the session does not hold")
                       .Register(r)
                       .Add({});
  evictions_ = &prometheus::BuildCounter()
                    .Name("rpsr_cache_evictions_total")
                    .Help(
                        "Clouds that left the cache, by reason (memory_budget, "
                        "session_expired, session_closed, released)")
                    .Register(r);
  cache_bytes_ = &prometheus::BuildGauge()
                      .Name("rpsr_cache_bytes")
                      .Help("Bytes held by cached trees")
                      .Register(r)
                      .Add({});
  cache_clouds_ = &prometheus::BuildGauge()
                       .Name("rpsr_cache_clouds")
                       .Help("Clouds (trees) held by the cache")
                       .Register(r)
                       .Add({});
  sessions_ =
      &prometheus::BuildGauge().Name("rpsr_sessions").Help("Live sessions").Register(r).Add({});
  uploaded_points_ = &prometheus::BuildCounter()
                          .Name("rpsr_uploaded_points_total")
                          .Help("Points received in completed uploads and Track frames")
                          .Register(r)
                          .Add({});
  model_loaded_ = &prometheus::BuildGauge()
                       .Name("rpsr_model_loaded")
                       .Help("1 once the registration model is loaded")
                       .Register(r)
                       .Add({});
  prepared_hits_ = &prometheus::BuildCounter()
                        .Name("rpsr_prepared_target_hits_total")
                        .Help("Registrations against a cached cloud whose prepared target was kept")
                        .Register(r)
                        .Add({});
  prepared_misses_ = &prometheus::BuildCounter()
                          .Name("rpsr_prepared_target_misses_total")
                          .Help("Registrations against a cached cloud that prepared its target")
                          .Register(r)
                          .Add({});
  prepared_targets_ = &prometheus::BuildGauge()
                           .Name("rpsr_prepared_targets")
                           .Help("Prepared targets kept")
                           .Register(r)
                           .Add({});
  prepared_target_bytes_ = &prometheus::BuildGauge()
                                .Name("rpsr_prepared_target_bytes")
                                .Help("Memory of the prepared targets kept, bytes")
                                .Register(r)
                                .Add({});
  // The series a dashboard expects exist from the start, at zero.
  for (const char* reason : {"memory_budget", "session_expired", "session_closed", "released"}) {
    evictions_->Add({{"reason", reason}});
  }
}

void ServiceMetrics::RecordAnswer(bool valid, bool held, bool line_rule, double confidence) {
  answers_[valid ? 0 : held ? 1 : 2][line_rule ? 1 : 0]->Increment();
  confidence_->Observe(confidence);
}

void ServiceMetrics::RecordCall(absl::string_view method, absl::string_view code, double seconds) {
  requests_->Add({{"method", std::string(method)}, {"code", std::string(code)}}).Increment();
  request_duration_->Add({{"method", std::string(method)}}, SecondsBuckets()).Observe(seconds);
}

SessionStoreHooks ServiceMetrics::CacheHooks() {
  SessionStoreHooks hooks;
  hooks.hit = [this] { cache_hits_->Increment(); };
  hooks.miss = [this] { cache_misses_->Increment(); };
  hooks.evicted = [this](absl::string_view reason, uint64_t) {
    evictions_->Add({{"reason", std::string(reason)}}).Increment();
  };
  hooks.occupancy = [this](size_t sessions, size_t clouds, uint64_t bytes) {
    sessions_->Set(static_cast<double>(sessions));
    cache_clouds_->Set(static_cast<double>(clouds));
    cache_bytes_->Set(static_cast<double>(bytes));
  };
  return hooks;
}

}  // namespace rpsr::server
