#include "client/rpsr_client.h"

#include <grpcpp/grpcpp.h>

#include <algorithm>
#include <bit>
#include <chrono>
#include <cmath>
#include <cstring>
#include <map>
#include <mutex>
#include <random>
#include <thread>
#include <utility>

#include "absl/strings/str_cat.h"
#include "absl/synchronization/mutex.h"
#include "rpsr/v1/registration.grpc.pb.h"
#include "rpsr/v1/registration.pb.h"

namespace rpsr::client {

static_assert(sizeof(Eigen::Vector3f) == 12, "points are sent as packed float32 xyz");
static_assert(std::endian::native == std::endian::little,
              "the wire format is little-endian float32; add a byte swap for this machine");

namespace {

constexpr uint64_t kDefaultChunkPoints = 65536;

absl::Status ToAbslStatus(const grpc::Status& status) {
  if (status.ok()) return absl::OkStatus();
  return absl::Status(static_cast<absl::StatusCode>(status.error_code()), status.error_message());
}

std::string PackPoints(absl::Span<const Eigen::Vector3f> points) {
  std::string bytes(points.size() * sizeof(Eigen::Vector3f), '\0');
  if (!points.empty()) std::memcpy(bytes.data(), points.data(), bytes.size());
  return bytes;
}

void ToProto(const Eigen::Isometry3d& T, rpsr::v1::RigidTransform* out) {
  out->clear_rotation();
  out->clear_translation();
  for (int r = 0; r < 3; ++r) {
    for (int c = 0; c < 3; ++c) out->add_rotation(T.linear()(r, c));
  }
  for (int i = 0; i < 3; ++i) out->add_translation(T.translation()[i]);
  const Eigen::Quaterniond q(T.linear());
  out->mutable_quaternion()->set_w(q.w());
  out->mutable_quaternion()->set_x(q.x());
  out->mutable_quaternion()->set_y(q.y());
  out->mutable_quaternion()->set_z(q.z());
}

Eigen::Isometry3d FromProto(const rpsr::v1::RigidTransform& in) {
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  if (in.rotation_size() == 9) {
    for (int r = 0; r < 3; ++r) {
      for (int c = 0; c < 3; ++c) T.linear()(r, c) = in.rotation(3 * r + c);
    }
  } else if (in.has_quaternion()) {
    Eigen::Quaterniond q(in.quaternion().w(), in.quaternion().x(), in.quaternion().y(),
                         in.quaternion().z());
    if (q.norm() > 0) T.linear() = q.normalized().toRotationMatrix();
  }
  if (in.translation_size() == 3) {
    T.translation() = Eigen::Vector3d(in.translation(0), in.translation(1), in.translation(2));
  }
  return T;
}

TreeStats FromProto(const rpsr::v1::TreeStats& in) {
  TreeStats out;
  out.num_points = in.num_points();
  out.max_depth = in.max_depth();
  out.nodes_per_depth.assign(in.nodes_per_depth().begin(), in.nodes_per_depth().end());
  out.memory_bytes = in.memory_bytes();
  if (in.cube_center_size() == 3) {
    out.cube_center = Eigen::Vector3d(in.cube_center(0), in.cube_center(1), in.cube_center(2));
  }
  out.cube_half_length = in.cube_half_length();
  out.build_seconds = in.build_seconds();
  return out;
}

RegistrationResult FromProto(const rpsr::v1::RegistrationResult& in) {
  RegistrationResult out;
  out.T_target_source = FromProto(in.transform_target_source());
  out.valid = in.valid();
  out.failure_reason = in.failure_reason();
  out.confidence = in.confidence();
  out.fitness = in.fitness();
  out.inlier_rmse = in.inlier_rmse();
  out.iterations = in.iterations();
  out.converged = in.converged();
  if (in.information_size() == 36) {
    for (int i = 0; i < 36; ++i) out.information(i / 6, i % 6) = in.information(i);
  }
  for (int i = 0; i < std::min(6, in.degenerate_axes_size()); ++i) {
    out.degenerate_axes[i] = in.degenerate_axes(i);
  }
  out.num_degenerate = in.num_degenerate();
  out.held_at_initial = in.held_at_initial();
  out.line_normals_from_planes = in.line_normals_from_planes();
  out.surface_scatter_cells = in.surface_scatter_cells();
  out.noise_polished = in.noise_polished();
  if (in.has_structure_alternative_transform_target_source()) {
    out.structure_alternative_T_target_source =
        FromProto(in.structure_alternative_transform_target_source());
  }
  out.net_T_target_source = FromProto(in.net_transform_target_source());
  out.net_score_peak = in.net_score_peak();
  out.start = in.start();
  out.starts = static_cast<int>(in.starts());
  out.mode = in.mode();
  const rpsr::v1::Timings& t = in.timings();
  out.timings = {t.queue_seconds(),  t.tree_seconds(),       t.net_seconds(),
                 t.refine_seconds(), t.confidence_seconds(), t.registrar_seconds(),
                 t.server_seconds(), t.batch_size()};
  return out;
}

void ToProto(const RegisterOptions& in, rpsr::v1::RegisterOptions* out) {
  out->set_mode(in.mode);
  out->set_passes(in.passes);
  if (in.initial_T_target_source)
    ToProto(*in.initial_T_target_source, out->mutable_initial_guess());
  out->set_deadline_seconds(absl::ToDoubleSeconds(in.server_deadline));
  out->set_refine_from_initial(in.refine_from_initial);
  out->set_search_scene_start(in.search_scene_start);
  out->set_later_passes_when_unconfident(in.later_passes_when_unconfident);
  out->set_symmetric_starts(in.symmetric_starts);
  out->set_round_axis_start(in.round_axis_start);
  out->set_weak_direction_start(in.weak_direction_start);
  out->set_weak_direction_finest_round(in.weak_direction_finest_round);
  out->set_centroid_start(in.centroid_start);
  out->set_principal_axes_start(in.principal_axes_start);
  out->set_extent_slide(in.extent_slide);
  out->set_weak_direction_chamfer(in.weak_direction_chamfer);
  out->set_half_turn_start(in.half_turn_start);
  out->set_screw_turns(in.screw_turns);
  out->set_far_valley(in.far_valley);
  out->set_sensor_aligned_check(in.sensor_aligned_check);
  out->set_rebin_coarse_depths(in.rebin_coarse_depths);
  out->set_joint_finest_stage(in.joint_finest_stage);
  out->set_coarse_wide_search(in.coarse_wide_search);
  out->set_noise_polish(in.noise_polish);
  if (in.line_normals_from_planes.has_value()) {
    out->set_line_normals_from_planes(*in.line_normals_from_planes);
  }
  out->set_hold_degenerate_at_initial(in.hold_degenerate_at_initial);
}

double SecondsSince(std::chrono::steady_clock::time_point start) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
}

}  // namespace

absl::Duration RetryBackoff(const RetryOptions& options, int attempt, double uniform01) {
  const double cap_seconds = absl::ToDoubleSeconds(options.max_backoff);
  const double exponential = absl::ToDoubleSeconds(options.initial_backoff) *
                             std::pow(std::max(options.multiplier, 1.0), std::max(attempt - 1, 0));
  return absl::Seconds(std::clamp(uniform01, 0.0, 1.0) * std::min(cap_seconds, exponential));
}

// The channel, its stub and what every call needs (deadline, token, retries).
class ClientChannel {
 public:
  ClientChannel(ClientOptions options, std::shared_ptr<grpc::Channel> channel)
      : options_(std::move(options)),
        channel_(std::move(channel)),
        stub_(rpsr::v1::RegistrationService::NewStub(channel_)),
        random_(std::random_device{}()) {}

  const ClientOptions& options() const { return options_; }
  grpc::Channel& channel() { return *channel_; }
  rpsr::v1::RegistrationService::Stub& stub() { return *stub_; }
  uint64_t chunk_points() const {
    return options_.chunk_points > 0 ? options_.chunk_points : kDefaultChunkPoints;
  }

  // A context with the bearer token and a deadline (`timeout`, or the default; none when
  // `with_deadline` is false).
  void Prepare(grpc::ClientContext& context, absl::Duration timeout = absl::ZeroDuration(),
               bool with_deadline = true) const {
    if (with_deadline) {
      const absl::Duration deadline =
          timeout > absl::ZeroDuration() ? timeout : options_.default_deadline;
      if (deadline > absl::ZeroDuration() && deadline != absl::InfiniteDuration()) {
        context.set_deadline(std::chrono::system_clock::now() +
                             absl::ToChronoMilliseconds(deadline));
      }
    }
    if (!options_.bearer_token.empty()) {
      context.AddMetadata("authorization", "Bearer " + options_.bearer_token);
    }
  }

  // Session affinity (deploy/envoy/envoy.yaml): every call of one session carries the same
  // random key, so a consistent-hash proxy sends them all to the replica that caches the
  // session's trees; without it the proxy hashes the client's address, which puts every session
  // of a host (or of a NAT) on one replica. Drawn before the session exists (CreateSession must
  // land where the later calls will) and kept when the session is re-created.
  std::string NewAffinityKey() {
    absl::MutexLock lock(&random_mutex_);
    return absl::StrCat(absl::Hex(random_(), absl::kZeroPad16));
  }
  static void AddAffinity(grpc::ClientContext& context, const std::string& affinity_key) {
    if (!affinity_key.empty()) context.AddMetadata("x-rpsr-affinity", affinity_key);
  }

  // Runs `attempt` (which returns an absl::Status) until it answers anything but UNAVAILABLE or
  // the attempts run out.
  template <typename Attempt>
  absl::Status WithRetries(Attempt&& attempt) {
    absl::Status status;
    const int attempts = std::max(options_.retry.max_attempts, 1);
    for (int k = 1; k <= attempts; ++k) {
      status = attempt();
      if (status.code() != absl::StatusCode::kUnavailable || k == attempts) break;
      double draw;
      {
        absl::MutexLock lock(&random_mutex_);
        draw = std::uniform_real_distribution<double>(0.0, 1.0)(random_);
      }
      std::this_thread::sleep_for(
          absl::ToChronoMicroseconds(RetryBackoff(options_.retry, k, draw)));
    }
    return status;
  }

  // One whole upload (no retries): the first message carries the session and the count.
  absl::StatusOr<rpsr::v1::UploadCloudResponse> UploadOnce(const std::string& session_id,
                                                           absl::Span<const Eigen::Vector3f> points,
                                                           const std::string& affinity_key) {
    grpc::ClientContext context;
    Prepare(context);
    AddAffinity(context, affinity_key);
    rpsr::v1::UploadCloudResponse response;
    std::unique_ptr<grpc::ClientWriter<rpsr::v1::UploadCloudRequest>> writer =
        stub_->UploadCloud(&context, &response);
    const uint64_t chunk = chunk_points();
    uint32_t sequence = 0;
    size_t offset = 0;
    do {
      const size_t count = std::min<size_t>(chunk, points.size() - offset);
      rpsr::v1::UploadCloudRequest request;
      if (sequence == 0) {
        request.set_session_id(session_id);
        request.set_point_count(points.size());
      }
      request.set_sequence(sequence++);
      request.set_xyz(PackPoints(points.subspan(offset, count)));
      offset += count;
      // A failed write means the server ended the call; Finish says why.
      if (!writer->Write(request)) break;
    } while (offset < points.size());
    writer->WritesDone();
    absl::Status status = ToAbslStatus(writer->Finish());
    if (!status.ok()) return status;
    return response;
  }

 private:
  ClientOptions options_;
  std::shared_ptr<grpc::Channel> channel_;
  std::unique_ptr<rpsr::v1::RegistrationService::Stub> stub_;
  absl::Mutex random_mutex_;
  std::mt19937_64 random_ ABSL_GUARDED_BY(random_mutex_);
};

// ---------------------------------------------------------------------------------------------
// Tracker

class TrackerStream {
 public:
  TrackerStream(std::shared_ptr<ClientChannel> channel, const std::string& session_id,
                const std::string& affinity_key, const TrackerOptions& options)
      : channel_(std::move(channel)) {
    channel_->Prepare(context_, absl::ZeroDuration(), /*with_deadline=*/false);
    ClientChannel::AddAffinity(context_, affinity_key);
    stream_ = channel_->stub().Track(&context_);
    rpsr::v1::TrackRequest request;
    rpsr::v1::TrackStart* start = request.mutable_start();
    start->set_session_id(session_id);
    ToProto(options.registration, start->mutable_options());
    start->set_constant_velocity_prior(options.constant_velocity_prior);
    if (!stream_->Write(request)) broken_ = true;
  }

  ~TrackerStream() {
    if (!finished_) {
      context_.TryCancel();
      (void)stream_->Finish();
    }
  }

  absl::StatusOr<TrackedFrame> AddFrame(absl::Span<const Eigen::Vector3f> points) {
    if (finished_) return absl::FailedPreconditionError("the tracker was finished");
    const auto start = std::chrono::steady_clock::now();
    const uint64_t chunk = channel_->chunk_points();
    uint32_t sequence = 0;
    size_t offset = 0;
    do {
      if (broken_) return Finish().ok() ? absl::InternalError("Track stream closed") : Finish();
      const size_t count = std::min<size_t>(chunk, points.size() - offset);
      rpsr::v1::TrackRequest request;
      rpsr::v1::FrameChunk* frame_chunk = request.mutable_chunk();
      frame_chunk->set_frame_index(next_frame_);
      frame_chunk->set_sequence(sequence);
      if (sequence == 0) frame_chunk->set_point_count(points.size());
      frame_chunk->set_xyz(PackPoints(points.subspan(offset, count)));
      ++sequence;
      offset += count;
      if (!stream_->Write(request)) broken_ = true;
    } while (offset < points.size());
    rpsr::v1::TrackResponse response;
    if (broken_ || !stream_->Read(&response)) {
      absl::Status status = Finish();
      if (status.ok()) status = absl::InternalError("the server ended the Track stream early");
      return status;
    }
    ++next_frame_;
    TrackedFrame frame;
    frame.frame_index = response.frame_index();
    if (response.has_relative()) frame.relative = FromProto(response.relative());
    frame.T_frame0_current = FromProto(response.accumulated());
    frame.tree = FromProto(response.tree());
    frame.round_trip_seconds = SecondsSince(start);
    return frame;
  }

  absl::Status Finish() {
    if (finished_) return final_status_;
    finished_ = true;
    stream_->WritesDone();
    rpsr::v1::TrackResponse ignored;
    while (stream_->Read(&ignored)) {
    }
    final_status_ = ToAbslStatus(stream_->Finish());
    return final_status_;
  }

 private:
  std::shared_ptr<ClientChannel> channel_;
  grpc::ClientContext context_;
  std::unique_ptr<grpc::ClientReaderWriter<rpsr::v1::TrackRequest, rpsr::v1::TrackResponse>>
      stream_;
  uint64_t next_frame_ = 0;
  bool broken_ = false;
  bool finished_ = false;
  absl::Status final_status_;
};

Tracker::Tracker(std::unique_ptr<TrackerStream> stream) : stream_(std::move(stream)) {}
Tracker::~Tracker() = default;
absl::StatusOr<TrackedFrame> Tracker::AddFrame(absl::Span<const Eigen::Vector3f> points) {
  return stream_->AddFrame(points);
}
absl::Status Tracker::Finish() { return stream_->Finish(); }

// ---------------------------------------------------------------------------------------------
// Session

// Client cloud ids are the session's own counter: the server's ids change when a cloud is
// re-uploaded or its session re-created, the caller's do not.
class SessionState {
 public:
  SessionState(std::shared_ptr<ClientChannel> channel, SessionOptions requested)
      : channel_(std::move(channel)),
        requested_(std::move(requested)),
        affinity_key_(channel_->NewAffinityKey()) {}

  ~SessionState() { (void)Close(); }

  absl::Status Open() {
    absl::MutexLock lock(&mutex_);
    return OpenLocked();
  }

  std::string id() const {
    absl::MutexLock lock(&mutex_);
    return session_id_;
  }
  // A copy: a re-creation on another thread rewrites them.
  SessionOptions options() const {
    absl::MutexLock lock(&mutex_);
    return effective_;
  }
  std::shared_ptr<ClientChannel> shared_channel() { return channel_; }
  const std::string& affinity_key() const { return affinity_key_; }

  absl::StatusOr<UploadedCloud> Upload(absl::Span<const Eigen::Vector3f> points) {
    const auto start = std::chrono::steady_clock::now();
    absl::StatusOr<rpsr::v1::UploadCloudResponse> response = UploadWithRecovery(points);
    if (!response.ok()) return response.status();
    UploadedCloud uploaded;
    uploaded.tree = FromProto(response->tree());
    absl::MutexLock lock(&mutex_);
    uploaded.cloud_id = next_client_id_++;
    Cloud& cloud = clouds_[uploaded.cloud_id];
    cloud.server_id = response->cloud_id();
    cloud.generation = generation_;
    if (requested_.keep_points_for_reupload) {
      cloud.points =
          std::make_shared<const std::vector<Eigen::Vector3f>>(points.begin(), points.end());
    }
    uploaded.upload_seconds = SecondsSince(start);
    return uploaded;
  }

  absl::StatusOr<RegistrationResult> Register(uint64_t source_id, uint64_t target_id,
                                              const RegisterOptions& options) {
    const auto start = std::chrono::steady_clock::now();
    absl::StatusOr<RegistrationResult> result = RegisterOnce(source_id, target_id, options);
    if (result.status().code() == absl::StatusCode::kNotFound) {
      // Evicted cloud or expired session: upload what is gone again (re-creating the session if
      // needed) and try once more.
      for (uint64_t id : {source_id, target_id}) {
        if (absl::Status status = Reupload(id); !status.ok()) {
          return absl::Status(status.code(),
                              absl::StrCat(result.status().message(), "; re-upload of cloud ", id,
                                           " failed: ", status.message()));
        }
      }
      result = RegisterOnce(source_id, target_id, options);
    }
    if (result.ok()) result->round_trip_seconds = SecondsSince(start);
    return result;
  }

  absl::Status Release(uint64_t cloud_id) {
    uint64_t server_id = 0;
    bool current = false;
    std::string session_id;
    {
      absl::MutexLock lock(&mutex_);
      auto it = clouds_.find(cloud_id);
      if (it == clouds_.end()) {
        return absl::NotFoundError(absl::StrCat("cloud ", cloud_id, " is not in this session"));
      }
      server_id = it->second.server_id;
      current = it->second.generation == generation_;
      session_id = session_id_;
      clouds_.erase(it);
    }
    if (!current) return absl::OkStatus();  // its session is gone already
    absl::Status status = channel_->WithRetries([&] {
      grpc::ClientContext context;
      channel_->Prepare(context);
      ClientChannel::AddAffinity(context, affinity_key_);
      rpsr::v1::ReleaseCloudRequest request;
      request.set_session_id(session_id);
      request.set_cloud_id(server_id);
      rpsr::v1::ReleaseCloudResponse response;
      return ToAbslStatus(channel_->stub().ReleaseCloud(&context, request, &response));
    });
    // Already evicted or expired: released all the same.
    return status.code() == absl::StatusCode::kNotFound ? absl::OkStatus() : status;
  }

  absl::Status Close() {
    std::string session_id;
    {
      absl::MutexLock lock(&mutex_);
      if (closed_) return absl::OkStatus();
      closed_ = true;
      session_id = session_id_;
      clouds_.clear();
    }
    if (session_id.empty()) return absl::OkStatus();
    absl::Status status = channel_->WithRetries([&] {
      grpc::ClientContext context;
      channel_->Prepare(context, absl::Seconds(5));
      ClientChannel::AddAffinity(context, affinity_key_);
      rpsr::v1::CloseSessionRequest request;
      request.set_session_id(session_id);
      rpsr::v1::CloseSessionResponse response;
      return ToAbslStatus(channel_->stub().CloseSession(&context, request, &response));
    });
    return status.code() == absl::StatusCode::kNotFound ? absl::OkStatus() : status;
  }

 private:
  struct Cloud {
    uint64_t server_id = 0;
    uint64_t generation = 0;  // the session generation the server id belongs to
    std::shared_ptr<const std::vector<Eigen::Vector3f>> points;
  };

  absl::Status OpenLocked() ABSL_EXCLUSIVE_LOCKS_REQUIRED(mutex_) {
    if (closed_) return absl::FailedPreconditionError("the session was closed");
    rpsr::v1::CreateSessionResponse response;
    absl::Status status = channel_->WithRetries([&] {
      grpc::ClientContext context;
      channel_->Prepare(context);
      ClientChannel::AddAffinity(context, affinity_key_);
      rpsr::v1::CreateSessionRequest request;
      request.mutable_options()->set_tree_max_depth(requested_.tree_max_depth);
      request.mutable_options()->set_model(requested_.model);
      request.mutable_options()->set_ttl_seconds(absl::ToDoubleSeconds(requested_.ttl));
      return ToAbslStatus(channel_->stub().CreateSession(&context, request, &response));
    });
    if (!status.ok()) return status;
    session_id_ = response.session_id();
    ++generation_;
    effective_ = requested_;
    effective_.tree_max_depth = response.options().tree_max_depth();
    effective_.model = response.options().model();
    effective_.ttl = absl::Seconds(response.options().ttl_seconds());
    return absl::OkStatus();
  }

  // Re-creates the session unless another thread did since `stale_session_id` was used.
  absl::Status ReopenIfStill(const std::string& stale_session_id) {
    absl::MutexLock lock(&mutex_);
    if (session_id_ != stale_session_id) return absl::OkStatus();
    return OpenLocked();
  }

  absl::StatusOr<rpsr::v1::UploadCloudResponse> UploadWithRecovery(
      absl::Span<const Eigen::Vector3f> points) {
    for (int attempt = 0;; ++attempt) {
      const std::string session_id = id();
      if (closed()) return absl::FailedPreconditionError("the session was closed");
      absl::StatusOr<rpsr::v1::UploadCloudResponse> response;
      absl::Status status = channel_->WithRetries([&] {
        response = channel_->UploadOnce(session_id, points, affinity_key_);
        return response.status();
      });
      // NOT_FOUND on upload: the session expired; open a new one once.
      if (status.code() != absl::StatusCode::kNotFound || attempt > 0) return response;
      if (absl::Status reopened = ReopenIfStill(session_id); !reopened.ok()) return reopened;
    }
  }

  bool closed() const {
    absl::MutexLock lock(&mutex_);
    return closed_;
  }

  absl::Status Reupload(uint64_t client_id) {
    std::shared_ptr<const std::vector<Eigen::Vector3f>> points;
    {
      absl::MutexLock lock(&mutex_);
      auto it = clouds_.find(client_id);
      if (it == clouds_.end()) {
        return absl::NotFoundError(absl::StrCat("cloud ", client_id, " is not in this session"));
      }
      points = it->second.points;
    }
    if (points == nullptr) {
      return absl::NotFoundError(
          "its points were not kept (SessionOptions::keep_points_for_reupload is false)");
    }
    absl::StatusOr<rpsr::v1::UploadCloudResponse> response = UploadWithRecovery(*points);
    if (!response.ok()) return response.status();
    absl::MutexLock lock(&mutex_);
    auto it = clouds_.find(client_id);
    if (it != clouds_.end()) {
      it->second.server_id = response->cloud_id();
      it->second.generation = generation_;
    }
    return absl::OkStatus();
  }

  absl::StatusOr<RegistrationResult> RegisterOnce(uint64_t source_id, uint64_t target_id,
                                                  const RegisterOptions& options) {
    rpsr::v1::RegisterRequest request;
    {
      absl::MutexLock lock(&mutex_);
      if (closed_) return absl::FailedPreconditionError("the session was closed");
      for (uint64_t id : {source_id, target_id}) {
        if (!clouds_.contains(id)) {
          return absl::InvalidArgumentError(
              absl::StrCat("cloud ", id, " was not uploaded in this session (or was released)"));
        }
      }
      const Cloud& source = clouds_[source_id];
      const Cloud& target = clouds_[target_id];
      // A cloud of an earlier session generation is gone with it: ask for the re-upload.
      if (source.generation != generation_ || target.generation != generation_) {
        return absl::NotFoundError("the cloud's session expired and was re-created");
      }
      request.set_session_id(session_id_);
      request.set_source_cloud_id(source.server_id);
      request.set_target_cloud_id(target.server_id);
    }
    ToProto(options, request.mutable_options());
    rpsr::v1::RegisterResponse response;
    absl::Status status = channel_->WithRetries([&] {
      grpc::ClientContext context;
      channel_->Prepare(context, options.timeout);
      ClientChannel::AddAffinity(context, affinity_key_);
      return ToAbslStatus(channel_->stub().Register(&context, request, &response));
    });
    if (!status.ok()) return status;
    return FromProto(response.result());
  }

  std::shared_ptr<ClientChannel> channel_;
  const SessionOptions requested_;
  const std::string affinity_key_;  // see ClientChannel::NewAffinityKey
  SessionOptions effective_ ABSL_GUARDED_BY(mutex_);
  mutable absl::Mutex mutex_;
  std::string session_id_ ABSL_GUARDED_BY(mutex_);
  uint64_t generation_ ABSL_GUARDED_BY(mutex_) = 0;
  bool closed_ ABSL_GUARDED_BY(mutex_) = false;
  uint64_t next_client_id_ ABSL_GUARDED_BY(mutex_) = 1;
  std::map<uint64_t, Cloud> clouds_ ABSL_GUARDED_BY(mutex_);
};

Session::Session(std::shared_ptr<SessionState> state) : state_(std::move(state)) {}
Session::~Session() = default;
std::string Session::id() const { return state_->id(); }
SessionOptions Session::options() const { return state_->options(); }

absl::StatusOr<UploadedCloud> Session::Upload(absl::Span<const Eigen::Vector3f> points) {
  return state_->Upload(points);
}

std::future<absl::StatusOr<UploadedCloud>> Session::UploadAsync(
    std::vector<Eigen::Vector3f> points) {
  return std::async(std::launch::async,
                    [state = state_, points = std::move(points)] { return state->Upload(points); });
}

absl::StatusOr<RegistrationResult> Session::Register(uint64_t source_cloud_id,
                                                     uint64_t target_cloud_id,
                                                     const RegisterOptions& options) {
  return state_->Register(source_cloud_id, target_cloud_id, options);
}

std::future<absl::StatusOr<RegistrationResult>> Session::RegisterAsync(
    uint64_t source_cloud_id, uint64_t target_cloud_id, const RegisterOptions& options) {
  return std::async(std::launch::async,
                    [state = state_, source_cloud_id, target_cloud_id, options] {
                      return state->Register(source_cloud_id, target_cloud_id, options);
                    });
}

absl::StatusOr<RegistrationResult> Session::Register(absl::Span<const Eigen::Vector3f> source,
                                                     absl::Span<const Eigen::Vector3f> target,
                                                     const RegisterOptions& options) {
  const auto start = std::chrono::steady_clock::now();
  absl::StatusOr<UploadedCloud> source_cloud = state_->Upload(source);
  if (!source_cloud.ok()) return source_cloud.status();
  absl::StatusOr<UploadedCloud> target_cloud = state_->Upload(target);
  if (!target_cloud.ok()) {
    (void)state_->Release(source_cloud->cloud_id);
    return target_cloud.status();
  }
  absl::StatusOr<RegistrationResult> result =
      state_->Register(source_cloud->cloud_id, target_cloud->cloud_id, options);
  (void)state_->Release(source_cloud->cloud_id);
  (void)state_->Release(target_cloud->cloud_id);
  if (result.ok()) result->round_trip_seconds = SecondsSince(start);
  return result;
}

absl::Status Session::Release(uint64_t cloud_id) { return state_->Release(cloud_id); }
absl::Status Session::Close() { return state_->Close(); }

absl::StatusOr<std::unique_ptr<Tracker>> Session::StartTracker(const TrackerOptions& options) {
  return std::unique_ptr<Tracker>(new Tracker(std::make_unique<TrackerStream>(
      state_->shared_channel(), id(), state_->affinity_key(), options)));
}

// ---------------------------------------------------------------------------------------------
// Client

Client::Client(std::shared_ptr<ClientChannel> channel) : channel_(std::move(channel)) {}
Client::~Client() = default;

absl::StatusOr<std::unique_ptr<Client>> Client::Connect(const ClientOptions& options) {
  if (options.address.empty()) return absl::InvalidArgumentError("the server address is empty");
  if (options.retry.max_attempts < 1 || options.retry.multiplier < 1.0 ||
      options.retry.initial_backoff < absl::ZeroDuration() ||
      options.retry.max_backoff < absl::ZeroDuration()) {
    return absl::InvalidArgumentError(
        "retry options: max_attempts >= 1, multiplier >= 1 and non-negative backoffs");
  }
  if (!options.use_tls && !options.tls_root_certs_pem.empty()) {
    return absl::InvalidArgumentError("TLS root certificates given but use_tls is false");
  }
  std::shared_ptr<grpc::ChannelCredentials> credentials;
  if (options.use_tls) {
    grpc::SslCredentialsOptions ssl;
    ssl.pem_root_certs = options.tls_root_certs_pem;
    credentials = grpc::SslCredentials(ssl);
  } else {
    credentials = grpc::InsecureChannelCredentials();
  }
  grpc::ChannelArguments arguments;
  arguments.SetMaxReceiveMessageSize(64 << 20);
  if (options.keepalive_time > absl::ZeroDuration()) {
    arguments.SetInt(GRPC_ARG_KEEPALIVE_TIME_MS,
                     static_cast<int>(absl::ToInt64Milliseconds(options.keepalive_time)));
    arguments.SetInt(GRPC_ARG_KEEPALIVE_TIMEOUT_MS,
                     static_cast<int>(absl::ToInt64Milliseconds(options.keepalive_timeout)));
    arguments.SetInt(GRPC_ARG_KEEPALIVE_PERMIT_WITHOUT_CALLS, 0);
  }
  std::shared_ptr<grpc::Channel> channel =
      grpc::CreateCustomChannel(options.address, credentials, arguments);
  return std::unique_ptr<Client>(new Client(std::make_shared<ClientChannel>(options, channel)));
}

const ClientOptions& Client::options() const { return channel_->options(); }

absl::Status Client::WaitForConnected(absl::Duration timeout) {
  const auto deadline = std::chrono::system_clock::now() + absl::ToChronoMilliseconds(timeout);
  if (channel_->channel().WaitForConnected(deadline)) return absl::OkStatus();
  return absl::DeadlineExceededError(absl::StrCat("no connection to ", channel_->options().address,
                                                  " within ", absl::FormatDuration(timeout)));
}

absl::StatusOr<ServerInfo> Client::GetServerInfo() {
  rpsr::v1::ServerInfo response;
  absl::Status status = channel_->WithRetries([&] {
    grpc::ClientContext context;
    channel_->Prepare(context);
    return ToAbslStatus(
        channel_->stub().GetServerInfo(&context, rpsr::v1::GetServerInfoRequest(), &response));
  });
  if (!status.ok()) return status;
  ServerInfo info;
  info.server_version = response.server_version();
  info.api_version = response.api_version();
  info.model_name = response.model_name();
  info.model_description = response.model_description();
  info.modes.assign(response.modes().begin(), response.modes().end());
  info.default_mode = response.default_mode();
  info.auth_required = response.auth_required();
  const rpsr::v1::ServerLimits& l = response.limits();
  info.limits = {l.max_points_per_cloud(),    l.max_clouds_per_session(), l.max_sessions(),
                 l.max_message_bytes(),       l.max_inline_points(),      l.memory_budget_bytes(),
                 l.default_tree_max_depth(),  l.min_tree_max_depth(),     l.max_tree_max_depth(),
                 l.default_ttl_seconds(),     l.max_ttl_seconds(),        l.max_batch(),
                 l.max_queue_delay_seconds(), l.max_queue_size(),         l.workers(),
                 l.recommended_chunk_points()};
  return info;
}

absl::StatusOr<std::unique_ptr<Session>> Client::CreateSession(const SessionOptions& options) {
  auto state = std::make_shared<SessionState>(channel_, options);
  if (absl::Status status = state->Open(); !status.ok()) return status;
  return std::unique_ptr<Session>(new Session(std::move(state)));
}

absl::StatusOr<RegistrationResult> Client::RegisterInline(absl::Span<const Eigen::Vector3f> source,
                                                          absl::Span<const Eigen::Vector3f> target,
                                                          const RegisterOptions& options) {
  const auto start = std::chrono::steady_clock::now();
  rpsr::v1::RegisterRequest request;
  request.mutable_source_cloud()->set_xyz(PackPoints(source));
  request.mutable_target_cloud()->set_xyz(PackPoints(target));
  ToProto(options, request.mutable_options());
  rpsr::v1::RegisterResponse response;
  absl::Status status = channel_->WithRetries([&] {
    grpc::ClientContext context;
    channel_->Prepare(context, options.timeout);
    return ToAbslStatus(channel_->stub().Register(&context, request, &response));
  });
  if (!status.ok()) return status;
  RegistrationResult result = FromProto(response.result());
  result.round_trip_seconds = SecondsSince(start);
  return result;
}

std::future<absl::StatusOr<RegistrationResult>> Client::RegisterInlineAsync(
    std::vector<Eigen::Vector3f> source, std::vector<Eigen::Vector3f> target,
    const RegisterOptions& options) {
  // The channel (shared) outlives the call even if the Client is destroyed meanwhile.
  return std::async(std::launch::async, [channel = channel_, source = std::move(source),
                                         target = std::move(target), options] {
    Client client(channel);
    return client.RegisterInline(source, target, options);
  });
}

absl::StatusOr<std::unique_ptr<Tracker>> Client::StartTracker(const TrackerOptions& options) {
  return std::unique_ptr<Tracker>(
      new Tracker(std::make_unique<TrackerStream>(channel_, "", "", options)));
}

}  // namespace rpsr::client
