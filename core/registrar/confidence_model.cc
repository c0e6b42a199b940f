#include "core/registrar/confidence_model.h"

#include <algorithm>
#include <cmath>
#include <string>
#include <vector>

#include "Eigen/Eigenvalues"
#include "Eigen/LU"
#include "absl/status/status.h"
#include "absl/strings/numbers.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "absl/strings/str_split.h"
#include "absl/strings/strip.h"
#include "core/refine/cell_index.h"
#include "core/refine/node_closeness.h"
#include "core/refine/symmetry_starts.h"

namespace rpsr::core {
namespace {

constexpr double kRadToDeg = 180.0 / M_PI;

double AngleDeg(const Eigen::Matrix3d& R) {
  const double c = std::clamp((R.trace() - 1.0) / 2.0, -1.0, 1.0);
  return std::acos(c) * kRadToDeg;
}

// Rotation (deg) between two transforms, and how far apart they put the source's centre of mass
// (the clouds' units). Not the difference of their translations: that depends on where the
// clouds lie from their frame's origin (a cloud 1 km from it moves 17 m under a 1-degree turn),
// and the features must read the same for a cloud however it is placed.
std::pair<double, double> Difference(const Eigen::Isometry3d& a, const Eigen::Isometry3d& b,
                                     const Eigen::Vector3d& centre) {
  return {AngleDeg(a.linear().transpose() * b.linear()), (a * centre - b * centre).norm()};
}

double Sigmoid(double z) {
  if (z >= 0) return 1.0 / (1.0 + std::exp(-z));
  const double e = std::exp(z);
  return e / (1.0 + e);
}

int FeatureIndex(absl::string_view name) {
  const std::vector<std::string>& names = ConfidenceFeatureNames();
  for (size_t i = 0; i < names.size(); ++i) {
    if (names[i] == name) return static_cast<int>(i);
  }
  return -1;
}

// How sharply the answer is singled out among other poses: the mean fraction of the source's
// nodes (SymmetryDepth, an even sample) left without a target node within 1.9 cells when the
// answer is turned by 45 degrees either way about each axis through the moved source's centre,
// minus the answer's own fraction. A surface fitted right loses many of its partners under such a
// turn; two clouds that explain each other about as well in any pose (two volumes of random
// points, fog) lose few, however well they fit. Measured on held-out pairs (pair seed 1003, modes
// refine and net+refine): right answers on objects 0.13-0.78 (5% below 0.22; a round object
// turned about its axis keeps its partners) and on scans 0.64-0.88; unrelated random volumes
// -0.01-0.15, unrelated objects and streets up to 0.43 (turns of 15 degrees: right objects down
// to 0.01; 30 degrees: 0.04; 30 and shifts of 15% of the extent: 0.085 against volumes' 0.083,
// twice the cost). 0 where nothing can be measured.
double TurnContrast(const Octree& source, const Octree& target, const Eigen::Isometry3d& answer) {
  constexpr double kTurnDeg = 45.0;
  // The twin margin's distance (1.9 cells one depth above the finest): a partner that near.
  const double far_cells = SelfSymmetryOptions{}.far_cells;
  const Eigen::Vector3d pivot = answer * source.level(0).center_of_mass[0].cast<double>();
  std::vector<Eigen::Isometry3d> poses = {answer};
  for (int axis = 0; axis < 3; ++axis) {
    for (double sign : {-1.0, 1.0}) {
      const Eigen::AngleAxisd turn(sign * kTurnDeg * M_PI / 180.0, Eigen::Vector3d::Unit(axis));
      Eigen::Isometry3d about = Eigen::Isometry3d::Identity();
      about.linear() = turn.toRotationMatrix();
      about.translation() = pivot - turn * pivot;
      poses.push_back(about * answer);
    }
  }
  // 512 of the depth's nodes: each fraction within ~0.02 (binomial standard error), at a quarter
  // of the 2,048 nodes' cost (registrar_bench's confidence_ms, a scan pair 4.0 -> 0.9 ms).
  NodeClosenessOptions sample;
  sample.max_source_nodes = 512;
  const std::vector<double> far =
      FarNodeFractions(source, target, poses, SymmetryDepth(source, target), far_cells, sample);
  if (far.empty() || far.front() < 0.0) return 0.0;
  double turned = 0.0;
  for (size_t k = 1; k < far.size(); ++k) {
    if (far[k] < 0.0) return 0.0;
    turned += far[k];
  }
  return turned / static_cast<double>(far.size() - 1) - far.front();
}

}  // namespace

const std::vector<std::string>& ConfidenceFeatureNames() {
  static const auto* names = new std::vector<std::string>{
      "fitness",
      "inlier_rmse_cells",
      "finest_fitness",
      "finest_inlier_rmse_cells",
      "mean_robust_weight",
      "log_min_eigenvalue",
      "log_second_eigenvalue",
      "log_rotation_std_deg",
      "log_translation_std_rel",
      "converged",
      "iterations_per_depth",
      "finest_iterations",
      "log_last_update_cells",
      "net_score_peak",
      "log_net_pass_change_deg",
      "net_pass_change_rel",
      "log_refine_correction_deg",
      "refine_correction_rel",
      "mode_net",
      "mode_refine",
      "surface_scatter_cells",
      "noise_polished",
      "symmetric_twin_margin",
      "turn_contrast",
  };
  return *names;
}

double ConfidenceExtent(const Octree& target) { return target.half_length(); }

std::vector<double> ConfidenceFeatureVector(const ConfidenceInputs& in) {
  std::vector<double> f(kNumConfidenceFeatures, 0.0);
  const RegistrationResult& r = *in.result;
  const TreeRefinementResult& refined = *in.refinement;
  const double extent = std::max(ConfidenceExtent(*in.target), 1e-12);
  const Eigen::Vector3d centre = in.source->level(0).center_of_mass[0].cast<double>();
  const double fitness_edge = CellEdge(*in.target, refined.fitness_depth);
  f[kFeatureFitness] = refined.fitness;
  f[kFeatureInlierRmseCells] = refined.inlier_rmse / std::max(fitness_edge, 1e-12);
  const double finest_edge =
      refined.stages.empty() ? fitness_edge : std::max(refined.stages.back().cell_edge, 1e-12);
  f[kFeatureFinestFitness] = refined.finest_fitness;
  f[kFeatureFinestInlierRmseCells] = refined.finest_inlier_rmse / finest_edge;
  f[kFeatureMeanRobustWeight] = refined.mean_robust_weight;
  f[kFeatureFinestIterations] = refined.stages.empty() ? 0.0 : refined.stages.back().iterations;
  f[kFeatureLogMinEigenvalue] = std::log10(std::max(refined.normalized_eigenvalues[0], 1e-6));
  f[kFeatureLogSecondEigenvalue] = std::log10(std::max(refined.normalized_eigenvalues[1], 1e-6));
  // The pose's standard errors as the information matrix predicts them (up to the residuals' true
  // scale, which the regularised covariances only approximate).
  // The damping that keeps a singular H invertible is relative to its trace with the rotation
  // rows and columns taken as displacements at the extent (rotation * extent), as the refinement
  // damps: a plain trace adds radians^-2 to metres^-2, which weighs differently at every scale.
  const Eigen::Matrix<double, 6, 6>& H = refined.information;
  const double extent2 = extent * extent;
  const double trace = H.diagonal().head<3>().sum() / extent2 + H.diagonal().tail<3>().sum();
  if (trace > 0 && H.allFinite()) {
    Eigen::Matrix<double, 6, 6> damped = H;
    damped.diagonal().head<3>().array() += 1e-9 * trace * extent2;
    damped.diagonal().tail<3>().array() += 1e-9 * trace;
    const Eigen::Matrix<double, 6, 6> covariance = damped.inverse();
    Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> rotation(covariance.topLeftCorner<3, 3>());
    Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> translation(
        covariance.bottomRightCorner<3, 3>());
    const double rotation_std_deg =
        std::sqrt(std::max(rotation.eigenvalues().maxCoeff(), 0.0)) * kRadToDeg;
    const double translation_std = std::sqrt(std::max(translation.eigenvalues().maxCoeff(), 0.0));
    f[kFeatureLogRotationStdDeg] = std::log10(std::max(rotation_std_deg, 1e-9));
    f[kFeatureLogTranslationStdRel] = std::log10(std::max(translation_std / extent, 1e-12));
  } else {
    f[kFeatureLogRotationStdDeg] = 2.0;
    f[kFeatureLogTranslationStdRel] = 0.0;
  }
  f[kFeatureConverged] = refined.converged ? 1.0 : 0.0;
  f[kFeatureIterationsPerDepth] =
      refined.stages.empty()
          ? 0.0
          : static_cast<double>(refined.iterations) / static_cast<double>(refined.stages.size());
  if (!refined.stages.empty()) {
    const DepthStage& last = refined.stages.back();
    const double cells =
        (last.last_update_translation + last.last_update_rotation_rad * in.target->half_length()) /
        std::max(last.cell_edge, 1e-12);
    f[kFeatureLogLastUpdateCells] = std::log10(std::max(cells, 1e-6));
  } else {
    f[kFeatureLogLastUpdateCells] = -6.0;
  }
  f[kFeatureNetScorePeak] = r.net_score_peak;
  if (in.net_per_pass.size() >= 2) {
    const auto [deg, metres] =
        Difference(in.net_per_pass[in.net_per_pass.size() - 2], in.net_per_pass.back(), centre);
    f[kFeatureLogNetPassChangeDeg] = std::log10(1.0 + deg);
    f[kFeatureNetPassChangeRel] = metres / extent;
  }
  const auto [deg, metres] = Difference(in.refine_start, r.T_target_source, centre);
  f[kFeatureLogRefineCorrectionDeg] = std::log10(1.0 + deg);
  f[kFeatureRefineCorrectionRel] = metres / extent;
  f[kFeatureModeNet] = r.mode == RegistrationMode::kNet ? 1.0 : 0.0;
  f[kFeatureModeRefine] = r.mode == RegistrationMode::kRefine ? 1.0 : 0.0;
  // Polished answers are of noisy clouds, whose other measures read differently (a coarser last
  // stage, normal distances of scattered points); unrelated clouds scatter as much (random volumes
  // read up to 0.43 in net+refine when the fit knew neither).
  f[kFeatureSurfaceScatterCells] = std::max(refined.surface_scatter_cells, 0.0);
  f[kFeatureNoisePolished] = refined.noise_polished ? 1.0 : 0.0;
  // A near-symmetric object's answer (a gear a tooth off) fits as well by every measure above as
  // its twin does; only the feature that breaks the symmetry (a gear's pin) tells them apart
  // (symmetry_starts.h). The margin is how much more of the target's breaking nodes the answer's
  // meet than its best twin's do (BreakingNodeMatches): on 220 unseen gear answers (the
  // ten-setting harness's settings, seeds 1-3) those at 0.5 or more were right 95% of the time
  // (the rest jittered pairs a translation off), those below -0.2 never, and the old fit read
  // them all at ~0.3 (tests/bench/notes/confidence-notes.md, *The twin margin by the features
  // that break the symmetry*). No near-symmetry (most objects, every scan): 1, as no twin comes
  // near. Near-symmetries without a feature to find on both sides (a screwdriver's lobes, a pin
  // cropped away): 0, the twins cannot be told apart.
  f[kFeatureSymmetricTwinMargin] = 1.0;
  if (in.symmetries != nullptr && !in.symmetries->empty()) {
    f[kFeatureSymmetricTwinMargin] = 0.0;
    const BreakingNodes breaking =
        FindBreakingNodes(*in.source, *in.target, r.T_target_source, *in.symmetries);
    std::vector<Eigen::Isometry3d> poses = {r.T_target_source};
    for (const SelfSymmetry& symmetry : *in.symmetries) {
      poses.push_back(symmetry.S * r.T_target_source);
    }
    const std::vector<double> matches =
        BreakingNodeMatches(*in.source, *in.target, breaking, poses);
    if (matches.front() >= 0.0) {
      const double best_twin = *std::max_element(matches.begin() + 1, matches.end());
      f[kFeatureSymmetricTwinMargin] = matches.front() - best_twin;
    }
  }
  f[kFeatureTurnContrast] = TurnContrast(*in.source, *in.target, r.T_target_source);
  for (double& v : f) {
    if (!std::isfinite(v)) v = 0.0;
  }
  return f;
}

ConfidenceModel ConfidenceModel::Uncalibrated() {
  ConfidenceModel m;
  m.calibrated = false;
  m.bias = 0.0;
  // Around a well-fitted pair: fitness ~0.9, RMSE ~0.15 cells, converged.
  m.features = {
      {kFeatureFitness, 0.8, 0.1, 1.5},   {kFeatureInlierRmseCells, 0.2, 0.05, -1.0},
      {kFeatureConverged, 0.5, 0.5, 0.5}, {kFeatureLogMinEigenvalue, -1.0, 0.5, 0.5},
      {kFeatureModeNet, 0.0, 1.0, -4.0},
  };
  return m;
}

double ConfidenceModel::RawProbability(const std::vector<double>& x) const {
  double z = bias;
  for (const Feature& f : features) {
    const double v = f.index < static_cast<int>(x.size()) ? x[f.index] : 0.0;
    z += f.weight * (v - f.mean) / f.scale;
  }
  return Sigmoid(z);
}

double ConfidenceModel::Probability(const std::vector<double>& x) const {
  const double p = RawProbability(x);
  if (isotonic_x.empty()) return p;
  // Beyond the end points, straight on to (0, 0) and (1, 1): no flat ends, so two results the
  // logistic model ranks apart stay apart.
  if (p <= isotonic_x.front()) {
    return isotonic_x.front() > 0 ? isotonic_y.front() * p / isotonic_x.front() : 0.0;
  }
  if (p >= isotonic_x.back()) {
    const double rest = 1.0 - isotonic_x.back();
    return rest > 0 ? isotonic_y.back() + (1.0 - isotonic_y.back()) * (p - isotonic_x.back()) / rest
                    : isotonic_y.back();
  }
  const size_t hi = static_cast<size_t>(std::upper_bound(isotonic_x.begin(), isotonic_x.end(), p) -
                                        isotonic_x.begin());
  const size_t lo = hi - 1;
  const double span = isotonic_x[hi] - isotonic_x[lo];
  const double a = span > 0 ? (p - isotonic_x[lo]) / span : 0.5;
  return isotonic_y[lo] + a * (isotonic_y[hi] - isotonic_y[lo]);
}

double ConfidenceModel::Confidence(const std::vector<double>& x, bool valid,
                                   int num_degenerate) const {
  if (!valid) return 0.0;
  double p = Probability(x);
  if (num_degenerate > 0) p = std::min(p, degenerate_cap);
  return std::clamp(p, 0.0, 1.0);
}

std::string ConfidenceModel::ToText(absl::string_view comment) const {
  std::string out = "rpsr_confidence 1\n";
  for (absl::string_view line : absl::StrSplit(comment, '\n', absl::SkipEmpty())) {
    absl::StrAppend(&out, "# ", line, "\n");
  }
  absl::StrAppendFormat(&out, "bias %.17g\n", bias);
  const std::vector<std::string>& names = ConfidenceFeatureNames();
  for (const Feature& f : features) {
    absl::StrAppendFormat(&out, "feature %s %.17g %.17g %.17g\n", names[f.index], f.mean, f.scale,
                          f.weight);
  }
  if (!isotonic_x.empty()) {
    out += "isotonic";
    for (size_t i = 0; i < isotonic_x.size(); ++i) {
      absl::StrAppendFormat(&out, " %.17g %.17g", isotonic_x[i], isotonic_y[i]);
    }
    out += "\n";
  }
  absl::StrAppendFormat(&out, "degenerate_cap %.17g\n", degenerate_cap);
  return out;
}

absl::StatusOr<ConfidenceModel> ConfidenceModel::Parse(absl::string_view text) {
  ConfidenceModel m;
  bool header = false;
  int line_number = 0;
  auto error = [&](absl::string_view what) {
    return absl::InvalidArgumentError(
        absl::StrCat("confidence calibration line ", line_number, ": ", what));
  };
  for (absl::string_view raw : absl::StrSplit(text, '\n')) {
    ++line_number;
    absl::string_view line = raw.substr(0, raw.find('#'));
    line = absl::StripAsciiWhitespace(line);
    if (line.empty()) continue;
    std::vector<absl::string_view> tokens =
        absl::StrSplit(line, absl::ByAnyChar(" \t"), absl::SkipEmpty());
    std::vector<double> numbers;
    for (size_t i = 1; i < tokens.size(); ++i) {
      double v = 0.0;
      if (tokens[0] == "feature" && i == 1) continue;
      if (!absl::SimpleAtod(tokens[i], &v) || !std::isfinite(v)) {
        return error(absl::StrCat("'", tokens[i], "' is not a finite number"));
      }
      numbers.push_back(v);
    }
    if (!header) {
      if (tokens[0] != "rpsr_confidence" || numbers.size() != 1 || numbers[0] != 1) {
        return error("expected the header 'rpsr_confidence 1'");
      }
      header = true;
    } else if (tokens[0] == "bias") {
      if (numbers.size() != 1) return error("bias takes one number");
      m.bias = numbers[0];
    } else if (tokens[0] == "feature") {
      if (tokens.size() != 5) return error("feature takes a name, mean, scale and weight");
      Feature f;
      f.index = FeatureIndex(tokens[1]);
      if (f.index < 0) return error(absl::StrCat("unknown feature '", tokens[1], "'"));
      f.mean = numbers[0];
      f.scale = numbers[1];
      f.weight = numbers[2];
      if (!(f.scale > 0)) return error("a feature's scale must be positive");
      m.features.push_back(f);
    } else if (tokens[0] == "isotonic") {
      if (numbers.size() < 4 || numbers.size() % 2 != 0) {
        return error("isotonic takes at least two (x, y) pairs");
      }
      for (size_t i = 0; i < numbers.size(); i += 2) {
        m.isotonic_x.push_back(numbers[i]);
        m.isotonic_y.push_back(numbers[i + 1]);
      }
      for (size_t i = 0; i < m.isotonic_x.size(); ++i) {
        if (m.isotonic_y[i] < 0 || m.isotonic_y[i] > 1) return error("isotonic y outside [0, 1]");
        if (i > 0 &&
            (m.isotonic_x[i] < m.isotonic_x[i - 1] || m.isotonic_y[i] < m.isotonic_y[i - 1])) {
          return error("isotonic points must be ascending in x and non-decreasing in y");
        }
      }
    } else if (tokens[0] == "degenerate_cap") {
      if (numbers.size() != 1 || numbers[0] < 0 || numbers[0] > 1) {
        return error("degenerate_cap takes one number in [0, 1]");
      }
      m.degenerate_cap = numbers[0];
    } else {
      return error(absl::StrCat("unknown key '", tokens[0], "'"));
    }
  }
  if (!header) return absl::InvalidArgumentError("confidence calibration: empty text");
  return m;
}

}  // namespace rpsr::core
