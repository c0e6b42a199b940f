// rpsr eval: registers pairs with the Registrar (core/registrar: network, refinement on the trees,
// confidence) and reports the paper's errors (Sec. 4): rotation angle and translation distance,
// RMSE / MAE / median, recall at thresholds, time.
// Pairs come from a manifest (`rpsr data pairs ...`) or from the object protocol directly,
// where --study runs the paper's ModelNet study (clean + four disturbances x five levels).
#include <cerrno>
#include <chrono>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <optional>
#include <string>
#include <vector>

#include "absl/flags/flag.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "absl/strings/str_join.h"
#include "client/cli/cli_progress.h"
#include "client/cli/shared_flags.h"
#include "client/cli/subcommands.h"
#include "core/data/object_pairs.h"
#include "core/data/pair_manifest.h"
#include "core/data/registration_metrics.h"
#include "core/data/transform_convention.h"
#include "core/io/point_cloud_io.h"
#include "core/net/rpsr_net.h"
#include "core/registrar/embedded_models.h"
#include "core/registrar/registrar.h"
#include "core/synth/seeded_random.h"

ABSL_FLAG(std::string, manifest, "",
          "evaluate the pairs of this manifest (source,target,gt) instead of generating them");
ABSL_FLAG(bool, study, false,
          "--protocol objects: run the paper's study: clean plus noise, outliers, crop and "
          "jitter at each of the five levels (--count pairs each, the same objects throughout)");
ABSL_FLAG(std::string, recall, "",
          "recall thresholds: objects ((1 deg, 0.01) and (5 deg, 0.05)) or lidar ((1 deg, 0.3 "
          "m)); default from --protocol");

namespace rpsr::client {
namespace {

struct EvalPair {
  std::string source_name;
  std::string target_name;
  core::Octree source;
  core::Octree target;
  std::optional<Eigen::Isometry3d> truth;
};

struct Setting {
  std::string name;
  std::vector<EvalPair> pairs;
};

absl::StatusOr<EvalPair> MakeEvalPair(const core::PointCloud& source,
                                      const core::PointCloud& target,
                                      const core::BarnesHutTreeOptions& tree_options) {
  absl::StatusOr<core::Octree> s = core::BuildOctree(source, tree_options);
  if (!s.ok()) return s.status();
  absl::StatusOr<core::Octree> t = core::BuildOctree(target, tree_options);
  if (!t.ok()) return t.status();
  EvalPair pair{"", "", *std::move(s), *std::move(t), std::nullopt};
  return pair;
}

absl::StatusOr<std::vector<Setting>> ObjectSettings(
    const core::BarnesHutTreeOptions& tree_options) {
  core::PairOptions base;
  std::optional<core::ObjectSplit> split =
      ParseObjectSplitFlag(absl::GetFlag(FLAGS_split), core::ObjectSplit::kM2Unseen);
  if (!split) return absl::InvalidArgumentError("--split must be m1, seen or unseen");
  base.split = *split;
  base.num_points = absl::GetFlag(FLAGS_num_points);
  std::vector<std::pair<core::DisturbanceKind, int>> kinds;
  if (absl::GetFlag(FLAGS_study)) {
    kinds.push_back({core::DisturbanceKind::kNone, 0});
    for (core::DisturbanceKind kind :
         {core::DisturbanceKind::kGaussianNoise, core::DisturbanceKind::kUniformOutliers,
          core::DisturbanceKind::kCrop, core::DisturbanceKind::kJitter}) {
      for (int level = 0; level < core::kNumDisturbanceLevels; ++level)
        kinds.push_back({kind, level});
    }
  } else {
    std::optional<core::DisturbanceKind> kind =
        ParseDisturbanceFlag(absl::GetFlag(FLAGS_disturbance));
    if (!kind)
      return absl::InvalidArgumentError(
          "--disturbance: none, noise, outliers, crop, jitter or partial");
    kinds.push_back({*kind, absl::GetFlag(FLAGS_level)});
  }
  const int count = absl::GetFlag(FLAGS_count);
  const uint64_t seed = absl::GetFlag(FLAGS_seed);
  std::vector<Setting> settings;
  ProgressBar bar("pairs");
  int done = 0;
  for (const auto& [kind, level] : kinds) {
    core::PairOptions options = base;
    options.disturbance = kind;
    options.disturbance_level = level;
    absl::StatusOr<double> magnitude = core::DisturbanceMagnitudeAtLevel(kind, level);
    if (!magnitude.ok()) return magnitude.status();
    Setting setting;
    setting.name = kind == core::DisturbanceKind::kNone
                       ? "clean"
                       : absl::StrCat(core::DisturbanceName(kind), "@", *magnitude);
    for (int i = 0; i < count; ++i) {
      // The same seed per index across settings: the same objects and poses, disturbed apart.
      absl::StatusOr<core::ObjectPair> pair =
          core::MakeObjectPair(options, core::DeriveSeed(seed, static_cast<uint64_t>(i)));
      if (!pair.ok()) return pair.status();
      absl::StatusOr<EvalPair> eval = MakeEvalPair(pair->source, pair->target, tree_options);
      if (!eval.ok()) return eval.status();
      eval->source_name = absl::StrCat("object:", i, ":source");
      eval->target_name = absl::StrCat("object:", i, ":target");
      eval->truth = pair->T_target_source;
      setting.pairs.push_back(*std::move(eval));
      bar.Update(++done, static_cast<double>(count) * kinds.size(), NAN, setting.name);
    }
    settings.push_back(std::move(setting));
  }
  bar.Finish();
  return settings;
}

absl::StatusOr<std::vector<Setting>> ManifestSettings(
    const std::string& path, const core::BarnesHutTreeOptions& tree_options) {
  absl::StatusOr<std::vector<core::ManifestRow>> rows = core::ReadPairManifest(path);
  if (!rows.ok()) return rows.status();
  Setting setting;
  setting.name = path;
  ProgressBar bar("read");
  for (size_t i = 0; i < rows->size(); ++i) {
    const core::ManifestRow& row = (*rows)[i];
    absl::StatusOr<core::PointCloud> source = core::ReadPointCloud(row.source);
    if (!source.ok()) return source.status();
    absl::StatusOr<core::PointCloud> target = core::ReadPointCloud(row.target);
    if (!target.ok()) return target.status();
    absl::StatusOr<EvalPair> eval = MakeEvalPair(*source, *target, tree_options);
    if (!eval.ok()) {
      return absl::Status(eval.status().code(),
                          absl::StrCat(path, " line ", i + 2, ": ", eval.status().message()));
    }
    eval->source_name = row.source;
    eval->target_name = row.target;
    eval->truth = row.T_target_source;
    setting.pairs.push_back(*std::move(eval));
    bar.Update(i + 1, rows->size(), NAN, "");
  }
  bar.Finish();
  return std::vector<Setting>{std::move(setting)};
}

std::string JsonEscaped(const std::string& text) {
  std::string out;
  for (char c : text) {
    if (c == '"' || c == '\\') out += '\\';
    out += c;
  }
  return out;
}

std::string Row16(const Eigen::Isometry3d& T) {
  return absl::StrJoin(core::RowMajorEntries(T), " ",
                       [](std::string* out, double v) { absl::StrAppendFormat(out, "%.9g", v); });
}

}  // namespace

int RunEvalCommand(const std::vector<std::string>& /*args*/) {
  const std::string output = absl::GetFlag(FLAGS_output);
  if (output.empty()) {
    std::fprintf(stderr, "rpsr eval: --output FILE.csv is required\n");
    return 2;
  }
  const std::string mode = absl::GetFlag(FLAGS_mode);
  absl::StatusOr<core::RegistrationMode> parsed_mode = core::ParseRegistrationMode(mode);
  if (!parsed_mode.ok()) {
    std::fprintf(stderr, "rpsr eval: --mode must be net, net+refine or refine (not %s)\n",
                 mode.c_str());
    return 2;
  }
  const std::string protocol = absl::GetFlag(FLAGS_protocol);
  std::string recall_kind = absl::GetFlag(FLAGS_recall);
  if (recall_kind.empty()) recall_kind = protocol == "lidar" ? "lidar" : "objects";
  if (recall_kind != "objects" && recall_kind != "lidar") {
    std::fprintf(stderr, "rpsr eval: --recall must be objects or lidar\n");
    return 2;
  }
  const std::vector<core::RecallThreshold> thresholds =
      recall_kind == "lidar" ? core::LidarRecallThresholds() : core::ObjectRecallThresholds();
  core::BarnesHutTreeOptions tree_options;
  tree_options.max_depth = absl::GetFlag(FLAGS_tree_depth);

  absl::StatusOr<std::unique_ptr<core::Registrar>> registrar =
      core::Registrar::Create(RegistrarConfigFromModelFlag(absl::GetFlag(FLAGS_model)));
  if (!registrar.ok()) {
    std::fprintf(stderr, "rpsr eval: %s\n", std::string(registrar.status().message()).c_str());
    return 1;
  }
  std::fprintf(stderr, "rpsr eval: %s\n", (*registrar)->model_description().c_str());
  core::SetNetThreads(absl::GetFlag(FLAGS_threads));

  absl::StatusOr<std::vector<Setting>> settings;
  if (!absl::GetFlag(FLAGS_manifest).empty()) {
    settings = ManifestSettings(absl::GetFlag(FLAGS_manifest), tree_options);
  } else if (protocol == "objects") {
    settings = ObjectSettings(tree_options);
  } else {
    std::fprintf(stderr,
                 "rpsr eval: --protocol %s needs --manifest (write one with rpsr data pairs)\n",
                 protocol.c_str());
    return 2;
  }
  if (!settings.ok()) {
    std::fprintf(stderr, "rpsr eval: %s\n", std::string(settings.status().message()).c_str());
    return settings.status().code() == absl::StatusCode::kInvalidArgument ? 2 : 1;
  }

  const std::filesystem::path parent = std::filesystem::path(output).parent_path();
  std::error_code ec;
  if (!parent.empty()) std::filesystem::create_directories(parent, ec);
  std::ofstream rows(output);
  if (ec || !rows) {
    std::fprintf(stderr, "rpsr eval: cannot write %s (%s)\n", output.c_str(),
                 ec ? ec.message().c_str() : std::strerror(errno));
    return 1;
  }
  rows << "setting,source,target,T_target_source,score_peak,time_ms,rotation_error_deg,"
          "translation_error,confidence,valid\n";
  const int batch_size = std::max(1, absl::GetFlag(FLAGS_batch_size));
  core::RegistrationOptions registration;
  registration.mode = *parsed_mode;
  ApplyRegistrationFlags(registration);
  std::string summary_csv =
      "setting,pairs,rotation_rmse_deg,rotation_mae_deg,"
      "rotation_median_deg,translation_rmse,translation_mae,"
      "translation_median";
  for (const core::RecallThreshold& t : thresholds) absl::StrAppend(&summary_csv, ",", t.Name());
  absl::StrAppend(&summary_csv, ",ms_per_pair\n");
  std::vector<std::string> json_settings;
  std::printf("%-28s %5s %9s %9s %9s %9s %9s", "setting", "pairs", "rot_rmse", "rot_mae", "rot_med",
              "t_rmse", "t_med");
  for (const core::RecallThreshold& t : thresholds) std::printf(" %16s", t.Name().c_str());
  std::printf(" %9s\n", "ms/pair");
  for (const Setting& setting : *settings) {
    std::vector<core::PairError> errors;
    double total_ms = 0.0;
    for (size_t begin = 0; begin < setting.pairs.size(); begin += batch_size) {
      const size_t end = std::min(setting.pairs.size(), begin + batch_size);
      std::vector<std::pair<const core::Octree*, const core::Octree*>> batch;
      for (size_t i = begin; i < end; ++i) {
        batch.push_back({&setting.pairs[i].source, &setting.pairs[i].target});
      }
      const auto start = std::chrono::steady_clock::now();
      std::vector<absl::StatusOr<core::RegistrationResult>> results =
          (*registrar)->RegisterBatch(batch, registration);
      const double ms =
          std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start)
              .count();
      total_ms += ms;
      for (size_t i = begin; i < end; ++i) {
        const EvalPair& pair = setting.pairs[i];
        const absl::StatusOr<core::RegistrationResult>& result = results[i - begin];
        if (!result.ok()) {
          std::fprintf(stderr, "rpsr eval: %s (%s): %s\n", setting.name.c_str(),
                       pair.source_name.c_str(), std::string(result.status().message()).c_str());
          return 1;
        }
        rows << setting.name << "," << pair.source_name << "," << pair.target_name << ","
             << Row16(result->T_target_source) << "," << result->net_score_peak << ","
             << ms / batch.size();
        if (pair.truth) {
          const core::PairError e = core::ErrorOf(result->T_target_source, *pair.truth);
          errors.push_back(e);
          rows << "," << e.rotation_deg << "," << e.translation;
        } else {
          rows << ",,";
        }
        rows << "," << result->confidence << "," << (result->valid ? 1 : 0) << "\n";
      }
    }
    const core::ErrorSummary s = core::Summarize(errors, thresholds);
    const double ms_per_pair = total_ms / std::max<size_t>(1, setting.pairs.size());
    std::printf("%-28s %5d %9.3f %9.3f %9.3f %9.4f %9.4f", setting.name.c_str(), s.count,
                s.rotation_rmse_deg, s.rotation_mae_deg, s.rotation_median_deg, s.translation_rmse,
                s.translation_median);
    for (double r : s.recall) std::printf(" %16.3f", r);
    std::printf(" %9.2f\n", ms_per_pair);
    absl::StrAppendFormat(&summary_csv, "%s,%d,%.6g,%.6g,%.6g,%.6g,%.6g,%.6g", setting.name,
                          s.count, s.rotation_rmse_deg, s.rotation_mae_deg, s.rotation_median_deg,
                          s.translation_rmse, s.translation_mae, s.translation_median);
    std::string json = absl::StrFormat(
        "{\"setting\": \"%s\", \"pairs\": %d, \"rotation_rmse_deg\": %.6g, "
        "\"rotation_mae_deg\": %.6g, \"rotation_median_deg\": %.6g, \"translation_rmse\": "
        "%.6g, \"translation_mae\": %.6g, \"translation_median\": %.6g",
        setting.name, s.count, s.rotation_rmse_deg, s.rotation_mae_deg, s.rotation_median_deg,
        s.translation_rmse, s.translation_mae, s.translation_median);
    for (size_t k = 0; k < thresholds.size(); ++k) {
      absl::StrAppendFormat(&summary_csv, ",%.4f", s.recall[k]);
      absl::StrAppendFormat(&json, ", \"%s\": %.4f", thresholds[k].Name(), s.recall[k]);
    }
    absl::StrAppendFormat(&summary_csv, ",%.3f\n", ms_per_pair);
    absl::StrAppendFormat(&json, ", \"ms_per_pair\": %.3f}", ms_per_pair);
    json_settings.push_back(json);
  }
  std::ofstream(output + ".summary.csv") << summary_csv;
  std::ofstream(output + ".summary.json")
      << "{\"model\": \"" << JsonEscaped((*registrar)->model_description()) << "\", \"mode\": \""
      << mode << "\", \"settings\": [\n  " << absl::StrJoin(json_settings, ",\n  ") << "\n]}\n";
  std::fprintf(stderr, "rpsr eval: wrote %s, %s.summary.csv and %s.summary.json\n", output.c_str(),
               output.c_str(), output.c_str());
  return 0;
}

}  // namespace rpsr::client
