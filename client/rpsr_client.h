// rpsr::client::Client: the C++ client of the rpsr registration service (rpsrd, proto/rpsr/v1).
//
//   auto client = rpsr::client::Client::Connect({.address = "127.0.0.1:50051"});
//   auto session = (*client)->CreateSession({.tree_max_depth = 6});
//   auto source = (*session)->Upload(source_points);        // streamed in chunks, tree built once
//   auto target = (*session)->Upload(target_points);
//   auto result = (*session)->Register(source->cloud_id, target->cloud_id);
//   // result->T_target_source maps source points into the target frame; check result->valid.
//
// What it does for the caller:
//  - chunks uploads under the server's message limit (packed little-endian float32 xyz);
//  - retries calls answered UNAVAILABLE (server starting or draining, connection lost) with
//    exponential backoff and full jitter, up to RetryOptions::max_attempts;
//  - keeps (by default) the points of every cloud it uploaded, so when the server answers NOT_FOUND
//    because the cloud was evicted or the session expired, it re-creates the session if needed,
//    re-uploads and runs the call again; the cloud ids the caller holds stay valid;
//  - attaches the bearer token and a deadline to every call;
//  - returns errors as absl::Status with the server's code and message.
//
// Only Abseil, Eigen and the standard library appear here: no gRPC, protobuf or LibTorch types
// (the implementation sits behind pimpl). Thread-safe: one Client and its Sessions may be used
// from many threads at once; a Tracker is for one thread at a time.
//
// Conventions: T_target_source maps source points into the target frame (p_target = R p_source
// + t); the clouds' units (metres for LiDAR); seconds.
#ifndef RPSR_CLIENT_RPSR_CLIENT_H_
#define RPSR_CLIENT_RPSR_CLIENT_H_

#include <array>
#include <cstdint>
#include <future>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "Eigen/Core"
#include "Eigen/Geometry"
#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "absl/time/time.h"
#include "absl/types/span.h"

namespace rpsr::client {

// Retries of calls answered UNAVAILABLE. Attempt k (1-based) waits a uniformly random time in
// [0, min(max_backoff, initial_backoff * multiplier^(k-1))] before the next ("full jitter", so
// that many clients cut off at once do not come back in step).
struct RetryOptions {
  int max_attempts = 5;  // 1: no retry
  absl::Duration initial_backoff = absl::Milliseconds(50);
  absl::Duration max_backoff = absl::Seconds(2);
  double multiplier = 2.0;
};

struct ClientOptions {
  // host:port of rpsrd.
  std::string address = "127.0.0.1:50051";
  // TLS: true uses tls_root_certs_pem (PEM text) as the trusted roots, or the system's when
  // empty. false: plaintext.
  bool use_tls = false;
  std::string tls_root_certs_pem;
  // Sent as "authorization: Bearer <token>" when not empty.
  std::string bearer_token;
  // Deadline of each call (an upload's or a Track stream's whole life counts as one call for
  // Upload; a Tracker's stream has none). Per-call overrides: RegisterOptions::timeout.
  absl::Duration default_deadline = absl::Seconds(60);
  // HTTP/2 keepalive pings while calls are open (e.g. a quiet Track stream), so a dead peer or
  // a silently dropped connection is noticed; zero: none. A gRPC server refuses pings more often
  // than its GRPC_ARG_HTTP2_MIN_RECV_PING_INTERVAL_WITHOUT_DATA_MS (5 minutes by default) and
  // closes the connection ("too_many_pings"), hence this default.
  absl::Duration keepalive_time = absl::Minutes(5);
  absl::Duration keepalive_timeout = absl::Seconds(10);
  // Points per upload message; 0: 65,536 (768 KiB, well under the default 4 MiB limit).
  uint64_t chunk_points = 0;
  RetryOptions retry;
};

struct ServerLimits {
  uint64_t max_points_per_cloud = 0;
  uint32_t max_clouds_per_session = 0;
  uint32_t max_sessions = 0;
  uint64_t max_message_bytes = 0;
  uint64_t max_inline_points = 0;
  uint64_t memory_budget_bytes = 0;
  int default_tree_max_depth = 0;
  int min_tree_max_depth = 0;
  int max_tree_max_depth = 0;
  double default_ttl_seconds = 0.0;
  double max_ttl_seconds = 0.0;
  uint32_t max_batch = 0;
  double max_queue_delay_seconds = 0.0;
  uint32_t max_queue_size = 0;
  uint32_t workers = 0;
  uint64_t recommended_chunk_points = 0;
};

struct ServerInfo {
  std::string server_version;
  std::string api_version;
  std::string model_name;
  std::string model_description;
  std::vector<std::string> modes;
  std::string default_mode;
  ServerLimits limits;
  bool auth_required = false;
};

struct SessionOptions {
  // Tree depth of this session's clouds; 0: the server's default (objects: 6, LiDAR: 8-9).
  int tree_max_depth = 0;
  // The model expected ("objects"); empty: whatever the server runs.
  std::string model;
  // Time to live after last use; zero: the server's default.
  absl::Duration ttl = absl::ZeroDuration();
  // Keep each uploaded cloud's points in the client, so that an evicted cloud is re-uploaded
  // transparently. false saves the memory; an evicted cloud then answers NOT_FOUND.
  bool keep_points_for_reupload = true;
};

// A cloud's Barnes-Hut tree as the server built it.
struct TreeStats {
  uint64_t num_points = 0;
  int max_depth = 0;
  std::vector<uint32_t> nodes_per_depth;
  uint64_t memory_bytes = 0;
  Eigen::Vector3d cube_center = Eigen::Vector3d::Zero();
  double cube_half_length = 0.0;
  double build_seconds = 0.0;
};

struct UploadedCloud {
  uint64_t cloud_id = 0;  // valid in this Session for the caller, even across re-uploads
  TreeStats tree;
  double upload_seconds = 0.0;  // client side, first to last byte and the answer
};

struct RegisterOptions {
  // "net", "net+refine" or "refine"; empty: the server's default (net+refine).
  std::string mode;
  int passes = 0;  // network passes; 0: the mode's default (net: the model's; net+refine: 2)
  std::optional<Eigen::Isometry3d> initial_T_target_source;
  // Server-side time budget (queued requests past it are dropped unrun); zero: none.
  absl::Duration server_deadline = absl::ZeroDuration();
  // net+refine's later starts (proto RegisterOptions): refine from the initial guess too when
  // the network's start is not confident; search a start about z on scene-scale trees.
  bool refine_from_initial = true;
  bool search_scene_start = true;
  // Run the network's later passes only when the first pass's answer is not confident, and
  // refine their estimate too (proto RegisterOptions.later_passes_when_unconfident).
  bool later_passes_when_unconfident = true;
  // Refine the answer turned by the target's near-symmetry under which the features that break
  // it meet (a gear's pin) too (proto RegisterOptions.symmetric_starts).
  bool symmetric_starts = true;
  // Refine the answer turned about the target's round axis too, when not confident (proto
  // RegisterOptions.round_axis_start).
  bool round_axis_start = true;
  // Refine the answer stepped along its weakest direction too, when that leaves clearly fewer
  // nodes without a partner (proto RegisterOptions.weak_direction_start).
  bool weak_direction_start = true;
  // With weak_direction_start, the same step once more at the finest depth for clean, whole
  // answers where the first kept nothing: a little more accurate on clean object scans, about a
  // quarter slower on objects (proto RegisterOptions.weak_direction_finest_round).
  bool weak_direction_finest_round = false;
  // Refine the answer's rotation with the clouds' centres of mass put together too, when the
  // answer is not confident and leaves them apart, or is confident but overlaps below 97% and
  // leaves them more than 2 cells apart (proto RegisterOptions.centroid_start).
  bool centroid_start = true;
  // Refine starts from the clouds' principal axes too when the answer fits poorly and is not
  // confident (proto RegisterOptions.principal_axes_start).
  bool principal_axes_start = true;
  // Move the answer along its least constrained direction until the clouds' ends agree, when both
  // ends agree on the move (proto RegisterOptions.extent_slide).
  bool extent_slide = true;
  // Move the answer along its least constrained direction to where the points that motion moves
  // across their surface meet the other cloud best, when that direction is still constrained
  // (proto RegisterOptions.weak_direction_chamfer).
  bool weak_direction_chamfer = true;
  // Refine the answer turned by a half turn about a principal axis of a target that nearly maps
  // onto itself under it (a guitar flipped front to back), kept when it fits clearly better
  // (proto RegisterOptions.half_turn_start).
  bool half_turn_start = true;
  // With round_axis_start: the turns of a screw the target nearly maps onto itself under (a helix
  // spring), each advanced by its share of the pitch, scored beside the plain turns (proto
  // RegisterOptions.screw_turns).
  bool screw_turns = true;
  // Move the answer along its least constrained direction to the middle of the valley in the count
  // of nodes without a partner (a spring off along its screw), for object answers below 0.95
  // confidence that overlap almost wholly, cover nine tenths of the target and whose direction is
  // still constrained; never more confident than the answer (proto RegisterOptions.far_valley).
  bool far_valley = true;
  // Check a scene-scale answer that puts the two sensors together against a search over the
  // structure off the ground (proto RegisterOptions.sensor_aligned_check); in mode refine a
  // losing answer is kept but doubted (confidence capped, failure_reason naming the other pose).
  bool sensor_aligned_check = true;
  // The refinement's coarse depths on the target's cells (proto RegisterOptions; false: the
  // source tree's own cells).
  bool rebin_coarse_depths = true;
  // With it, the finest stage also fits the next coarser depth (proto RegisterOptions).
  bool joint_finest_stage = true;
  // With it, the coarse stages search two cells (proto RegisterOptions.coarse_wide_search; false:
  // one, as the finest stage, ~1.1 ms less an object's refinement).
  bool coarse_wide_search = true;
  // Line-shaped nodes (a sparse scan's ring arcs) take their ancestor plane's normal (proto
  // RegisterOptions.line_normals_from_planes): for 16- and 32-beam scanners. Unset: the server
  // chooses per pair (RegistrationResult::line_normals_from_planes says which ran).
  std::optional<bool> line_normals_from_planes;
  // A last point-to-plane stage one depth coarser when the source's points scatter about the
  // surface by a sizeable part of the finest cell (proto RegisterOptions.noise_polish).
  bool noise_polish = true;
  // With initial_T_target_source: a degenerate answer keeps the guess along the unconstrained
  // directions (proto RegisterOptions.hold_degenerate_at_initial; RegistrationResult::
  // held_at_initial).
  bool hold_degenerate_at_initial = true;
  // The gRPC deadline of this call; zero: ClientOptions::default_deadline.
  absl::Duration timeout = absl::ZeroDuration();
};

// Server-side seconds per stage (see proto Timings).
struct ServerTimings {
  double queue_seconds = 0.0;
  double tree_seconds = 0.0;
  double net_seconds = 0.0;
  double refine_seconds = 0.0;
  double confidence_seconds = 0.0;
  double registrar_seconds = 0.0;
  double server_seconds = 0.0;
  uint32_t batch_size = 0;
};

struct RegistrationResult {
  Eigen::Isometry3d T_target_source = Eigen::Isometry3d::Identity();
  // false: do not use T; failure_reason says why (on a valid result: a doubt, see
  // RegisterOptions::sensor_aligned_check).
  bool valid = false;
  std::string failure_reason;
  // Calibrated probability that T is within (1 degree, 1% of the target's extent) of the truth.
  double confidence = 0.0;
  double fitness = 0.0;
  double inlier_rmse = 0.0;
  int iterations = 0;
  bool converged = false;
  Eigen::Matrix<double, 6, 6> information = Eigen::Matrix<double, 6, 6>::Zero();
  std::array<bool, 6> degenerate_axes = {};  // rotation x, y, z, translation x, y, z
  int num_degenerate = 0;
  // The pose along the degenerate directions is the initial guess's (hold_degenerate_at_initial).
  bool held_at_initial = false;
  // Whether line-shaped nodes took their ancestor plane's normal (as asked, or as chosen).
  bool line_normals_from_planes = false;
  // The source's scatter about the target's surface in finest cell edges (negative: not
  // measured) and whether the noise polish ran (proto RegistrationResult).
  double surface_scatter_cells = -1.0;
  bool noise_polished = false;
  // Mode refine, a doubted answer: the pose that fits the structure off the ground clearly better
  // (proto RegistrationResult.structure_alternative_transform_target_source).
  std::optional<Eigen::Isometry3d> structure_alternative_T_target_source;
  Eigen::Isometry3d net_T_target_source = Eigen::Isometry3d::Identity();
  double net_score_peak = 0.0;
  std::string mode;
  // Where the returned pose's refinement started ("network", "network_later_passes", "initial",
  // "searched", "searched_turns", "structure", "round_axis", "weak_direction", "centroid",
  // "principal_axes", "extent_slide", "weak_direction_chamfer", "far_valley", "half_turn",
  // "symmetric") and how
  // many starts the server refined or measured for this pair (proto RegistrationResult.start,
  // .starts).
  std::string start;
  int starts = 0;
  ServerTimings timings;
  // Client side: from the first attempt's start to the answer (retries and re-uploads included).
  double round_trip_seconds = 0.0;
};

struct TrackerOptions {
  RegisterOptions registration;
  // Start each frame's registration from the previous relative motion (LiDAR odometry).
  bool constant_velocity_prior = false;
};

struct TrackedFrame {
  uint64_t frame_index = 0;
  // T_previous_current; absent for frame 0.
  std::optional<RegistrationResult> relative;
  // T_frame0_current.
  Eigen::Isometry3d T_frame0_current = Eigen::Isometry3d::Identity();
  TreeStats tree;
  double round_trip_seconds = 0.0;
};

class ClientChannel;
class SessionState;
class TrackerStream;

// Odometry over the Track stream: each frame is uploaded once and registered on the previous one.
// Not thread-safe; not retried (a broken stream ends the tracking: start a new Tracker).
class Tracker {
 public:
  ~Tracker();  // finishes the stream if Finish was not called
  Tracker(const Tracker&) = delete;
  Tracker& operator=(const Tracker&) = delete;

  // Streams the frame and waits for its answer.
  absl::StatusOr<TrackedFrame> AddFrame(absl::Span<const Eigen::Vector3f> points);
  // Half-closes the stream and returns its final status.
  absl::Status Finish();

 private:
  friend class Session;
  friend class Client;
  explicit Tracker(std::unique_ptr<TrackerStream> stream);
  std::unique_ptr<TrackerStream> stream_;
};

// A server session: a namespace of cached clouds with one tree depth and time to live.
class Session {
 public:
  ~Session();  // closes the session on the server (best effort)
  Session(const Session&) = delete;
  Session& operator=(const Session&) = delete;

  // The server's current id of this session (it changes if the session expired and was
  // re-created).
  std::string id() const;
  // The effective options (defaults filled in by the server), as of the session's latest
  // creation: a copy, since a re-creation on another thread may change them.
  SessionOptions options() const;

  absl::StatusOr<UploadedCloud> Upload(absl::Span<const Eigen::Vector3f> points);
  std::future<absl::StatusOr<UploadedCloud>> UploadAsync(std::vector<Eigen::Vector3f> points);

  absl::StatusOr<RegistrationResult> Register(uint64_t source_cloud_id, uint64_t target_cloud_id,
                                              const RegisterOptions& options = {});
  std::future<absl::StatusOr<RegistrationResult>> RegisterAsync(
      uint64_t source_cloud_id, uint64_t target_cloud_id, const RegisterOptions& options = {});

  // Uploads both clouds, registers them and releases them.
  absl::StatusOr<RegistrationResult> Register(absl::Span<const Eigen::Vector3f> source,
                                              absl::Span<const Eigen::Vector3f> target,
                                              const RegisterOptions& options = {});

  // Frees one cloud on the server (and its kept points).
  absl::Status Release(uint64_t cloud_id);
  // Closes the session on the server; later calls answer FailedPrecondition.
  absl::Status Close();

  // A Track stream whose frames use this session's tree options.
  absl::StatusOr<std::unique_ptr<Tracker>> StartTracker(const TrackerOptions& options = {});

 private:
  friend class Client;
  explicit Session(std::shared_ptr<SessionState> state);
  std::shared_ptr<SessionState> state_;
};

class Client {
 public:
  // Creates the channel (connection is lazy: the first call connects). InvalidArgument for empty
  // addresses or bad options.
  static absl::StatusOr<std::unique_ptr<Client>> Connect(const ClientOptions& options);
  ~Client();
  Client(const Client&) = delete;
  Client& operator=(const Client&) = delete;

  const ClientOptions& options() const;

  // Blocks until the channel is connected or `timeout` passes (DeadlineExceeded).
  absl::Status WaitForConnected(absl::Duration timeout);

  absl::StatusOr<ServerInfo> GetServerInfo();

  absl::StatusOr<std::unique_ptr<Session>> CreateSession(const SessionOptions& options = {});

  // Registers two small clouds sent inline (at most ServerLimits::max_inline_points each), no
  // session needed; trees at the server's default depth.
  absl::StatusOr<RegistrationResult> RegisterInline(absl::Span<const Eigen::Vector3f> source,
                                                    absl::Span<const Eigen::Vector3f> target,
                                                    const RegisterOptions& options = {});
  std::future<absl::StatusOr<RegistrationResult>> RegisterInlineAsync(
      std::vector<Eigen::Vector3f> source, std::vector<Eigen::Vector3f> target,
      const RegisterOptions& options = {});

  // A Track stream with the server's default tree options (see Session::StartTracker).
  absl::StatusOr<std::unique_ptr<Tracker>> StartTracker(const TrackerOptions& options = {});

 private:
  explicit Client(std::shared_ptr<ClientChannel> channel);
  std::shared_ptr<ClientChannel> channel_;
};

// The wait before retry `attempt` (1-based) with full jitter, `uniform01` a draw in [0, 1).
absl::Duration RetryBackoff(const RetryOptions& options, int attempt, double uniform01);

}  // namespace rpsr::client

#endif  // RPSR_CLIENT_RPSR_CLIENT_H_
