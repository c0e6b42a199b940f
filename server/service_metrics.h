// The service's Prometheus metrics (issue 6), all prefixed rpsr_, base units, no per-session
// labels (sessions are unbounded):
//   rpsr_requests_total{method, code}                 counter
//   rpsr_request_duration_seconds{method}             histogram, receipt to answer
//   rpsr_queue_wait_seconds                           histogram, time in the batch queue
//   rpsr_tree_build_seconds                           histogram, decode + tree per cloud
//   rpsr_network_seconds / rpsr_refinement_seconds    histograms, per registered pair
//   rpsr_registrations_total{outcome, line_rule}     counter, answers by what they say: outcome
//                                                     valid, held (invalid, kept at the initial
//                                                     guess along degenerate directions) or
//                                                     invalid; line_rule on / off (the
//                                                     refinement's line_normals_from_planes)
//   rpsr_registration_confidence                      histogram, the answers' confidence
//   rpsr_batch_size                                   histogram, pairs per batch
//   rpsr_queue_depth                                  gauge, registrations waiting
//   rpsr_cache_hits_total / rpsr_cache_misses_total   counters, cached cloud look-ups
//   rpsr_cache_evictions_total{reason}                counter, clouds leaving the cache
//   rpsr_cache_bytes / rpsr_cache_clouds / rpsr_sessions   gauges
//   rpsr_prepared_target_hits_total / _misses_total   counters, targets prepared once and reused
//   rpsr_prepared_targets                             gauge, prepared targets kept
//   rpsr_prepared_target_bytes                        gauge, their memory
//   rpsr_uploaded_points_total                        counter
//   rpsr_model_loaded                                 gauge, 1 once the model is loaded
// Exposed by prometheus-cpp's Exposer (server/rpsr_server.cc) on its own port.
#ifndef RPSR_SERVER_SERVICE_METRICS_H_
#define RPSR_SERVER_SERVICE_METRICS_H_

#include <memory>

#include "absl/strings/string_view.h"
#include "prometheus/counter.h"
#include "prometheus/family.h"
#include "prometheus/gauge.h"
#include "prometheus/histogram.h"
#include "prometheus/registry.h"
#include "server/session_store.h"

namespace rpsr::server {

class ServiceMetrics {
 public:
  ServiceMetrics();
  ServiceMetrics(const ServiceMetrics&) = delete;
  ServiceMetrics& operator=(const ServiceMetrics&) = delete;

  std::shared_ptr<prometheus::Registry> registry() const { return registry_; }

  // One finished call: `code` is the gRPC status code's name ("OK", "NOT_FOUND", ...).
  void RecordCall(absl::string_view method, absl::string_view code, double seconds);
  void ObserveQueueWait(double seconds) { queue_wait_->Observe(seconds); }
  void ObserveTreeBuild(double seconds) { tree_build_->Observe(seconds); }
  void ObserveNetwork(double seconds) { network_->Observe(seconds); }
  void ObserveRefinement(double seconds) { refinement_->Observe(seconds); }
  // One registered pair's answer: what an operator watches for a sensor or scene gone bad (a rising
  // share of invalid or low-confidence answers) and which line rule the refinement ran.
  void RecordAnswer(bool valid, bool held, bool line_rule, double confidence);
  void ObserveBatch(int size) { batch_size_->Observe(size); }
  void SetQueueDepth(int depth) { queue_depth_->Set(depth); }
  void AddUploadedPoints(double points) { uploaded_points_->Increment(points); }
  void SetModelLoaded(bool loaded) { model_loaded_->Set(loaded ? 1.0 : 0.0); }
  // One look-up of the prepared-target cache (PreparedTargetCache) and its size after it.
  void RecordPreparedTarget(bool hit, size_t kept, size_t bytes) {
    (hit ? prepared_hits_ : prepared_misses_)->Increment();
    prepared_targets_->Set(static_cast<double>(kept));
    prepared_target_bytes_->Set(static_cast<double>(bytes));
  }

  // Hooks that keep the cache series up to date.
  SessionStoreHooks CacheHooks();

 private:
  std::shared_ptr<prometheus::Registry> registry_;
  prometheus::Family<prometheus::Counter>* requests_;
  prometheus::Family<prometheus::Histogram>* request_duration_;
  prometheus::Family<prometheus::Counter>* evictions_;
  prometheus::Histogram* queue_wait_;
  prometheus::Histogram* tree_build_;
  prometheus::Histogram* network_;
  prometheus::Histogram* refinement_;
  // rpsr_registrations_total's six series, [valid, held, invalid][line rule off, on]: looked up
  // once here, not per answer.
  prometheus::Counter* answers_[3][2];
  prometheus::Histogram* confidence_;
  prometheus::Histogram* batch_size_;
  prometheus::Gauge* queue_depth_;
  prometheus::Counter* cache_hits_;
  prometheus::Counter* cache_misses_;
  prometheus::Gauge* cache_bytes_;
  prometheus::Gauge* cache_clouds_;
  prometheus::Gauge* sessions_;
  prometheus::Counter* uploaded_points_;
  prometheus::Gauge* model_loaded_;
  prometheus::Counter* prepared_hits_;
  prometheus::Counter* prepared_misses_;
  prometheus::Gauge* prepared_targets_;
  prometheus::Gauge* prepared_target_bytes_;
};

// The name of a gRPC status code as Prometheus labels and logs show it ("DEADLINE_EXCEEDED").
absl::string_view StatusCodeName(int code);

}  // namespace rpsr::server

#endif  // RPSR_SERVER_SERVICE_METRICS_H_
