// rpsr odometry SEQUENCE_DIR [--server ADDR | --local] --output POSES.txt: registers every
// consecutive frame pair of a KITTI-layout sequence (SEQUENCE_DIR/velodyne/NNNNNN.bin; any cloud
// format core/io reads is accepted there), each frame onto the previous one starting from the
// previous relative motion, and writes the poses in KITTI's format (12 numbers a line, frame 0 =
// identity; camera 0 poses when calib.txt gives Tr, LiDAR poses otherwise). With ground truth
// (poses.txt, or <root>/poses/NN.txt) it reports KITTI's odometry metrics
// (core/data/kitti_odometry_metrics.h) and draws the trajectory against the truth (PNG).
// On a server the frames go through the Track stream: each is uploaded once.
// Exit codes: 0 done, 1 failure (files, server), 2 bad flags.
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <future>
#include <optional>
#include <string>
#include <system_error>
#include <vector>

#include "absl/flags/flag.h"
#include "absl/strings/ascii.h"
#include "absl/strings/numbers.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "absl/strings/str_split.h"
#include "client/cli/cli_progress.h"
#include "client/cli/png_canvas.h"
#include "client/cli/registration_report.h"
#include "client/cli/service_flags.h"
#include "client/cli/shared_flags.h"
#include "client/cli/subcommands.h"
#include "core/data/kitti_odometry.h"
#include "core/data/kitti_odometry_metrics.h"
#include "core/io/file_bytes.h"
#include "core/io/point_cloud_io.h"
#include "core/registrar/registrar.h"

ABSL_FLAG(std::string, plot, "",
          "odometry: the trajectory picture (PNG); default: --output with the extension .png; "
          "'none': no picture");
ABSL_FLAG(int, max_frames, 0, "odometry: use the first N frames only (0: all)");
ABSL_FLAG(std::string, segment_lengths, "100,200,300,400,500,600,700,800",
          "odometry: KITTI metric segment lengths in metres (the benchmark's 100..800; shorter "
          "ones for short sequences)");
ABSL_FLAG(bool, constant_velocity, true,
          "odometry: start each registration from the previous relative motion (false: from "
          "identity)");

namespace rpsr::client {
namespace {

namespace fs = std::filesystem;

constexpr int kFailure = 1;
constexpr int kBadFlags = 2;

int Fail(int code, const std::string& message) {
  std::fprintf(stderr, "rpsr odometry: %s\n", message.c_str());
  return code;
}

// The frames of a sequence folder: velodyne/* (or the folder itself) files that core/io reads,
// sorted by name.
absl::StatusOr<std::vector<std::string>> ListFrames(const fs::path& sequence_dir) {
  fs::path folder = sequence_dir / "velodyne";
  std::error_code error;
  if (!fs::is_directory(folder, error)) folder = sequence_dir;
  if (!fs::is_directory(folder, error)) {
    return absl::NotFoundError(absl::StrCat(sequence_dir.string(), " is not a folder"));
  }
  std::vector<std::string> frames;
  for (const fs::directory_entry& entry : fs::directory_iterator(folder, error)) {
    const std::string extension = absl::AsciiStrToLower(entry.path().extension().string());
    if (entry.is_regular_file() && (extension == ".bin" || extension == ".ply" ||
                                    extension == ".pcd" || extension == ".xyz")) {
      frames.push_back(entry.path().string());
    }
  }
  if (error) return absl::UnavailableError(absl::StrCat(folder.string(), ": ", error.message()));
  std::sort(frames.begin(), frames.end());
  if (frames.size() < 2) {
    return absl::InvalidArgumentError(absl::StrCat(folder.string(), " holds ", frames.size(),
                                                   " frames (.bin .ply .pcd .xyz); need >= 2"));
  }
  return frames;
}

struct GroundTruth {
  std::optional<Eigen::Isometry3d> T_camera_lidar;  // from calib.txt
  std::vector<Eigen::Isometry3d> T_world_camera;    // poses.txt (empty: none)
};

// calib.txt and the poses when the folder is <root>/sequences/NN of a KITTI layout.
GroundTruth ReadGroundTruth(const fs::path& sequence_dir, int frame_count) {
  GroundTruth truth;
  std::error_code error;
  const fs::path dir = fs::weakly_canonical(sequence_dir, error);
  if (absl::StatusOr<std::string> calib = core::ReadFileBytes((dir / "calib.txt").string());
      calib.ok()) {
    absl::StatusOr<Eigen::Isometry3d> tr = core::ParseKittiCalibTr(*calib, "calib.txt");
    if (tr.ok()) truth.T_camera_lidar = *tr;
  }
  int number = 0;
  if (dir.parent_path().filename() == "sequences" &&
      absl::SimpleAtoi(dir.filename().string(), &number)) {
    absl::StatusOr<core::KittiOdometrySequence> sequence =
        core::KittiOdometrySequence::Open(dir.parent_path().parent_path().string(), number);
    if (sequence.ok() && sequence->frame_count() >= frame_count) {
      truth.T_camera_lidar = sequence->T_camera_lidar();
      truth.T_world_camera.assign(sequence->T_world_camera().begin(),
                                  sequence->T_world_camera().begin() + frame_count);
    }
  }
  return truth;
}

absl::StatusOr<std::vector<double>> ParseLengths(const std::string& text) {
  std::vector<double> lengths;
  for (absl::string_view part : absl::StrSplit(text, ',', absl::SkipWhitespace())) {
    double length = 0;
    if (!absl::SimpleAtod(part, &length) || !(length > 0)) {
      return absl::InvalidArgumentError(
          absl::StrCat("--segment_lengths: '", part, "' is not a positive number"));
    }
    lengths.push_back(length);
  }
  if (lengths.empty()) return absl::InvalidArgumentError("--segment_lengths is empty");
  return lengths;
}

// Reads frames one ahead on another thread, so that reading a scan overlaps the registration of
// the previous one.
class FrameReader {
 public:
  explicit FrameReader(const std::vector<std::string>& frames) : frames_(frames) { Prefetch(0); }
  // Frame i (called with i = 0, 1, 2, ... in order).
  absl::StatusOr<core::PointCloud> Next(size_t i) {
    absl::StatusOr<core::PointCloud> cloud = next_.get();
    if (!cloud.ok()) {
      return absl::Status(cloud.status().code(),
                          absl::StrCat(frames_[i], ": ", cloud.status().message()));
    }
    if (i + 1 < frames_.size()) Prefetch(i + 1);
    return cloud;
  }

 private:
  void Prefetch(size_t i) {
    next_ =
        std::async(std::launch::async, [path = frames_[i]] { return core::ReadPointCloud(path); });
  }
  const std::vector<std::string>& frames_;
  std::future<absl::StatusOr<core::PointCloud>> next_;
};

// One frame's registration onto the previous one.
struct Step {
  Eigen::Isometry3d T_previous_current = Eigen::Isometry3d::Identity();
  bool valid = false;
  double confidence = 0.0;
  // Invalid, but held at the previous motion along its degenerate directions
  // (--hold_degenerate_at_initial).
  bool held = false;
  // Line-shaped nodes took their ancestor plane's normal (--line_normals_from_planes, or chosen).
  bool line_normals = false;
  // Where the time of a frame went: the registrar's share, and (on a server) the whole round trip
  // of the frame (upload, tree, registration, answer) as the client saw it.
  double registrar_seconds = 0.0;
  double round_trip_seconds = 0.0;
};

class FrameProgress {
 public:
  explicit FrameProgress(int total) : bar_("frames"), total_(total) {}
  void Update(int done) {
    const double elapsed =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - start_).count();
    const double rate = elapsed > 0 ? done / elapsed : 0.0;
    bar_.Update(done, total_, rate > 0 ? (total_ - done) / rate : -1.0,
                absl::StrFormat("%d/%d, %.1f frames/s", done, total_, rate));
  }
  void Finish() { bar_.Finish(); }

 private:
  ProgressBar bar_;
  int total_;
  std::chrono::steady_clock::time_point start_ = std::chrono::steady_clock::now();
};

absl::StatusOr<std::vector<Step>> RunLocally(const std::vector<std::string>& frames,
                                             int requested_depth, const std::string& requested_mode,
                                             bool quiet) {
  const std::string model_flag = absl::GetFlag(FLAGS_model);
  absl::StatusOr<std::unique_ptr<core::Registrar>> registrar =
      core::Registrar::Create(RegistrarConfigFromModelFlag(model_flag));
  if (!registrar.ok()) return registrar.status();
  std::vector<Step> steps;
  FrameReader reader(frames);
  absl::StatusOr<core::PointCloud> previous = reader.Next(0);
  if (!previous.ok()) return previous.status();
  std::optional<core::Octree> previous_tree;
  Eigen::Isometry3d motion = Eigen::Isometry3d::Identity();
  // Depth and mode are chosen once, from the first frame, as the server path does for its
  // session: chosen per pair, a sequence whose extent crosses the scene-scale threshold would
  // pair trees of different depths and switch modes mid-way.
  const int depth = ChooseTreeDepth(*previous, *previous, requested_depth);
  const std::string mode =
      ChooseMode(*previous, *previous, requested_mode, model_flag.empty() ? "objects" : model_flag,
                 nullptr, absl::GetFlag(FLAGS_constant_velocity));
  core::BarnesHutTreeOptions tree_options;
  tree_options.max_depth = depth;
  absl::StatusOr<core::RegistrationMode> parsed_mode = core::ParseRegistrationMode(mode);
  if (!parsed_mode.ok()) return parsed_mode.status();
  core::RegistrationOptions options;
  options.mode = *parsed_mode;
  ApplyRegistrationFlags(options);
  const bool constant_velocity = absl::GetFlag(FLAGS_constant_velocity);
  FrameProgress progress(static_cast<int>(frames.size()));
  for (size_t i = 1; i < frames.size(); ++i) {
    absl::StatusOr<core::PointCloud> current = reader.Next(i);
    if (!current.ok()) return current.status();
    if (!previous_tree) {
      absl::StatusOr<core::Octree> tree = core::BuildOctree(*previous, tree_options);
      if (!tree.ok())
        return absl::Status(tree.status().code(),
                            absl::StrCat(frames[i - 1], ": ", tree.status().message()));
      previous_tree = *std::move(tree);
    }
    absl::StatusOr<core::Octree> tree = core::BuildOctree(*current, tree_options);
    if (!tree.ok()) {
      return absl::Status(tree.status().code(),
                          absl::StrCat(frames[i], ": ", tree.status().message()));
    }
    if (constant_velocity) options.initial_T_target_source = motion;
    absl::StatusOr<core::RegistrationResult> result =
        (*registrar)->Register(*tree, *previous_tree, options);
    if (!result.ok()) {
      return absl::Status(result.status().code(),
                          absl::StrCat("frame ", i, ": ", result.status().message()));
    }
    steps.push_back({result->T_target_source, result->valid, result->confidence,
                     result->held_at_initial, result->line_normals_from_planes,
                     result->timings.total_seconds, 0.0});
    if (core::StartsNextFrame(*result)) motion = result->T_target_source;
    previous = *std::move(current);
    previous_tree = *std::move(tree);
    if (!quiet) progress.Update(static_cast<int>(i + 1));
  }
  if (!quiet) progress.Finish();
  return steps;
}

#if RPSR_CLI_HAS_SERVICE
absl::StatusOr<std::vector<Step>> RunOnServer(const std::vector<std::string>& frames,
                                              int requested_depth,
                                              const std::string& requested_mode, bool quiet) {
  absl::StatusOr<ClientOptions> client_options = ClientOptionsFromFlags();
  if (!client_options.ok()) return client_options.status();
  absl::StatusOr<std::unique_ptr<Client>> client = Client::Connect(*client_options);
  if (!client.ok()) return client.status();
  absl::StatusOr<ServerInfo> info = (*client)->GetServerInfo();
  if (!info.ok()) return info.status();
  FrameReader reader(frames);
  absl::StatusOr<core::PointCloud> first = reader.Next(0);
  if (!first.ok()) return first.status();
  SessionOptions session_options;
  session_options.tree_max_depth = ChooseTreeDepth(*first, *first, requested_depth);
  session_options.keep_points_for_reupload = false;
  absl::StatusOr<std::unique_ptr<Session>> session = (*client)->CreateSession(session_options);
  if (!session.ok()) return session.status();
  TrackerOptions tracker_options;
  tracker_options.registration.mode = ChooseMode(*first, *first, requested_mode, info->model_name,
                                                 nullptr, absl::GetFlag(FLAGS_constant_velocity));
  ApplyRegistrationFlags(tracker_options.registration);
  tracker_options.constant_velocity_prior = absl::GetFlag(FLAGS_constant_velocity);
  absl::StatusOr<std::unique_ptr<Tracker>> tracker = (*session)->StartTracker(tracker_options);
  if (!tracker.ok()) return tracker.status();
  std::vector<Step> steps;
  FrameProgress progress(static_cast<int>(frames.size()));
  for (size_t i = 0; i < frames.size(); ++i) {
    absl::StatusOr<core::PointCloud> cloud =
        i == 0 ? absl::StatusOr<core::PointCloud>(*std::move(first)) : reader.Next(i);
    if (!cloud.ok()) return cloud.status();
    absl::StatusOr<TrackedFrame> frame = (*tracker)->AddFrame(cloud->points);
    if (!frame.ok()) {
      return absl::Status(frame.status().code(),
                          absl::StrCat("frame ", i, ": ", frame.status().message()));
    }
    if (i > 0) {
      if (!frame->relative) {
        return absl::InternalError(absl::StrCat("frame ", i, ": the server sent no pose"));
      }
      steps.push_back({frame->relative->T_target_source, frame->relative->valid,
                       frame->relative->confidence, frame->relative->held_at_initial,
                       frame->relative->line_normals_from_planes,
                       frame->relative->timings.registrar_seconds, frame->round_trip_seconds});
    }
    if (!quiet) progress.Update(static_cast<int>(i + 1));
  }
  if (!quiet) progress.Finish();
  if (absl::Status status = (*tracker)->Finish(); !status.ok()) return status;
  return steps;
}
#endif

std::string MetricsJson(const core::KittiOdometryMetrics& metrics) {
  std::string per_length;
  for (const auto& length : metrics.per_length) {
    absl::StrAppendFormat(&per_length,
                          "%s{\"length_m\": %g, \"segments\": %d, \"translation_error_percent\": "
                          "%.6g, \"rotation_error_deg_per_m\": %.6g}",
                          per_length.empty() ? "" : ", ", length.length_m, length.segment_count,
                          length.translation_error_percent, length.rotation_error_deg_per_m);
  }
  // No segment: the means do not exist (null), they are not zero.
  auto number = [&metrics](double value) {
    return metrics.segment_count > 0 ? absl::StrFormat("%.6g", value) : std::string("null");
  };
  return absl::StrFormat(
      "{\"segments\": %d, \"translation_error_percent\": %s, \"rotation_error_deg_per_m\": "
      "%s, \"rotation_error_deg_per_100m\": %s, \"path_length_m\": %.3f, \"per_length\": "
      "[%s]}",
      metrics.segment_count, number(metrics.translation_error_percent),
      number(metrics.rotation_error_deg_per_m), number(100 * metrics.rotation_error_deg_per_m),
      metrics.path_length_m, per_length);
}

}  // namespace

int RunOdometryCommand(const std::vector<std::string>& args) {
  if (args.size() != 1) {
    return Fail(kBadFlags,
                "usage: rpsr odometry SEQUENCE_DIR --output POSES.txt [--server ADDR | --local] "
                "[--max_frames N] [--plot FILE.png] [--segment_lengths 100,...,800] [--json]");
  }
  const std::string output = absl::GetFlag(FLAGS_output);
  if (output.empty()) return Fail(kBadFlags, "--output POSES.txt is required");
  absl::StatusOr<bool> use_server = UseServerFlag();
  if (!use_server.ok()) return Fail(kBadFlags, std::string(use_server.status().message()));
  absl::StatusOr<std::vector<double>> lengths = ParseLengths(absl::GetFlag(FLAGS_segment_lengths));
  if (!lengths.ok()) return Fail(kBadFlags, std::string(lengths.status().message()));
  const std::string requested_mode = ExplicitModeFlag();
  if (!requested_mode.empty() && !core::ParseRegistrationMode(requested_mode).ok()) {
    return Fail(kBadFlags, "--mode must be net, net+refine or refine");
  }
  const fs::path sequence_dir = args[0];
  absl::StatusOr<std::vector<std::string>> frames = ListFrames(sequence_dir);
  if (!frames.ok()) return Fail(kFailure, std::string(frames.status().message()));
  const int max_frames = absl::GetFlag(FLAGS_max_frames);
  if (max_frames < 0) return Fail(kBadFlags, "--max_frames must be >= 0");
  if (max_frames > 0 && static_cast<size_t>(max_frames) < frames->size()) {
    if (max_frames < 2) return Fail(kBadFlags, "--max_frames must be >= 2");
    frames->resize(static_cast<size_t>(max_frames));
  }
  const int frame_count = static_cast<int>(frames->size());
  const bool json = absl::GetFlag(FLAGS_json);

  const auto start = std::chrono::steady_clock::now();
  absl::StatusOr<std::vector<Step>> steps;
  if (*use_server) {
#if RPSR_CLI_HAS_SERVICE
    steps = RunOnServer(*frames, ExplicitTreeDepthFlag(), requested_mode, json);
#else
    return Fail(kBadFlags, "this rpsr was built without the client library (core-only build)");
#endif
  } else {
    steps = RunLocally(*frames, ExplicitTreeDepthFlag(), requested_mode, json);
  }
  if (!steps.ok()) return Fail(kFailure, std::string(steps.status().message()));
  const double seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();

  // LiDAR poses from the steps, then camera 0 poses when Tr is known (KITTI's convention).
  std::vector<Eigen::Isometry3d> T_world_lidar = {Eigen::Isometry3d::Identity()};
  int invalid = 0;
  int held = 0;
  int line_normals = 0;
  double registrar_seconds = 0.0;
  double round_trip_seconds = 0.0;
  for (const Step& step : *steps) {
    T_world_lidar.push_back(T_world_lidar.back() * step.T_previous_current);
    if (!step.valid) ++invalid;
    if (step.held) ++held;
    if (step.line_normals) ++line_normals;
    registrar_seconds += step.registrar_seconds;
    round_trip_seconds += step.round_trip_seconds;
  }
  const GroundTruth truth = ReadGroundTruth(sequence_dir, frame_count);
  const std::vector<Eigen::Isometry3d> poses =
      truth.T_camera_lidar ? core::CameraPosesFromLidarPoses(T_world_lidar, *truth.T_camera_lidar)
                           : T_world_lidar;
  std::error_code error;
  if (fs::path(output).has_parent_path())
    fs::create_directories(fs::path(output).parent_path(), error);
  if (absl::Status status = core::WriteFileBytes(output, core::FormatKittiPoses(poses));
      !status.ok()) {
    return Fail(kFailure, std::string(status.message()));
  }
  std::optional<core::KittiOdometryMetrics> metrics;
  if (!truth.T_world_camera.empty()) {
    core::KittiOdometryMetricsOptions options;
    options.segment_lengths_m = *lengths;
    absl::StatusOr<core::KittiOdometryMetrics> computed =
        core::ComputeKittiOdometryMetrics(poses, truth.T_world_camera, options);
    if (!computed.ok()) return Fail(kFailure, std::string(computed.status().message()));
    metrics = *computed;
  }
  std::string plot = absl::GetFlag(FLAGS_plot);
  if (plot.empty()) plot = fs::path(output).replace_extension(".png").string();
  if (plot != "none") {
    // Camera 0 poses: x right, z forward (seen from above: x, z); LiDAR poses: x, y.
    const std::pair<int, int> axes =
        truth.T_camera_lidar ? std::pair<int, int>{0, 2} : std::pair<int, int>{0, 1};
    if (absl::Status status = WriteTrajectoryPicture(plot, poses, truth.T_world_camera, axes);
        !status.ok()) {
      return Fail(kFailure, std::string(status.message()));
    }
  }

  const int pairs = frame_count - 1;
  if (json) {
    std::printf(
        "{\"sequence\": %s, \"where\": %s, \"frames\": %d, \"pairs\": %d, \"invalid_pairs\": %d, "
        "\"held_pairs\": %d, \"line_normals_from_planes_pairs\": %d, "
        "\"seconds\": %.3f, \"ms_per_pair\": %.3f, \"registrar_ms_per_pair\": %.3f, "
        "\"round_trip_ms_per_frame\": %.3f, \"poses\": %s, \"pose_frame\": %s, \"plot\": "
        "%s, \"metrics\": %s}\n",
        JsonString(sequence_dir.string()).c_str(),
        JsonString(*use_server ? absl::GetFlag(FLAGS_server) : "local").c_str(), frame_count, pairs,
        invalid, held, line_normals, seconds, 1e3 * seconds / pairs,
        1e3 * registrar_seconds / pairs, 1e3 * round_trip_seconds / pairs,
        JsonString(output).c_str(), JsonString(truth.T_camera_lidar ? "camera0" : "lidar").c_str(),
        JsonString(plot == "none" ? "" : plot).c_str(),
        metrics ? MetricsJson(*metrics).c_str() : "null");
    return 0;
  }
  std::printf("sequence %s: %d frames, %s\n", sequence_dir.string().c_str(), frame_count,
              *use_server ? ("server " + absl::GetFlag(FLAGS_server)).c_str() : "local");
  std::printf(
      "registered %d pairs in %.1f s (%.1f ms a pair, of which the registrar %.1f ms%s), "
      "%d not valid%s\n",
      pairs, seconds, 1e3 * seconds / pairs, 1e3 * registrar_seconds / pairs,
      *use_server
          ? absl::StrFormat("; %.1f ms a frame's round trip", 1e3 * round_trip_seconds / pairs)
                .c_str()
          : "",
      invalid,
      held > 0
          ? absl::StrFormat(" (%d degenerate, held at the previous motion along it)", held).c_str()
          : "");
  std::printf(
      "line-shaped nodes took their planes' normals in %d of %d pairs%s\n", line_normals, pairs,
      ExplicitLineNormalsFlag().has_value()
          ? " (as --line_normals_from_planes asked)"
          : " (chosen per pair from the scans; --line_normals_from_planes[=false] overrides)");
  // Many degenerate frames on a street usually mean ring arcs read as planes across the rings
  // (tests/bench/notes/odometry-notes.md, *Sparser scanners drift more*): say what helps.
  if (line_normals < pairs && pairs > 0 && 5 * invalid >= pairs) {
    std::printf(
        "hint: %d of %d pairs not valid; for a 16- or 32-beam scanner, or an open road, try "
        "--line_normals_from_planes\n",
        invalid, pairs);
  }
  std::printf("poses (%s, KITTI format) written to %s\n",
              truth.T_camera_lidar ? "camera 0 frame" : "LiDAR frame", output.c_str());
  if (metrics) {
    if (metrics->segment_count == 0) {
      std::printf(
          "KITTI metrics: no segment (the ground truth covers %.1f m, less than the "
          "shortest length %g m; see --segment_lengths)\n",
          metrics->path_length_m, lengths->front());
    } else {
      std::printf(
          "KITTI metrics over %d segments (%.1f m driven): translation %.3f %%, rotation "
          "%.5f deg/m (%.3f deg/100 m)\n",
          metrics->segment_count, metrics->path_length_m, metrics->translation_error_percent,
          metrics->rotation_error_deg_per_m, 100 * metrics->rotation_error_deg_per_m);
      for (const auto& length : metrics->per_length) {
        if (length.segment_count == 0) continue;
        std::printf("  %5g m: %3d segments, translation %.3f %%, rotation %.5f deg/m\n",
                    length.length_m, length.segment_count, length.translation_error_percent,
                    length.rotation_error_deg_per_m);
      }
    }
  } else {
    std::printf("no ground truth found (poses.txt of a <root>/sequences/NN folder): no metrics\n");
  }
  if (plot != "none") {
    std::printf("trajectory picture written to %s (black: ground truth, red: estimate)\n",
                plot.c_str());
  }
  return 0;
}

}  // namespace rpsr::client
