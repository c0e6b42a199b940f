#include "server/registration_service.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <optional>
#include <utility>
#include <vector>

#include "absl/strings/match.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "absl/synchronization/mutex.h"
#include "core/net/rpsr_net.h"
#include "server/cloud_assembler.h"
#include "server/prepared_target_cache.h"
#include "server/proto_convert.h"
#include "server/structured_log.h"

namespace rpsr::server {

// ---------------------------------------------------------------------------------------------
// The batcher over the registrar

absl::StatusOr<std::unique_ptr<RegistrationBatcher>> MakeRegistrationBatcher(
    std::shared_ptr<const core::Registrar> registrar, const BatchingOptions& options,
    ServiceMetrics* metrics) {
  if (registrar == nullptr) return absl::InvalidArgumentError("no registrar");
  DynamicBatcherOptions batcher_options;
  batcher_options.max_batch = options.max_batch;
  batcher_options.max_queue_delay = options.max_queue_delay;
  batcher_options.max_queue = options.max_queue;
  batcher_options.workers = options.workers;
  const int threads = options.intra_op_threads;
  batcher_options.worker_init = [threads](int) { core::SetNetThreads(threads); };
  batcher_options.drain_on_stop = true;

  DynamicBatcherHooks hooks;
  if (metrics != nullptr) {
    hooks.queue_wait = [metrics](double seconds) { metrics->ObserveQueueWait(seconds); };
    hooks.batch_done = [metrics](int size, double) { metrics->ObserveBatch(size); };
    hooks.queue_depth = [metrics](int depth) { metrics->SetQueueDepth(depth); };
  }
  // Shared by the workers.
  auto prepared_targets = std::make_shared<PreparedTargetCache>(
      registrar, static_cast<size_t>(std::max(0, options.prepared_targets)),
      static_cast<size_t>(options.prepared_target_bytes));
  auto batch_function = [registrar, metrics, prepared_targets](absl::Span<RegistrationJob> jobs)
      -> absl::StatusOr<std::vector<absl::StatusOr<RegistrationOutcome>>> {
    const absl::Time start = absl::Now();
    std::vector<core::RegistrationRequest> requests;
    std::vector<std::shared_ptr<const core::PreparedTarget>> prepared(jobs.size());
    requests.reserve(jobs.size());
    for (size_t i = 0; i < jobs.size(); ++i) {
      const RegistrationJob& job = jobs[i];
      if (job.target_from_store) {
        bool hit = false;
        prepared[i] = prepared_targets->Get(
            job.target, job.options.mode != core::RegistrationMode::kRefine, &hit);
        if (metrics != nullptr) {
          metrics->RecordPreparedTarget(hit, prepared_targets->size(), prepared_targets->bytes());
        }
      }
      requests.push_back({job.source.get(), job.target.get(), job.options, prepared[i].get()});
    }
    std::vector<absl::StatusOr<core::RegistrationResult>> results =
        registrar->RegisterBatch(requests);
    if (results.size() != jobs.size()) {
      return absl::InternalError(absl::StrCat("the registrar returned ", results.size(),
                                              " results for ", jobs.size(), " pairs"));
    }
    std::vector<absl::StatusOr<RegistrationOutcome>> outcomes;
    outcomes.reserve(jobs.size());
    for (size_t i = 0; i < jobs.size(); ++i) {
      if (!results[i].ok()) {
        outcomes.push_back(results[i].status());
        continue;
      }
      RegistrationOutcome outcome;
      outcome.result = *std::move(results[i]);
      outcome.queue_seconds = absl::ToDoubleSeconds(start - jobs[i].enqueued);
      outcome.batch_size = static_cast<int>(jobs.size());
      if (metrics != nullptr) {
        if (outcome.result.mode != core::RegistrationMode::kRefine) {
          metrics->ObserveNetwork(outcome.result.timings.net_seconds);
        }
        if (outcome.result.mode != core::RegistrationMode::kNet) {
          metrics->ObserveRefinement(outcome.result.timings.refine_seconds);
        }
        metrics->RecordAnswer(outcome.result.valid, outcome.result.held_at_initial,
                              outcome.result.line_normals_from_planes, outcome.result.confidence);
      }
      outcomes.push_back(std::move(outcome));
    }
    return outcomes;
  };
  return RegistrationBatcher::Create(batcher_options, std::move(batch_function), std::move(hooks));
}

// ---------------------------------------------------------------------------------------------
// What every call needs

struct RegistrationService::Shared {
  ServerOptions options;
  ServiceMetrics* metrics = nullptr;
  SessionStore* store = nullptr;

  absl::Mutex engine_mu;
  std::shared_ptr<const core::Registrar> registrar ABSL_GUARDED_BY(engine_mu);
  std::unique_ptr<RegistrationBatcher> owned_batcher ABSL_GUARDED_BY(engine_mu);
  std::atomic<RegistrationBatcher*> batcher{nullptr};
  std::atomic<bool> draining{false};
  std::atomic<uint32_t> open_streams{0};

  // Takes a slot for an UploadCloud or Track stream (released by ReleaseStream in OnDone).
  absl::Status AcquireStream() {
    if (open_streams.fetch_add(1) >= options.max_open_streams) {
      open_streams.fetch_sub(1);
      return absl::ResourceExhaustedError(
          absl::StrCat("the server has the most upload and track streams open it may (",
                       options.max_open_streams, "); retry shortly"));
    }
    return absl::OkStatus();
  }
  void ReleaseStream() { open_streams.fetch_sub(1); }

  // What every call checks first, in this order: admission (draining, model loaded), then the
  // caller's token. Returns the caller's identity.
  absl::StatusOr<std::string> AdmitCaller(const grpc::CallbackServerContext* context,
                                          bool needs_model) const {
    if (absl::Status admitted = Admit(needs_model); !admitted.ok()) return admitted;
    return Authenticate(context);
  }

  // AdmitCaller, then a stream slot, for UploadCloud and Track. On success the caller holds a
  // slot (ReleaseStream in OnDone) and gets its identity.
  absl::StatusOr<std::string> OpenStream(const grpc::CallbackServerContext* context,
                                         bool needs_model) {
    absl::StatusOr<std::string> caller = AdmitCaller(context, needs_model);
    if (!caller.ok()) return caller.status();
    if (absl::Status slot = AcquireStream(); !slot.ok()) return slot;
    return caller;
  }

  // Refuses calls while draining, and calls that need the model before it is loaded.
  absl::Status Admit(bool needs_model) const {
    if (draining.load()) {
      return absl::UnavailableError("the server is shutting down; retry on another instance");
    }
    if (needs_model && batcher.load() == nullptr) {
      return absl::UnavailableError("the server is loading its model; retry shortly");
    }
    return absl::OkStatus();
  }

  // The caller's identity: the bearer token it presented ("" when authentication is off).
  absl::StatusOr<std::string> Authenticate(const grpc::CallbackServerContext* context) const {
    if (options.auth_tokens.empty()) return std::string();
    const auto& metadata = context->client_metadata();
    auto it = metadata.find("authorization");
    if (it == metadata.end()) {
      return absl::UnauthenticatedError(
          "this server requires a bearer token: send metadata \"authorization: Bearer <token>\"");
    }
    const absl::string_view value(it->second.data(), it->second.size());
    constexpr absl::string_view kPrefix = "Bearer ";
    if (!absl::StartsWith(value, kPrefix)) {
      return absl::UnauthenticatedError("the authorization metadata must read \"Bearer <token>\"");
    }
    const absl::string_view token = value.substr(kPrefix.size());
    for (const std::string& accepted : options.auth_tokens) {
      if (ConstantTimeEquals(token, accepted)) return accepted;
    }
    return absl::UnauthenticatedError("the bearer token is not accepted by this server");
  }

  // Compares without an early exit, so response times do not reveal how much of a token matched.
  static bool ConstantTimeEquals(absl::string_view a, absl::string_view b) {
    const size_t n = std::max(a.size(), b.size());
    unsigned char difference = a.size() == b.size() ? 0 : 1;
    for (size_t i = 0; i < n; ++i) {
      const unsigned char x = i < a.size() ? static_cast<unsigned char>(a[i]) : 0;
      const unsigned char y = i < b.size() ? static_cast<unsigned char>(b[i]) : 0;
      difference |= static_cast<unsigned char>(x ^ y);
    }
    return difference == 0;
  }

  SessionSettings DefaultSettings() const {
    SessionSettings settings;
    settings.tree_max_depth = options.default_tree_max_depth;
    settings.ttl = options.cache.default_ttl;
    return settings;
  }

  std::string ModelName() const {
    return options.registrar_config.model_path.empty() ? options.registrar_config.model
                                                       : options.registrar_config.model_path;
  }

  uint64_t RecommendedChunkPoints() const {
    // Half the message limit leaves room for framing and fields; at most 64k points (768 KiB).
    const uint64_t by_size = options.max_message_bytes / 2 / kBytesPerPoint;
    return std::clamp<uint64_t>(by_size, 1, 65536);
  }
};

namespace {

using Shared = RegistrationService::Shared;

grpc::Status ToGrpc(const absl::Status& status) { return ToGrpcStatus(status); }

// Metrics and one log line per finished call.
// The session affinity key a client sent (x-rpsr-affinity, deploy/envoy/envoy.yaml), cut to 64
// characters: the request log names it so an operator sees how a balancer spread the sessions.
// "" when absent.
std::string AffinityKeyOf(const grpc::CallbackServerContext* context) {
  const auto& metadata = context->client_metadata();
  auto it = metadata.find("x-rpsr-affinity");
  if (it == metadata.end()) return "";
  return std::string(it->second.data(), std::min<size_t>(it->second.size(), 64));
}

class CallRecord {
 public:
  CallRecord(const Shared* shared, absl::string_view method,
             const grpc::CallbackServerContext* context)
      : shared_(shared),
        method_(method),
        peer_(context->peer()),
        affinity_(AffinityKeyOf(context)),
        start_(absl::Now()) {}

  absl::Time start() const { return start_; }
  double elapsed_seconds() const { return absl::ToDoubleSeconds(absl::Now() - start_); }

  // Once per call, before Finish (after Finish the reactor may already be gone).
  void Finished(const absl::Status& status, absl::string_view detail = "") {
    const double seconds = elapsed_seconds();
    const absl::string_view code = StatusCodeName(static_cast<int>(status.code()));
    shared_->metrics->RecordCall(method_, code, seconds);
    if (!shared_->options.log_requests) return;
    if (status.ok()) {
      LogEvent("info", "call",
               {{"method", std::string(method_)},
                {"code", std::string(code)},
                {"seconds", absl::StrFormat("%.6f", seconds)},
                {"peer", peer_},
                {"affinity", affinity_},
                {"detail", std::string(detail)}});
    } else {
      LogEvent("warn", "call",
               {{"method", std::string(method_)},
                {"code", std::string(code)},
                {"seconds", absl::StrFormat("%.6f", seconds)},
                {"peer", peer_},
                {"affinity", affinity_},
                {"error", std::string(status.message())}});
    }
  }

 private:
  const Shared* shared_;
  absl::string_view method_;
  std::string peer_;
  std::string affinity_;
  absl::Time start_;
};

// The earlier of the call's gRPC deadline and the request's own budget.
absl::Time RequestDeadline(const grpc::CallbackServerContext* context, absl::Time received,
                           double deadline_seconds) {
  absl::Time deadline = absl::InfiniteFuture();
  const auto grpc_deadline = context->deadline();
  if (grpc_deadline != std::chrono::system_clock::time_point::max()) {
    deadline = absl::FromChrono(grpc_deadline);
  }
  if (deadline_seconds > 0) {
    deadline = std::min(deadline, received + absl::Seconds(deadline_seconds));
  }
  return deadline;
}

// A cloud of a Register request: cached (by id) or inline (decoded and its tree built here).
absl::StatusOr<std::shared_ptr<const core::Octree>> ResolveCloud(
    Shared* shared, absl::string_view side, bool by_id, uint64_t cloud_id,
    const v1::InlineCloud* inline_cloud, absl::string_view session_id, absl::string_view caller,
    const SessionSettings& settings, double* tree_seconds) {
  if (by_id) {
    if (session_id.empty()) {
      return absl::InvalidArgumentError(
          absl::StrCat(side, "_cloud_id needs a session_id (cloud ids live in a session)"));
    }
    return shared->store->GetCloud(session_id, caller, cloud_id);
  }
  if (inline_cloud == nullptr) {
    return absl::InvalidArgumentError(
        absl::StrCat("no ", side, ": give ", side, "_cloud_id or an inline ", side, "_cloud"));
  }
  const uint64_t points = inline_cloud->xyz().size() / kBytesPerPoint;
  if (points > shared->options.max_inline_points) {
    return absl::ResourceExhaustedError(absl::StrCat(
        "inline ", side, "_cloud has ", points, " points, more than the ",
        shared->options.max_inline_points, " allowed inline; upload it with UploadCloud"));
  }
  const absl::Time start = absl::Now();
  std::vector<Eigen::Vector3f> decoded;
  decoded.reserve(points);
  absl::Status appended = AppendXyz(inline_cloud->xyz(), 0, &decoded);
  if (!appended.ok()) {
    return absl::Status(appended.code(),
                        absl::StrCat("inline ", side, "_cloud: ", appended.message()));
  }
  if (decoded.empty()) {
    return absl::InvalidArgumentError(
        absl::StrCat("inline ", side, "_cloud is empty (an empty cloud cannot be registered)"));
  }
  absl::StatusOr<std::shared_ptr<const core::Octree>> tree =
      BuildCloudTree(decoded, settings.tree_max_depth, shared->options.max_points_per_cloud);
  const double seconds = absl::ToDoubleSeconds(absl::Now() - start);
  *tree_seconds += seconds;
  if (!tree.ok()) {
    return absl::Status(tree.status().code(),
                        absl::StrCat("inline ", side, "_cloud: ", tree.status().message()));
  }
  shared->metrics->ObserveTreeBuild(seconds);
  return tree;
}

void FillTimings(const RegistrationOutcome& outcome, double tree_seconds, double server_seconds,
                 v1::Timings* timings) {
  timings->set_queue_seconds(outcome.queue_seconds);
  timings->set_tree_seconds(tree_seconds);
  timings->set_server_seconds(server_seconds);
  timings->set_batch_size(static_cast<uint32_t>(outcome.batch_size));
}

// ---------------------------------------------------------------------------------------------
// Register

class RegisterReactor final : public grpc::ServerUnaryReactor {
 public:
  RegisterReactor(Shared* shared, grpc::CallbackServerContext* context,
                  const v1::RegisterRequest* request, v1::RegisterResponse* response)
      : shared_(shared), record_(shared, "Register", context), response_(response) {
    absl::Status started = Start(context, *request);
    if (!started.ok()) FinishOnce(started);
  }

  void OnCancel() override { cancelled_->store(true); }
  void OnDone() override { delete this; }

 private:
  absl::Status Start(const grpc::CallbackServerContext* context,
                     const v1::RegisterRequest& request) {
    absl::StatusOr<std::string> caller = shared_->AdmitCaller(context, /*needs_model=*/true);
    if (!caller.ok()) return caller.status();
    absl::StatusOr<core::RegistrationOptions> options = OptionsFromProto(request.options());
    if (!options.ok()) return options.status();

    SessionSettings settings = shared_->DefaultSettings();
    if (!request.session_id().empty()) {
      absl::StatusOr<SessionSettings> session =
          shared_->store->UseSession(request.session_id(), *caller);
      if (!session.ok()) return session.status();
      settings = *session;
    }
    RegistrationJob job;
    absl::StatusOr<std::shared_ptr<const core::Octree>> source = ResolveCloud(
        shared_, "source", request.source_case() == v1::RegisterRequest::kSourceCloudId,
        request.source_cloud_id(), request.has_source_cloud() ? &request.source_cloud() : nullptr,
        request.session_id(), *caller, settings, &tree_seconds_);
    if (!source.ok()) return source.status();
    absl::StatusOr<std::shared_ptr<const core::Octree>> target = ResolveCloud(
        shared_, "target", request.target_case() == v1::RegisterRequest::kTargetCloudId,
        request.target_cloud_id(), request.has_target_cloud() ? &request.target_cloud() : nullptr,
        request.session_id(), *caller, settings, &tree_seconds_);
    if (!target.ok()) return target.status();
    job.source = *std::move(source);
    job.target = *std::move(target);
    job.options = *std::move(options);
    job.enqueued = absl::Now();
    job.target_from_store = request.target_case() == v1::RegisterRequest::kTargetCloudId;

    RegistrationBatcher* batcher = shared_->batcher.load();
    BatchRequestControl control;
    control.deadline =
        RequestDeadline(context, record_.start(), request.options().deadline_seconds());
    control.is_cancelled = [cancelled = cancelled_] { return cancelled->load(); };
    return batcher->Enqueue(
        std::move(job), std::move(control),
        [this](absl::StatusOr<RegistrationOutcome> outcome) { Complete(std::move(outcome)); });
  }

  // On a batcher worker (or wherever the batcher dropped the request).
  void Complete(absl::StatusOr<RegistrationOutcome> outcome) {
    if (!outcome.ok()) {
      FinishOnce(outcome.status());
      return;
    }
    v1::RegistrationResult* result = response_->mutable_result();
    ResultToProto(outcome->result, result);
    FillTimings(*outcome, tree_seconds_, record_.elapsed_seconds(), result->mutable_timings());
    FinishOnce(absl::OkStatus());
  }

  void FinishOnce(const absl::Status& status) {
    record_.Finished(status);
    Finish(ToGrpc(status));  // OnDone may delete this from now on
  }

  Shared* shared_;
  CallRecord record_;
  v1::RegisterResponse* response_;
  double tree_seconds_ = 0.0;
  std::shared_ptr<std::atomic<bool>> cancelled_ = std::make_shared<std::atomic<bool>>(false);
};

// ---------------------------------------------------------------------------------------------
// UploadCloud

class UploadReactor final : public grpc::ServerReadReactor<v1::UploadCloudRequest> {
 public:
  UploadReactor(Shared* shared, grpc::CallbackServerContext* context,
                v1::UploadCloudResponse* response)
      : shared_(shared),
        record_(shared, "UploadCloud", context),
        context_(context),
        response_(response),
        assembler_("upload", shared->options.max_points_per_cloud) {
    absl::StatusOr<std::string> caller = shared_->OpenStream(context, /*needs_model=*/false);
    if (!caller.ok()) {
      FinishOnce(caller.status());
      return;
    }
    holds_stream_ = true;
    caller_ = *std::move(caller);
    StartRead(&message_);
  }

  void OnReadDone(bool ok) override {
    if (!ok) {
      // The client half-closed, or the call broke (cancelled, disconnected).
      if (cancelled_.load() || context_->IsCancelled()) {
        FinishOnce(absl::CancelledError("the upload was cancelled; nothing was kept"));
      } else {
        FinishOnce(Complete());
      }
      return;
    }
    absl::Status accepted = Accept();
    if (!accepted.ok()) {
      FinishOnce(accepted);
      return;
    }
    StartRead(&message_);
  }

  void OnCancel() override { cancelled_.store(true); }
  void OnDone() override {
    if (holds_stream_) shared_->ReleaseStream();
    delete this;
  }

 private:
  absl::Status Accept() {
    if (!assembler_.begun()) {
      if (message_.session_id().empty()) {
        return absl::InvalidArgumentError(
            "the first UploadCloud message must carry the session_id");
      }
      absl::StatusOr<SessionSettings> settings =
          shared_->store->UseSession(message_.session_id(), caller_);
      if (!settings.ok()) return settings.status();
      session_id_ = message_.session_id();
      tree_depth_ = settings->tree_max_depth;
      absl::Status begun = assembler_.Begin(message_.point_count());
      if (!begun.ok()) return begun;
    } else {
      if (!message_.session_id().empty() && message_.session_id() != session_id_) {
        return absl::InvalidArgumentError(
            absl::StrCat("upload: chunk ", message_.sequence(), " names session ",
                         message_.session_id(), " but the upload began in session ", session_id_));
      }
      if (message_.point_count() != 0 && message_.point_count() != assembler_.expected()) {
        return absl::InvalidArgumentError(absl::StrCat(
            "upload: chunk ", message_.sequence(), " declares ", message_.point_count(),
            " points but the first message declared ", assembler_.expected()));
      }
    }
    return assembler_.AddChunk(message_.sequence(), message_.xyz());
  }

  absl::Status Complete() {
    absl::Status complete = assembler_.CheckComplete();
    if (!complete.ok()) return complete;
    const absl::Time start = absl::Now();
    const uint64_t points = assembler_.received();
    std::vector<Eigen::Vector3f> cloud = assembler_.TakePoints();
    absl::StatusOr<std::shared_ptr<const core::Octree>> tree =
        BuildCloudTree(cloud, tree_depth_, shared_->options.max_points_per_cloud);
    cloud = {};  // the points are not kept
    if (!tree.ok()) return tree.status();
    const double seconds = absl::ToDoubleSeconds(absl::Now() - start);
    shared_->metrics->ObserveTreeBuild(seconds);
    const core::Octree& built = **tree;
    absl::StatusOr<uint64_t> id = shared_->store->AddCloud(session_id_, caller_, *tree);
    if (!id.ok()) return id.status();
    shared_->metrics->AddUploadedPoints(static_cast<double>(points));
    response_->set_cloud_id(*id);
    TreeStatsToProto(built, seconds, response_->mutable_tree());
    detail_ = absl::StrCat("cloud=", *id, " points=", points);
    return absl::OkStatus();
  }

  void FinishOnce(const absl::Status& status) {
    record_.Finished(status, detail_);
    Finish(ToGrpc(status));
  }

  Shared* shared_;
  CallRecord record_;
  grpc::CallbackServerContext* context_;
  v1::UploadCloudResponse* response_;
  std::string caller_;
  std::string session_id_;
  std::string detail_;
  int tree_depth_ = 0;
  CloudAssembler assembler_;
  v1::UploadCloudRequest message_;
  std::atomic<bool> cancelled_{false};
  bool holds_stream_ = false;
};

// ---------------------------------------------------------------------------------------------
// Track

class TrackReactor final : public grpc::ServerBidiReactor<v1::TrackRequest, v1::TrackResponse> {
 public:
  TrackReactor(Shared* shared, grpc::CallbackServerContext* context)
      : shared_(shared), record_(shared, "Track", context), context_(context) {
    absl::StatusOr<std::string> caller = shared_->OpenStream(context, /*needs_model=*/true);
    if (!caller.ok()) {
      FinishOnce(caller.status());
      return;
    }
    holds_stream_ = true;
    caller_ = *std::move(caller);
    settings_ = shared_->DefaultSettings();
    StartRead(&request_);
  }

  void OnReadDone(bool ok) override {
    if (!ok) {
      if (cancelled_->load() || context_->IsCancelled()) {
        FinishOnce(absl::CancelledError("the Track stream was cancelled"));
      } else if (assembler_ != nullptr && assembler_->begun() && !assembler_->complete()) {
        FinishOnce(
            absl::InvalidArgumentError(absl::StrCat("the stream ended inside frame ", next_frame_,
                                                    ": ", assembler_->CheckComplete().message())));
      } else {
        FinishOnce(absl::OkStatus());
      }
      return;
    }
    absl::Status accepted = Accept();
    if (!accepted.ok()) FinishOnce(accepted);
  }

  void OnWriteDone(bool ok) override {
    if (!ok) {
      FinishOnce(absl::CancelledError("the client stopped receiving Track answers"));
      return;
    }
    ++next_frame_;
    StartRead(&request_);
  }

  void OnCancel() override { cancelled_->store(true); }
  void OnDone() override {
    if (holds_stream_) shared_->ReleaseStream();
    delete this;
  }

 private:
  // One message; reads the next one unless a frame went off to be registered (or failed).
  absl::Status Accept() {
    if (request_.has_start()) {
      if (started_) return absl::InvalidArgumentError("Track: TrackStart may come only once");
      const v1::TrackStart& start = request_.start();
      if (!start.session_id().empty()) {
        absl::StatusOr<SessionSettings> settings =
            shared_->store->UseSession(start.session_id(), caller_);
        if (!settings.ok()) return settings.status();
        settings_ = *settings;
        session_id_ = start.session_id();
      }
      absl::StatusOr<core::RegistrationOptions> options = OptionsFromProto(start.options());
      if (!options.ok()) return options.status();
      options_ = *std::move(options);
      deadline_seconds_ = start.options().deadline_seconds();
      constant_velocity_ = start.constant_velocity_prior();
      started_ = true;
      StartRead(&request_);
      return absl::OkStatus();
    }
    if (!started_) {
      return absl::InvalidArgumentError("Track: the first message must be a TrackStart");
    }
    if (!request_.has_chunk()) {
      return absl::InvalidArgumentError("Track: a message with neither start nor chunk");
    }
    const v1::FrameChunk& chunk = request_.chunk();
    if (chunk.frame_index() != next_frame_) {
      return absl::InvalidArgumentError(absl::StrCat("Track: a chunk of frame ",
                                                     chunk.frame_index(), " arrived where frame ",
                                                     next_frame_, " was expected"));
    }
    if (assembler_ == nullptr) {
      if (chunk.sequence() != 0) {
        return absl::InvalidArgumentError(
            absl::StrCat("frame ", next_frame_, ": chunk ", chunk.sequence(),
                         " arrived where chunk 0 was expected (chunks out of order or lost)"));
      }
      assembler_ = std::make_unique<CloudAssembler>(absl::StrCat("frame ", next_frame_),
                                                    shared_->options.max_points_per_cloud);
      absl::Status begun = assembler_->Begin(chunk.point_count());
      if (!begun.ok()) return begun;
    }
    absl::Status added = assembler_->AddChunk(chunk.sequence(), chunk.xyz());
    if (!added.ok()) return added;
    if (!assembler_->complete()) {
      StartRead(&request_);
      return absl::OkStatus();
    }
    return ProcessFrame();
  }

  absl::Status ProcessFrame() {
    frame_received_ = absl::Now();
    if (!session_id_.empty()) {
      absl::StatusOr<SessionSettings> alive = shared_->store->UseSession(session_id_, caller_);
      if (!alive.ok()) return alive.status();
    }
    const uint64_t points = assembler_->received();
    std::vector<Eigen::Vector3f> cloud = assembler_->TakePoints();
    assembler_.reset();
    absl::StatusOr<std::shared_ptr<const core::Octree>> tree =
        BuildCloudTree(cloud, settings_.tree_max_depth, shared_->options.max_points_per_cloud);
    cloud = {};
    const double tree_seconds = absl::ToDoubleSeconds(absl::Now() - frame_received_);
    if (!tree.ok()) {
      return absl::Status(tree.status().code(),
                          absl::StrCat("frame ", next_frame_, ": ", tree.status().message()));
    }
    shared_->metrics->ObserveTreeBuild(tree_seconds);
    shared_->metrics->AddUploadedPoints(static_cast<double>(points));
    response_.Clear();
    response_.set_frame_index(next_frame_);
    TreeStatsToProto(**tree, tree_seconds, response_.mutable_tree());
    if (previous_ == nullptr) {
      previous_ = *std::move(tree);
      TransformToProto(accumulated_, response_.mutable_accumulated());
      StartWrite(&response_);
      return absl::OkStatus();
    }
    RegistrationJob job;
    job.source = *tree;
    job.target = previous_;
    job.options = options_;
    if (constant_velocity_ && last_relative_.has_value()) {
      job.options.initial_T_target_source = *last_relative_;
    }
    job.enqueued = absl::Now();
    current_ = *std::move(tree);
    tree_seconds_ = tree_seconds;
    BatchRequestControl control;
    control.deadline = RequestDeadline(context_, frame_received_, deadline_seconds_);
    control.is_cancelled = [cancelled = cancelled_] { return cancelled->load(); };
    RegistrationBatcher* batcher = shared_->batcher.load();
    return batcher->Enqueue(
        std::move(job), std::move(control),
        [this](absl::StatusOr<RegistrationOutcome> outcome) { Registered(std::move(outcome)); });
  }

  // On a batcher worker: no read or write is pending meanwhile.
  void Registered(absl::StatusOr<RegistrationOutcome> outcome) {
    if (!outcome.ok()) {
      FinishOnce(absl::Status(outcome.status().code(), absl::StrCat("frame ", next_frame_, ": ",
                                                                    outcome.status().message())));
      return;
    }
    const Eigen::Isometry3d& relative = outcome->result.T_target_source;
    accumulated_ = accumulated_ * relative;
    if (core::StartsNextFrame(outcome->result)) last_relative_ = relative;
    previous_ = std::move(current_);
    v1::RegistrationResult* result = response_.mutable_relative();
    ResultToProto(outcome->result, result);
    FillTimings(*outcome, tree_seconds_, absl::ToDoubleSeconds(absl::Now() - frame_received_),
                result->mutable_timings());
    TransformToProto(accumulated_, response_.mutable_accumulated());
    StartWrite(&response_);
  }

  void FinishOnce(const absl::Status& status) {
    record_.Finished(status, absl::StrCat("frames=", next_frame_));
    Finish(ToGrpc(status));
  }

  Shared* shared_;
  CallRecord record_;
  grpc::CallbackServerContext* context_;
  std::string caller_;
  std::string session_id_;
  SessionSettings settings_;
  core::RegistrationOptions options_;
  double deadline_seconds_ = 0.0;
  bool constant_velocity_ = false;
  bool started_ = false;
  uint64_t next_frame_ = 0;
  std::unique_ptr<CloudAssembler> assembler_;
  std::shared_ptr<const core::Octree> previous_;
  std::shared_ptr<const core::Octree> current_;
  Eigen::Isometry3d accumulated_ = Eigen::Isometry3d::Identity();
  std::optional<Eigen::Isometry3d> last_relative_;
  absl::Time frame_received_;
  double tree_seconds_ = 0.0;
  v1::TrackRequest request_;
  v1::TrackResponse response_;
  std::shared_ptr<std::atomic<bool>> cancelled_ = std::make_shared<std::atomic<bool>>(false);
  bool holds_stream_ = false;
};

// Runs a short synchronous unary handler on the call's default reactor.
template <typename Handler>
grpc::ServerUnaryReactor* RunUnary(Shared* shared, absl::string_view method,
                                   grpc::CallbackServerContext* context, Handler handler) {
  CallRecord record(shared, method, context);
  absl::StatusOr<std::string> caller = shared->AdmitCaller(context, /*needs_model=*/false);
  const absl::Status status = caller.ok() ? handler(*caller) : caller.status();
  record.Finished(status);
  grpc::ServerUnaryReactor* reactor = context->DefaultReactor();
  reactor->Finish(ToGrpc(status));
  return reactor;
}

}  // namespace

// ---------------------------------------------------------------------------------------------
// The service

RegistrationService::RegistrationService(const ServerOptions& options, ServiceMetrics* metrics,
                                         SessionStore* store)
    : shared_(std::make_unique<Shared>()) {
  shared_->options = options;
  shared_->metrics = metrics;
  shared_->store = store;
}

RegistrationService::~RegistrationService() { StopBatcher(); }

void RegistrationService::SetEngine(std::shared_ptr<const core::Registrar> registrar,
                                    std::unique_ptr<RegistrationBatcher> batcher) {
  absl::MutexLock lock(&shared_->engine_mu);
  shared_->registrar = std::move(registrar);
  shared_->owned_batcher = std::move(batcher);
  shared_->batcher.store(shared_->owned_batcher.get());
}

bool RegistrationService::ready() const { return shared_->batcher.load() != nullptr; }

void RegistrationService::StartDraining() { shared_->draining.store(true); }

void RegistrationService::StopBatcher() {
  RegistrationBatcher* batcher = nullptr;
  {
    absl::MutexLock lock(&shared_->engine_mu);
    batcher = shared_->owned_batcher.get();
  }
  if (batcher != nullptr) batcher->Stop();
}

grpc::ServerUnaryReactor* RegistrationService::GetServerInfo(grpc::CallbackServerContext* context,
                                                             const v1::GetServerInfoRequest*,
                                                             v1::ServerInfo* response) {
  Shared* shared = shared_.get();
  return RunUnary(shared, "GetServerInfo", context, [&](const std::string&) {
    const ServerOptions& o = shared->options;
    response->set_server_version(ServerVersion());
    response->set_api_version("rpsr.v1");
    response->set_model_name(shared->ModelName());
    {
      absl::MutexLock lock(&shared->engine_mu);
      response->set_model_description(shared->registrar != nullptr
                                          ? shared->registrar->model_description()
                                          : std::string("(loading)"));
    }
    for (const char* mode : {"net", "net+refine", "refine"}) response->add_modes(mode);
    response->set_default_mode("net+refine");
    response->set_auth_required(!o.auth_tokens.empty());
    v1::ServerLimits* limits = response->mutable_limits();
    limits->set_max_points_per_cloud(o.max_points_per_cloud);
    limits->set_max_clouds_per_session(o.cache.max_clouds_per_session);
    limits->set_max_sessions(o.cache.max_sessions);
    limits->set_max_message_bytes(o.max_message_bytes);
    limits->set_max_inline_points(o.max_inline_points);
    limits->set_memory_budget_bytes(o.cache.memory_budget_bytes);
    limits->set_default_tree_max_depth(o.default_tree_max_depth);
    limits->set_min_tree_max_depth(o.min_tree_max_depth);
    limits->set_max_tree_max_depth(o.max_tree_max_depth);
    limits->set_default_ttl_seconds(absl::ToDoubleSeconds(o.cache.default_ttl));
    limits->set_max_ttl_seconds(absl::ToDoubleSeconds(o.cache.max_ttl));
    limits->set_max_batch(static_cast<uint32_t>(o.batching.max_batch));
    limits->set_max_queue_delay_seconds(absl::ToDoubleSeconds(o.batching.max_queue_delay));
    limits->set_max_queue_size(static_cast<uint32_t>(o.batching.max_queue));
    limits->set_workers(static_cast<uint32_t>(o.batching.workers));
    limits->set_recommended_chunk_points(shared->RecommendedChunkPoints());
    limits->set_max_open_streams(o.max_open_streams);
    return absl::OkStatus();
  });
}

grpc::ServerUnaryReactor* RegistrationService::CreateSession(
    grpc::CallbackServerContext* context, const v1::CreateSessionRequest* request,
    v1::CreateSessionResponse* response) {
  Shared* shared = shared_.get();
  return RunUnary(shared, "CreateSession", context, [&](const std::string& caller) {
    const ServerOptions& o = shared->options;
    const v1::SessionOptions& asked = request->options();
    SessionSettings settings = shared->DefaultSettings();
    settings.owner = caller;
    if (asked.tree_max_depth() != 0) {
      if (asked.tree_max_depth() < o.min_tree_max_depth ||
          asked.tree_max_depth() > o.max_tree_max_depth) {
        return absl::InvalidArgumentError(absl::StrCat(
            "options.tree_max_depth is ", asked.tree_max_depth(), "; this server builds trees of ",
            o.min_tree_max_depth, " to ", o.max_tree_max_depth, " levels (0: its default, ",
            o.default_tree_max_depth, ")"));
      }
      settings.tree_max_depth = asked.tree_max_depth();
    }
    if (!asked.model().empty() && asked.model() != shared->ModelName()) {
      return absl::FailedPreconditionError(absl::StrCat(
          "this server runs model \"", shared->ModelName(), "\", not \"", asked.model(), "\""));
    }
    if (!std::isfinite(asked.ttl_seconds()) || asked.ttl_seconds() < 0) {
      return absl::InvalidArgumentError(absl::StrCat("options.ttl_seconds is ", asked.ttl_seconds(),
                                                     "; a finite number >= 0 expected"));
    }
    if (asked.ttl_seconds() > 0) {
      settings.ttl = std::min(absl::Seconds(asked.ttl_seconds()), o.cache.max_ttl);
    }
    absl::StatusOr<std::string> id = shared->store->CreateSession(settings);
    if (!id.ok()) return id.status();
    response->set_session_id(*id);
    v1::SessionOptions* effective = response->mutable_options();
    effective->set_tree_max_depth(settings.tree_max_depth);
    effective->set_model(shared->ModelName());
    effective->set_ttl_seconds(absl::ToDoubleSeconds(settings.ttl));
    return absl::OkStatus();
  });
}

grpc::ServerUnaryReactor* RegistrationService::CloseSession(grpc::CallbackServerContext* context,
                                                            const v1::CloseSessionRequest* request,
                                                            v1::CloseSessionResponse* response) {
  Shared* shared = shared_.get();
  return RunUnary(shared, "CloseSession", context, [&](const std::string& caller) {
    absl::StatusOr<size_t> released = shared->store->CloseSession(request->session_id(), caller);
    if (!released.ok()) return released.status();
    response->set_clouds_released(static_cast<uint32_t>(*released));
    return absl::OkStatus();
  });
}

grpc::ServerUnaryReactor* RegistrationService::ReleaseCloud(grpc::CallbackServerContext* context,
                                                            const v1::ReleaseCloudRequest* request,
                                                            v1::ReleaseCloudResponse*) {
  Shared* shared = shared_.get();
  return RunUnary(shared, "ReleaseCloud", context, [&](const std::string& caller) {
    return shared->store->ReleaseCloud(request->session_id(), caller, request->cloud_id());
  });
}

grpc::ServerReadReactor<v1::UploadCloudRequest>* RegistrationService::UploadCloud(
    grpc::CallbackServerContext* context, v1::UploadCloudResponse* response) {
  return new UploadReactor(shared_.get(), context, response);
}

grpc::ServerUnaryReactor* RegistrationService::Register(grpc::CallbackServerContext* context,
                                                        const v1::RegisterRequest* request,
                                                        v1::RegisterResponse* response) {
  return new RegisterReactor(shared_.get(), context, request, response);
}

grpc::ServerBidiReactor<v1::TrackRequest, v1::TrackResponse>* RegistrationService::Track(
    grpc::CallbackServerContext* context) {
  return new TrackReactor(shared_.get(), context);
}

}  // namespace rpsr::server
