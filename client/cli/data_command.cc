// rpsr data: writes data sets to disk.
//   rpsr data objects --output DIR     normalised object clouds and objects.csv
//   rpsr data lidar --output DIR       simulated LiDAR sequences in the KITTI odometry layout
//   rpsr data pairs --protocol objects --output DIR
//   rpsr data pairs --protocol lidar --kitti ROOT --sequence NN --output DIR
//                                      registration pairs: clouds/ and manifest.csv
//                                      (core/data/pair_manifest.h: source,target,gt)
// Exit codes: 0 done, 1 reading or writing failed, 2 bad flags.
#include <algorithm>
#include <atomic>
#include <chrono>
#include <condition_variable>
#include <cstdio>
#include <filesystem>
#include <functional>
#include <mutex>
#include <optional>
#include <set>
#include <string>
#include <system_error>
#include <thread>
#include <vector>

#include "absl/flags/flag.h"
#include "absl/strings/ascii.h"
#include "absl/strings/numbers.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "absl/strings/str_join.h"
#include "absl/strings/str_split.h"
#include "client/cli/cli_progress.h"
#include "client/cli/shared_flags.h"
#include "client/cli/subcommands.h"
#include "core/data/kitti_odometry.h"
#include "core/data/lidar_pairs.h"
#include "core/data/object_pairs.h"
#include "core/data/pair_manifest.h"
#include "core/data/simulated_kitti.h"
#include "core/io/mesh_sampling.h"
#include "core/io/point_cloud_io.h"
#include "core/synth/mesh_folder.h"
#include "core/synth/seeded_random.h"
#include "core/synth/shape_families.h"

// --output, --protocol, --seed and --num_points are shared with other subcommands
// (shared_flags.cc).
ABSL_FLAG(std::string, format, "",
          "cloud files: ply, pcd, xyz or bin (KITTI float32 x y z r); default ply for objects, "
          "bin for LiDAR pairs");
ABSL_FLAG(std::string, mesh_folder, "",
          "objects and object pairs: sample the .off/.ply meshes of this folder (searched "
          "recursively, sorted by path; pair i uses mesh i modulo their number) instead of the "
          "procedural families; --split is then ignored");
ABSL_FLAG(bool, same_points, false,
          "pairs --protocol objects: the target is the clean source mapped by the ground truth, "
          "point for point (default: independent samples of the surface; with --disturbance "
          "partial the target is then cropped too)");
ABSL_FLAG(double, max_angle_deg, 45.0,
          "pairs --protocol objects: each Euler angle uniform in (0, this] degrees");
ABSL_FLAG(double, max_translation, 0.5,
          "pairs --protocol objects: each translation component uniform in [-this, this]");
ABSL_FLAG(int, sequences, 1, "lidar: sequences to simulate, written as sequences/00, 01, ...");
ABSL_FLAG(int, frames, 300, "lidar: frames per sequence (10 scans a second)");
ABSL_FLAG(std::string, style, "urban",
          "lidar: street style urban, suburban, open or parking; a comma-separated list is "
          "cycled through the sequences");
ABSL_FLAG(int, azimuth_steps, 2000,
          "lidar: azimuths per revolution (HDL-64E at 10 Hz: 2000; fewer thin the scans, e.g. "
          "500 for small sample data); given, it overrides --sensor's");
ABSL_FLAG(std::string, sensor, "hdl64",
          "lidar: the scanner simulated: hdl64 (64 beams, +2 to -24.8 deg, 2000 azimuths: "
          "KITTI's), hdl32 (32 beams, +10.67 to -30.67 deg, 2250) or vlp16 (16 beams, +-15 deg, "
          "1800), all at 10 Hz");
ABSL_FLAG(std::string, kitti, "",
          "pairs --protocol lidar: root of a KITTI odometry layout (holding sequences/NN/), "
          "real or written by `rpsr data lidar`");
ABSL_FLAG(std::string, sequence, "",
          "pairs --protocol lidar: sequence number(s) under --kitti, comma-separated (e.g. 08 "
          "or 00,01)");
ABSL_FLAG(std::string, ground, "keep",
          "pairs --protocol lidar: keep (the paper's K2-w) or remove (K1-w/o; needs "
          "SemanticKITTI labels)");
ABSL_FLAG(int, max_pairs, 0,
          "pairs --protocol lidar: at most this many pairs per sequence, drawn with --seed "
          "(0: every pair of the split)");

namespace rpsr::client {
namespace {

namespace fs = std::filesystem;

constexpr int kBadFlags = 2;
constexpr int kIoFailure = 1;

int Fail(int code, const std::string& message) {
  std::fprintf(stderr, "rpsr data: %s\n", message.c_str());
  return code;
}

void PrintDataUsage() {
  std::fprintf(stderr,
               "usage:\n"
               "  rpsr data objects --output DIR [--count N --split m1|seen|unseen "
               "--num_points 1024 --format ply --mesh_folder F --seed S]\n"
               "  rpsr data lidar --output DIR [--sequences 1 --frames 300 "
               "--style urban|suburban|open|parking --seed S]\n"
               "  rpsr data pairs --protocol objects --output DIR [--count N --split ... "
               "--disturbance none|noise|outliers|crop|jitter|partial --level 0..4 --same_points "
               "--format ply --seed S]\n"
               "  rpsr data pairs --protocol lidar --kitti ROOT --sequence NN --output DIR "
               "[--ground keep|remove --split train|test|validation --max_pairs N --format bin]\n"
               "'rpsr data --help' describes every flag.\n");
}

// Progress with an ETA from the average rate so far.
class Progress {
 public:
  Progress(std::string label, double total) : bar_(std::move(label)), total_(total) {}
  void Update(double done, const std::string& detail) {
    const double elapsed =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - start_).count();
    const double remaining = done > 0 ? elapsed / done * (total_ - done) : -1.0;
    bar_.Update(done, total_, remaining, detail);
  }
  void Finish() { bar_.Finish(); }

 private:
  ProgressBar bar_;
  double total_;
  std::chrono::steady_clock::time_point start_ = std::chrono::steady_clock::now();
};

// The --output folder, created. Empty (after printing the error) on failure.
std::optional<std::string> MakeOutputFolder(const std::string& subfolder, int* exit_code) {
  const std::string output = absl::GetFlag(FLAGS_output);
  if (output.empty()) {
    *exit_code = Fail(kBadFlags, "--output FOLDER is required");
    return std::nullopt;
  }
  std::error_code error;
  fs::create_directories(fs::path(output) / subfolder, error);
  if (error) {
    *exit_code = Fail(
        kIoFailure, absl::StrCat("cannot create ", output, "/", subfolder, ": ", error.message()));
    return std::nullopt;
  }
  return output;
}

// "" or one of ply pcd xyz bin; empty optional for anything else.
std::optional<std::string> CloudExtension(const std::string& default_format) {
  std::string format = absl::AsciiStrToLower(absl::GetFlag(FLAGS_format));
  if (format.empty()) format = default_format;
  if (format == "ply" || format == "pcd" || format == "xyz" || format == "bin") {
    return "." + format;
  }
  return std::nullopt;
}

int WriteCloud(const std::string& path, const core::PointCloud& cloud) {
  if (absl::Status status = core::WritePointCloud(path, cloud); !status.ok()) {
    return Fail(kIoFailure, absl::StrCat("cannot write ", path, ": ", status.message()));
  }
  return 0;
}

int WriteText(const std::string& path, const std::string& text) {
  std::FILE* file = std::fopen(path.c_str(), "wb");
  const bool ok = file != nullptr && std::fwrite(text.data(), 1, text.size(), file) == text.size();
  if (file != nullptr && std::fclose(file) != 0) return Fail(kIoFailure, "cannot write " + path);
  return ok ? 0 : Fail(kIoFailure, "cannot write " + path);
}

const char* SymmetryName(core::RotationalSymmetry symmetry) {
  switch (symmetry) {
    case core::RotationalSymmetry::kNone:
      return "none";
    case core::RotationalSymmetry::kDiscrete:
      return "discrete";
    case core::RotationalSymmetry::kContinuous:
      return "continuous";
  }
  return "unknown";
}

// --- objects and object pairs -----------------------------------------------------------------

// The object options both object modes share, from the flags. Returns an exit code != 0 on error.
struct ObjectSource {
  core::PairOptions options;
  std::string split_name;
  std::vector<std::string> meshes;  // empty: procedural families
  int count = 0;
  uint64_t seed = 1;
  std::string extension;
};

int ReadObjectSource(ObjectSource& source) {
  source.count = absl::GetFlag(FLAGS_count);
  if (source.count < 1) return Fail(kBadFlags, "--count must be at least 1");
  const int num_points = absl::GetFlag(FLAGS_num_points);
  if (num_points < 1) return Fail(kBadFlags, "--num_points must be at least 1");
  source.options.num_points = static_cast<size_t>(num_points);
  source.seed = absl::GetFlag(FLAGS_seed);
  source.split_name = absl::AsciiStrToLower(absl::GetFlag(FLAGS_split));
  std::optional<core::ObjectSplit> split =
      ParseObjectSplitFlag(source.split_name, core::ObjectSplit::kM1All);
  if (!split) {
    return Fail(kBadFlags, absl::StrCat("unknown --split '", source.split_name,
                                        "' for objects: use m1, seen or unseen"));
  }
  source.options.split = *split;
  if (source.split_name.empty()) source.split_name = "m1";
  std::optional<std::string> extension = CloudExtension("ply");
  if (!extension) {
    return Fail(kBadFlags, absl::StrCat("unknown --format '", absl::GetFlag(FLAGS_format),
                                        "': use ply, pcd, xyz or bin"));
  }
  source.extension = *extension;
  const std::string mesh_folder = absl::GetFlag(FLAGS_mesh_folder);
  if (!mesh_folder.empty()) {
    absl::StatusOr<std::vector<std::string>> meshes =
        core::ListMeshFiles(mesh_folder, /*recursive=*/true);
    if (!meshes.ok()) {
      return Fail(kBadFlags, absl::StrCat("--mesh_folder: ", meshes.status().message()));
    }
    if (meshes->empty()) {
      return Fail(kBadFlags, absl::StrCat("--mesh_folder ", mesh_folder,
                                          " holds no .off or .ply mesh (subfolders included)"));
    }
    source.meshes = *std::move(meshes);
  }
  return 0;
}

std::string IndexName(int index) { return absl::StrFormat("%06d", index); }

// A mesh's name in the listings: its path inside --mesh_folder (ModelNet: class/split/file.off).
std::string MeshName(const std::string& mesh_path) {
  return fs::path(mesh_path)
      .lexically_relative(fs::path(absl::GetFlag(FLAGS_mesh_folder)))
      .generic_string();
}

int RunObjects() {
  ObjectSource source;
  if (int code = ReadObjectSource(source); code != 0) return code;
  int exit_code = 0;
  std::optional<std::string> output = MakeOutputFolder("clouds", &exit_code);
  if (!output) return exit_code;
  // With a mesh folder, one cloud per mesh, at most --count.
  const int count = source.meshes.empty()
                        ? source.count
                        : std::min(source.count, static_cast<int>(source.meshes.size()));

  std::string listing = "cloud,family,family_index,split,rotational_symmetry,object_seed\n";
  Progress progress("objects", count);
  for (int i = 0; i < count; ++i) {
    const uint64_t seed = core::DeriveSeed(source.seed, static_cast<uint64_t>(i));
    const std::string relative = "clouds/" + IndexName(i) + source.extension;
    core::PointCloud cloud;
    if (source.meshes.empty()) {
      // The clean source of an undisturbed pair: an object of the split, normalised into
      // [-1, 1]^3 and sampled (object_pairs.h draws the family and the object).
      core::PairOptions options = source.options;
      options.same_points = true;
      absl::StatusOr<core::ObjectPair> pair = core::MakeObjectPair(options, seed);
      if (!pair.ok()) return Fail(kIoFailure, std::string(pair.status().message()));
      const core::ShapeFamily& family = core::ShapeFamilies()[pair->family_index];
      absl::StrAppend(&listing, relative, ",", family.name, ",", pair->family_index, ",",
                      family.split == core::FamilySplit::kSeen ? "seen" : "unseen", ",",
                      SymmetryName(family.symmetry), ",", pair->object_seed, "\n");
      cloud = std::move(pair->source);
    } else {
      const std::string& mesh_path = source.meshes[i];
      absl::StatusOr<core::TriangleMesh> mesh = core::ReadNormalizedMesh(mesh_path);
      if (!mesh.ok()) return Fail(kIoFailure, std::string(mesh.status().message()));
      absl::StatusOr<core::PointCloud> sampled =
          core::SampleSurface(*mesh, source.options.num_points, seed);
      if (!sampled.ok()) {
        return Fail(kIoFailure, absl::StrCat(mesh_path, ": ", sampled.status().message()));
      }
      absl::StrAppend(&listing, relative, ",", MeshName(mesh_path), ",-1,,unknown,", "0\n");
      cloud = *std::move(sampled);
    }
    if (int code = WriteCloud((fs::path(*output) / relative).string(), cloud); code != 0) {
      return code;
    }
    progress.Update(i + 1, absl::StrCat(i + 1, "/", count));
  }
  progress.Finish();
  const std::string listing_path = (fs::path(*output) / "objects.csv").string();
  if (int code = WriteText(listing_path, listing); code != 0) return code;
  std::fprintf(stderr, "rpsr data: wrote %d object clouds (%zu points each) and %s\n", count,
               source.options.num_points, listing_path.c_str());
  return 0;
}

int RunObjectPairs() {
  ObjectSource source;
  if (int code = ReadObjectSource(source); code != 0) return code;
  const std::string disturbance = absl::AsciiStrToLower(absl::GetFlag(FLAGS_disturbance));
  std::optional<core::DisturbanceKind> kind = ParseDisturbanceFlag(disturbance);
  if (!kind) {
    return Fail(kBadFlags, absl::StrCat("unknown --disturbance '", disturbance,
                                        "': use none, noise, outliers, crop, jitter or partial"));
  }
  source.options.disturbance = *kind;
  source.options.disturbance_level = absl::GetFlag(FLAGS_level);
  source.options.same_points = absl::GetFlag(FLAGS_same_points);
  source.options.max_angle_deg = absl::GetFlag(FLAGS_max_angle_deg);
  source.options.max_translation = absl::GetFlag(FLAGS_max_translation);
  if (source.options.disturbance_level < 0 || source.options.disturbance_level > 4) {
    return Fail(kBadFlags, "--level must be in 0..4");
  }
  if (absl::Status valid = core::ValidatePairOptions(source.options); !valid.ok()) {
    return Fail(kBadFlags, absl::StrCat("bad pair flags: ", valid.message(),
                                        " (see --max_angle_deg, --max_translation)"));
  }
  int exit_code = 0;
  std::optional<std::string> output = MakeOutputFolder("clouds", &exit_code);
  if (!output) return exit_code;

  std::vector<core::ManifestRow> rows;
  std::string details =
      "pair,family,rotational_symmetry,disturbance,magnitude,source_points,target_points,"
      "angle_x_deg,angle_y_deg,angle_z_deg\n";
  Progress progress("pairs", source.count);
  for (int i = 0; i < source.count; ++i) {
    const uint64_t seed = core::DeriveSeed(source.seed, static_cast<uint64_t>(i));
    absl::StatusOr<core::ObjectPair> pair;
    std::string family_name;
    std::string symmetry = "unknown";
    if (source.meshes.empty()) {
      pair = core::MakeObjectPair(source.options, seed);
      if (pair.ok()) {
        const core::ShapeFamily& family = core::ShapeFamilies()[pair->family_index];
        family_name = family.name;
        symmetry = SymmetryName(family.symmetry);
      }
    } else {
      const std::string& mesh_path = source.meshes[i % source.meshes.size()];
      absl::StatusOr<core::TriangleMesh> mesh = core::ReadNormalizedMesh(mesh_path);
      if (!mesh.ok()) return Fail(kIoFailure, std::string(mesh.status().message()));
      pair = core::MakeObjectPairFromMesh(*mesh, source.options, seed);
      if (!pair.ok()) {
        return Fail(kIoFailure, absl::StrCat(mesh_path, ": ", pair.status().message()));
      }
      family_name = MeshName(mesh_path);
    }
    if (!pair.ok()) return Fail(kIoFailure, std::string(pair.status().message()));

    core::ManifestRow row;
    row.source =
        (fs::path(*output) / "clouds" / (IndexName(i) + "_source" + source.extension)).string();
    row.target =
        (fs::path(*output) / "clouds" / (IndexName(i) + "_target" + source.extension)).string();
    row.T_target_source = pair->T_target_source;
    if (int code = WriteCloud(row.source, pair->source); code != 0) return code;
    if (int code = WriteCloud(row.target, pair->target); code != 0) return code;
    constexpr double kDegrees = 180.0 / M_PI;
    absl::StrAppend(&details, i, ",", family_name, ",", symmetry, ",",
                    core::DisturbanceName(pair->disturbance.kind), ",", pair->disturbance.magnitude,
                    ",", pair->source.size(), ",", pair->target.size(), ",",
                    pair->euler_angles_rad.x() * kDegrees, ",",
                    pair->euler_angles_rad.y() * kDegrees, ",",
                    pair->euler_angles_rad.z() * kDegrees, "\n");
    rows.push_back(std::move(row));
    progress.Update(i + 1, absl::StrCat(i + 1, "/", source.count));
  }
  progress.Finish();
  const std::string manifest = (fs::path(*output) / "manifest.csv").string();
  if (absl::Status status = core::WritePairManifest(manifest, rows); !status.ok()) {
    return Fail(kIoFailure, std::string(status.message()));
  }
  if (int code = WriteText((fs::path(*output) / "pairs.csv").string(), details); code != 0) {
    return code;
  }
  const std::string disturbance_text =
      *kind == core::DisturbanceKind::kNone
          ? "no disturbance"
          : absl::StrCat(disturbance, " level ", source.options.disturbance_level);
  std::fprintf(stderr,
               "rpsr data: wrote %d object pairs (%s, %s%s) and %s (pairs.csv: family, "
               "disturbance and angles of each)\n",
               source.count,
               source.meshes.empty() ? ("split " + source.split_name).c_str() : "mesh folder",
               disturbance_text.c_str(), source.options.same_points ? ", same points" : "",
               manifest.c_str());
  return 0;
}

// --- LiDAR ------------------------------------------------------------------------------------

std::optional<core::StreetStyle> ParseStyle(absl::string_view name) {
  if (name == "urban") return core::StreetStyle::kUrbanCanyon;
  if (name == "suburban") return core::StreetStyle::kSuburban;
  if (name == "open") return core::StreetStyle::kOpenRoad;
  if (name == "parking") return core::StreetStyle::kParkingLot;
  return std::nullopt;
}

// Counts velodyne/*.bin of a sequence being written, so that a progress bar can follow the
// simulator (which writes frames from its worker threads and reports nothing until done).
class FrameFileWatcher {
 public:
  FrameFileWatcher(std::string velodyne_dir, std::function<void(int)> on_count)
      : thread_([this, dir = std::move(velodyne_dir), on_count = std::move(on_count)] {
          std::unique_lock<std::mutex> lock(mutex_);
          while (!cv_.wait_for(lock, std::chrono::milliseconds(500), [this] { return stop_; })) {
            std::error_code error;
            int count = 0;
            for (fs::directory_iterator it(dir, error), end; !error && it != end;
                 it.increment(error)) {
              ++count;
            }
            on_count(count);
          }
        }) {}
  ~FrameFileWatcher() {
    {
      std::lock_guard<std::mutex> lock(mutex_);
      stop_ = true;
    }
    cv_.notify_all();
    thread_.join();
  }

 private:
  std::mutex mutex_;
  std::condition_variable cv_;
  bool stop_ = false;
  std::thread thread_;  // last: starts after the members it uses
};

// --sensor's beams, elevations and azimuths (datasheet figures at 10 Hz), --azimuth_steps when
// given on the command line.
std::optional<core::LidarSensorOptions> SensorFromFlags() {
  std::optional<core::LidarSensorOptions> sensor =
      core::LidarSensorPreset(absl::AsciiStrToLower(absl::GetFlag(FLAGS_sensor)));
  if (sensor && GivenOnCommandLine("azimuth_steps")) {
    sensor->azimuth_steps = absl::GetFlag(FLAGS_azimuth_steps);
  }
  return sensor;
}

int RunLidar() {
  const int sequences = absl::GetFlag(FLAGS_sequences);
  const int frames = absl::GetFlag(FLAGS_frames);
  if (sequences < 1 || sequences > 100) return Fail(kBadFlags, "--sequences must be in 1..100");
  if (frames < 1 || frames > 100000) return Fail(kBadFlags, "--frames must be in 1..100000");
  std::vector<core::StreetStyle> styles;
  for (absl::string_view name : absl::StrSplit(absl::GetFlag(FLAGS_style), ',')) {
    std::optional<core::StreetStyle> style =
        ParseStyle(absl::StripAsciiWhitespace(absl::AsciiStrToLower(name)));
    if (!style) {
      return Fail(kBadFlags, absl::StrCat("unknown --style '", name,
                                          "': use urban, suburban, open or parking"));
    }
    styles.push_back(*style);
  }
  const std::optional<core::LidarSensorOptions> sensor = SensorFromFlags();
  if (!sensor) {
    return Fail(kBadFlags, absl::StrCat("unknown --sensor '", absl::GetFlag(FLAGS_sensor),
                                        "': use hdl64, hdl32 or vlp16"));
  }
  int exit_code = 0;
  std::optional<std::string> output = MakeOutputFolder("sequences", &exit_code);
  if (!output) return exit_code;
  const uint64_t seed = absl::GetFlag(FLAGS_seed);

  Progress progress("lidar", static_cast<double>(sequences) * frames);
  std::mutex progress_mutex;
  for (int s = 0; s < sequences; ++s) {
    core::LidarSequenceOptions options;
    options.style = styles[s % styles.size()];
    options.frame_count = frames;
    options.seed = core::DeriveSeed(seed, static_cast<uint64_t>(s));
    options.sensor = *sensor;
    options.thread_count = std::clamp(static_cast<int>(std::thread::hardware_concurrency()), 1, 16);
    absl::StatusOr<core::SimulatedKittiSummary> summary;
    {
      const std::string detail = absl::StrFormat("sequence %02d/%02d", s, sequences - 1);
      FrameFileWatcher watcher(
          core::KittiSequenceDirectory(*output, s) + "/velodyne", [&](int written) {
            std::lock_guard<std::mutex> lock(progress_mutex);
            progress.Update(static_cast<double>(s) * frames + std::min(written, frames), detail);
          });
      summary = core::WriteSimulatedKittiSequence(*output, s, options);
    }
    if (!summary.ok()) {
      progress.Finish();
      return Fail(kIoFailure, absl::StrCat("sequence ", s, ": ", summary.status().message()));
    }
    progress.Update(
        static_cast<double>(s + 1) * frames,
        absl::StrFormat("sequence %02d: %d scans, %zu..%zu points", s, summary->frame_count,
                        summary->min_points_per_scan, summary->max_points_per_scan));
  }
  progress.Finish();
  std::fprintf(stderr,
               "rpsr data: wrote %d simulated sequence(s) of %d frames under %s/sequences "
               "(make pairs with: rpsr data pairs --protocol lidar --kitti %s --sequence 00 "
               "--output DIR)\n",
               sequences, frames, output->c_str(), output->c_str());
  return 0;
}

// The names of the folders in <root>/sequences, sorted, for error messages.
std::string SequenceFolders(const std::string& root) {
  std::vector<std::string> names;
  std::error_code error;
  for (fs::directory_iterator it(fs::path(root) / "sequences", error), end; !error && it != end;
       it.increment(error)) {
    if (it->is_directory(error)) names.push_back(it->path().filename().string());
  }
  std::sort(names.begin(), names.end());
  return names.empty() ? "none" : absl::StrJoin(names, " ");
}

int RunLidarPairs() {
  const std::string root = absl::GetFlag(FLAGS_kitti);
  if (root.empty())
    return Fail(kBadFlags, "--kitti ROOT (the folder holding sequences/) is required");
  std::error_code error;
  if (!fs::is_directory(fs::path(root) / "sequences", error)) {
    return Fail(kBadFlags, absl::StrCat("--kitti ", root,
                                        " has no sequences/ folder: name the root of a KITTI "
                                        "odometry layout (e.g. one written by `rpsr data lidar`)"));
  }
  std::vector<int> sequence_numbers;
  for (absl::string_view text :
       absl::StrSplit(absl::GetFlag(FLAGS_sequence), ',', absl::SkipWhitespace())) {
    int number = 0;
    if (!absl::SimpleAtoi(absl::StripAsciiWhitespace(text), &number) || number < 0) {
      return Fail(kBadFlags,
                  absl::StrCat("bad --sequence '", text, "': use numbers like 08 or 00,01"));
    }
    sequence_numbers.push_back(number);
  }
  if (sequence_numbers.empty()) return Fail(kBadFlags, "--sequence NN is required (e.g. 00)");
  const std::string ground_name = absl::AsciiStrToLower(absl::GetFlag(FLAGS_ground));
  core::GroundHandling ground;
  if (ground_name == "keep") {
    ground = core::GroundHandling::kKeep;
  } else if (ground_name == "remove") {
    ground = core::GroundHandling::kRemove;
  } else {
    return Fail(kBadFlags,
                absl::StrCat("unknown --ground '", ground_name, "': use keep or remove"));
  }
  std::string split_name = absl::AsciiStrToLower(absl::GetFlag(FLAGS_split));
  if (split_name.empty()) split_name = "test";
  core::LidarSplit split;
  if (split_name == "train") {
    split = core::LidarSplit::kTrain;
  } else if (split_name == "test") {
    split = core::LidarSplit::kTest;
  } else if (split_name == "validation") {
    split = core::LidarSplit::kValidation;
  } else {
    return Fail(kBadFlags, absl::StrCat("unknown --split '", split_name,
                                        "' for LiDAR pairs: use train, test or validation"));
  }
  const int max_pairs = absl::GetFlag(FLAGS_max_pairs);
  if (max_pairs < 0) return Fail(kBadFlags, "--max_pairs must be >= 0 (0: all)");
  std::optional<std::string> extension = CloudExtension("bin");
  if (!extension) {
    return Fail(kBadFlags, absl::StrCat("unknown --format '", absl::GetFlag(FLAGS_format),
                                        "': use bin, ply, pcd or xyz"));
  }
  core::LidarPairOptions pair_options;
  pair_options.max_pairs = static_cast<size_t>(max_pairs);
  pair_options.seed = absl::GetFlag(FLAGS_seed);

  // Open every sequence and select its pairs before writing anything.
  std::vector<core::KittiOdometrySequence> opened;
  std::vector<std::vector<core::LidarPairIndex>> selected;
  size_t total = 0;
  for (int number : sequence_numbers) {
    absl::StatusOr<core::KittiOdometrySequence> sequence =
        core::KittiOdometrySequence::Open(root, number);
    if (!sequence.ok()) {
      return Fail(kIoFailure, absl::StrFormat("cannot open sequence %02d: %s (sequences under %s: "
                                              "%s)",
                                              number, sequence.status().message(), root,
                                              SequenceFolders(root)));
    }
    if (ground == core::GroundHandling::kRemove && !sequence->has_labels()) {
      return Fail(kBadFlags,
                  absl::StrCat("--ground remove needs SemanticKITTI labels, and ",
                               sequence->directory(), " has no labels/ folder: use --ground keep"));
    }
    absl::StatusOr<std::vector<core::LidarPairIndex>> pairs =
        core::SelectLidarPairs(number, sequence->frame_count(), split, pair_options);
    if (!pairs.ok()) return Fail(kBadFlags, std::string(pairs.status().message()));
    if (pairs->empty()) {
      const core::FrameRange range =
          core::SplitFrameRange(sequence->frame_count(), split, pair_options);
      std::fprintf(
          stderr,
          "rpsr data: warning: the %s block of sequence %02d (frames %d..%d of %d) holds "
          "no pair i, i+%d%s\n",
          split_name.c_str(), number, range.begin, range.end - 1, sequence->frame_count(),
          pair_options.frame_offset,
          split == core::LidarSplit::kTrain
              ? ""
              : absl::StrFormat(" after its %d-frame gap", pair_options.split_gap_frames).c_str());
    }
    total += pairs->size();
    opened.push_back(*std::move(sequence));
    selected.push_back(*std::move(pairs));
  }
  if (total == 0) {
    return Fail(kBadFlags, absl::StrCat("no pairs to write: the ", split_name,
                                        " split is too short; use a longer sequence or another "
                                        "--split (train takes the first 70% of the frames)"));
  }
  int exit_code = 0;
  std::optional<std::string> output = MakeOutputFolder("clouds", &exit_code);
  if (!output) return exit_code;

  std::vector<core::ManifestRow> rows;
  std::set<std::string> written;  // a frame is the target of one pair and the source of another
  Progress progress("pairs", static_cast<double>(total));
  for (size_t s = 0; s < opened.size(); ++s) {
    for (const core::LidarPairIndex& index : selected[s]) {
      absl::StatusOr<core::LidarPair> pair = core::LoadLidarPair(opened[s], index, ground);
      if (!pair.ok()) {
        progress.Finish();
        return Fail(kIoFailure, absl::StrFormat("sequence %02d frames %d, %d: %s", index.sequence,
                                                index.source_frame, index.target_frame,
                                                pair.status().message()));
      }
      const auto frame_path = [&](int frame) {
        return (fs::path(*output) / "clouds" /
                absl::StrFormat("%02d_%06d%s", index.sequence, frame, *extension))
            .string();
      };
      core::ManifestRow row{frame_path(index.source_frame), frame_path(index.target_frame),
                            pair->T_target_source};
      for (const auto& [path, cloud] :
           {std::pair{&row.source, &pair->source}, std::pair{&row.target, &pair->target}}) {
        if (!written.insert(*path).second) continue;
        if (int code = WriteCloud(*path, *cloud); code != 0) return code;
      }
      rows.push_back(std::move(row));
      progress.Update(
          static_cast<double>(rows.size()),
          absl::StrFormat("sequence %02d frame %d", index.sequence, index.source_frame));
    }
  }
  progress.Finish();
  const std::string manifest = (fs::path(*output) / "manifest.csv").string();
  if (absl::Status status = core::WritePairManifest(manifest, rows); !status.ok()) {
    return Fail(kIoFailure, std::string(status.message()));
  }
  std::fprintf(stderr, "rpsr data: wrote %zu LiDAR pairs (%s split, ground %s: %s) and %s\n",
               rows.size(), split_name.c_str(), ground_name.c_str(),
               ground == core::GroundHandling::kKeep ? "K2-w" : "K1-w/o", manifest.c_str());
  return 0;
}

}  // namespace

int RunDataCommand(const std::vector<std::string>& args) {
  if (args.size() != 1) {
    if (args.size() > 1) {
      std::fprintf(stderr, "rpsr data: one mode expected, got %zu arguments (%s)\n", args.size(),
                   absl::StrJoin(args, " ").c_str());
    }
    PrintDataUsage();
    return kBadFlags;
  }
  const std::string& mode = args[0];
  if (mode == "objects") return RunObjects();
  if (mode == "lidar") return RunLidar();
  if (mode == "pairs") {
    const std::string protocol = absl::GetFlag(FLAGS_protocol);
    if (protocol == "objects") return RunObjectPairs();
    if (protocol == "lidar") return RunLidarPairs();
    return Fail(kBadFlags,
                absl::StrCat("unknown --protocol '", protocol, "': use objects or lidar"));
  }
  std::fprintf(stderr, "rpsr data: unknown mode '%s'\n", mode.c_str());
  PrintDataUsage();
  return kBadFlags;
}

}  // namespace rpsr::client
