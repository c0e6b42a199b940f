#include "client/cli/registration_report.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <vector>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "absl/strings/str_join.h"
#include "core/data/registration_metrics.h"

namespace rpsr::client {
namespace {

std::string JsonNumbers(const double* values, int count) {
  std::string out = "[";
  for (int i = 0; i < count; ++i) {
    absl::StrAppendFormat(&out, "%s%.9g", i == 0 ? "" : ", ", values[i]);
  }
  return out + "]";
}

double Diagonal(const core::PointCloud& cloud) {
  const Eigen::AlignedBox3f box = core::BoundsOf(cloud.points);
  return box.isEmpty() ? 0.0 : static_cast<double>(box.sizes().norm());
}

// The mean number of points in the occupied cells of the cloud's bounding cube at `depth`.
double MeanPointsPerCell(const core::PointCloud& cloud, int depth) {
  const Eigen::AlignedBox3f box = core::BoundsOf(cloud.points);
  if (box.isEmpty()) return 0.0;
  const Eigen::Vector3d low = box.min().cast<double>();
  const double edge = std::max(static_cast<double>(box.sizes().maxCoeff()), 1e-30);
  const double cells = static_cast<double>(uint64_t{1} << depth);
  std::vector<uint64_t> codes;
  codes.reserve(cloud.points.size());
  for (const Eigen::Vector3f& p : cloud.points) {
    uint64_t code = 0;
    for (int a = 0; a < 3; ++a) {
      const double c = std::clamp((p[a] - low[a]) / edge * cells, 0.0, cells - 1.0);
      code = code * (uint64_t{1} << depth) + static_cast<uint64_t>(c);
    }
    codes.push_back(code);
  }
  std::sort(codes.begin(), codes.end());
  const size_t occupied =
      static_cast<size_t>(std::unique(codes.begin(), codes.end()) - codes.begin());
  return static_cast<double>(cloud.points.size()) / static_cast<double>(occupied);
}

}  // namespace

PairReport ReportOf(const core::RegistrationResult& result, double seconds) {
  PairReport report;
  report.T_target_source = result.T_target_source;
  report.valid = result.valid;
  report.failure_reason = result.failure_reason;
  report.confidence = result.confidence;
  report.fitness = result.fitness;
  report.inlier_rmse = result.inlier_rmse;
  report.iterations = result.iterations;
  report.mode = std::string(core::RegistrationModeName(result.mode));
  report.start = result.start;
  report.starts = result.starts;
  report.held_at_initial = result.held_at_initial;
  report.line_normals_from_planes = result.line_normals_from_planes;
  report.surface_scatter_cells = result.surface_scatter_cells;
  report.noise_polished = result.noise_polished;
  report.structure_alternative = result.structure_alternative_T_target_source;
  report.seconds = seconds;
  return report;
}

#if RPSR_CLI_HAS_SERVICE
PairReport ReportOf(const RegistrationResult& result) {
  PairReport report;
  report.T_target_source = result.T_target_source;
  report.valid = result.valid;
  report.failure_reason = result.failure_reason;
  report.confidence = result.confidence;
  report.fitness = result.fitness;
  report.inlier_rmse = result.inlier_rmse;
  report.iterations = result.iterations;
  report.mode = result.mode;
  report.start = result.start;
  report.starts = result.starts;
  report.held_at_initial = result.held_at_initial;
  report.line_normals_from_planes = result.line_normals_from_planes;
  report.surface_scatter_cells = result.surface_scatter_cells;
  report.noise_polished = result.noise_polished;
  report.structure_alternative = result.structure_alternative_T_target_source;
  report.seconds = result.round_trip_seconds;
  return report;
}
#endif

bool IsSceneScale(const core::PointCloud& cloud) {
  return Diagonal(cloud) > kSceneDiagonal &&
         MeanPointsPerCell(cloud, kSceneTreeDepth - 1) >= kSceneMinPointsPerCell;
}

int ChooseTreeDepth(const core::PointCloud& source, const core::PointCloud& target, int requested) {
  if (requested > 0) return requested;
  return IsSceneScale(source) || IsSceneScale(target) ? kSceneTreeDepth : 6;
}

std::string ChooseMode(const core::PointCloud& source, const core::PointCloud& target,
                       const std::string& requested, const std::string& model_name,
                       std::string* why, bool has_motion_prior) {
  if (!requested.empty()) {
    if (why != nullptr) *why = "as asked";
    return requested;
  }
  const bool scene = IsSceneScale(source) || IsSceneScale(target);
  const bool object_model = model_name.find("lidar") == std::string::npos;
  if (scene && object_model && has_motion_prior) {
    if (why != nullptr) {
      *why = "scene-scale clouds, an object model and a motion prior: refinement from the prior";
    }
    return "refine";
  }
  if (why != nullptr) {
    *why = scene && object_model
               ? "the default; scene-scale clouds and an object model: the refinement starts "
                 "from the network's first pass and, unless that is confident, from its second "
                 "pass, the identity and a searched start"
               : "the default";
  }
  return "net+refine";
}

std::string FormatReportText(const PairReport& report) {
  const Eigen::Matrix3d R = report.T_target_source.linear();
  const Eigen::Vector3d t = report.T_target_source.translation();
  const Eigen::Quaterniond q(R);
  std::string out;
  absl::StrAppendFormat(&out, "R =\n");
  for (int r = 0; r < 3; ++r) {
    absl::StrAppendFormat(&out, "  % .6f % .6f % .6f\n", R(r, 0), R(r, 1), R(r, 2));
  }
  absl::StrAppendFormat(&out, "t = % .6f % .6f % .6f\n", t.x(), t.y(), t.z());
  absl::StrAppendFormat(&out, "quaternion (w x y z) = % .6f % .6f % .6f % .6f\n", q.w(), q.x(),
                        q.y(), q.z());
  absl::StrAppendFormat(&out,
                        "valid %s, confidence %.3f, fitness %.3f, inlier RMSE %.4g, %d "
                        "iterations, mode %s, %s start of %d tried, %.1f ms\n",
                        report.valid ? "yes" : "no", report.confidence, report.fitness,
                        report.inlier_rmse, report.iterations, report.mode, report.start,
                        report.starts, 1e3 * report.seconds);
  if (!report.failure_reason.empty()) {
    // On a valid answer it is a doubt the pipeline has about it (mode refine's sensor-aligned
    // check: another pose fits the structure off the ground clearly better).
    absl::StrAppend(&out, report.valid ? "note: " : "reason: ", report.failure_reason, "\n");
  }
  if (report.noise_polished) {
    // Worth a line: the clouds are noisier than the finest cells, and the answer's precision is
    // the coarser depth's.
    absl::StrAppendFormat(&out,
                          "noisy surface: the source scatters %.2f finest cells about the "
                          "target's planes; polished point-to-plane one depth coarser\n",
                          report.surface_scatter_cells);
  }
  if (report.truth) {
    const core::PairError error = core::ErrorOf(report.T_target_source, *report.truth);
    absl::StrAppendFormat(&out, "error vs truth: rotation %.3f deg, translation %.4g\n",
                          error.rotation_deg, error.translation);
  }
  return out;
}

std::string FormatReportJson(const PairReport& report) {
  Eigen::Matrix<double, 3, 3, Eigen::RowMajor> R = report.T_target_source.linear();
  const Eigen::Vector3d t = report.T_target_source.translation();
  const Eigen::Quaterniond q(report.T_target_source.linear());
  const double quaternion[4] = {q.w(), q.x(), q.y(), q.z()};
  std::string out = absl::StrCat(
      "{\"valid\": ", report.valid ? "true" : "false",
      ", \"failure_reason\": ", JsonString(report.failure_reason),
      ", \"confidence\": ", absl::StrFormat("%.9g", report.confidence),
      ", \"rotation\": ", JsonNumbers(R.data(), 9), ", \"translation\": ", JsonNumbers(t.data(), 3),
      ", \"quaternion_wxyz\": ", JsonNumbers(quaternion, 4),
      ", \"fitness\": ", absl::StrFormat("%.9g", report.fitness),
      ", \"inlier_rmse\": ", absl::StrFormat("%.9g", report.inlier_rmse),
      ", \"iterations\": ", report.iterations, ", \"mode\": ", JsonString(report.mode),
      ", \"start\": ", JsonString(report.start), ", \"starts\": ", report.starts,
      ", \"held_at_initial\": ", report.held_at_initial ? "true" : "false",
      ", \"line_normals_from_planes\": ", report.line_normals_from_planes ? "true" : "false",
      ", \"surface_scatter_cells\": ", absl::StrFormat("%.6g", report.surface_scatter_cells),
      ", \"noise_polished\": ", report.noise_polished ? "true" : "false",
      ", \"seconds\": ", absl::StrFormat("%.6f", report.seconds));
  if (report.structure_alternative) {
    const Eigen::Matrix<double, 3, 3, Eigen::RowMajor> Ra = report.structure_alternative->linear();
    const Eigen::Vector3d ta = report.structure_alternative->translation();
    absl::StrAppend(&out, ", \"structure_alternative\": {\"rotation\": ", JsonNumbers(Ra.data(), 9),
                    ", \"translation\": ", JsonNumbers(ta.data(), 3), "}");
  }
  if (report.truth) {
    const core::PairError error = core::ErrorOf(report.T_target_source, *report.truth);
    absl::StrAppendFormat(&out, ", \"rotation_error_deg\": %.9g, \"translation_error\": %.9g",
                          error.rotation_deg, error.translation);
  }
  return out + "}";
}

std::string JsonString(const std::string& text) {
  std::string out = "\"";
  for (char c : text) {
    if (c == '"' || c == '\\') {
      out += '\\';
      out += c;
    } else if (static_cast<unsigned char>(c) < 0x20) {
      absl::StrAppendFormat(&out, "\\u%04x", static_cast<int>(c));
    } else {
      out += c;
    }
  }
  return out + "\"";
}

absl::StatusOr<PairReport> RegisterWithRegistrar(const core::Registrar& registrar,
                                                 const core::PointCloud& source,
                                                 const core::PointCloud& target, int tree_depth,
                                                 const core::RegistrationOptions& options) {
  const auto start = std::chrono::steady_clock::now();
  core::BarnesHutTreeOptions tree_options;
  tree_options.max_depth = tree_depth;
  absl::StatusOr<core::Octree> source_tree = core::BuildOctree(source, tree_options);
  if (!source_tree.ok()) {
    return absl::Status(source_tree.status().code(),
                        absl::StrCat("source: ", source_tree.status().message()));
  }
  absl::StatusOr<core::Octree> target_tree = core::BuildOctree(target, tree_options);
  if (!target_tree.ok()) {
    return absl::Status(target_tree.status().code(),
                        absl::StrCat("target: ", target_tree.status().message()));
  }
  absl::StatusOr<core::RegistrationResult> result =
      registrar.Register(*source_tree, *target_tree, options);
  if (!result.ok()) return result.status();
  return ReportOf(*result,
                  std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count());
}

}  // namespace rpsr::client
