// The confidence of a registration: a calibrated probability that the returned pose is within
// (1 degree, 1% of the target's extent) of the truth, from what the pipeline measured on the way.
//
// The target's extent is its tree's cube half-length (the largest half-extent of its bounding
// box): 1 for an object scaled into [-1, 1]^3, so 1% is the object protocol's 0.01; ~0.8-1.2 m on
// a LiDAR scan.
//
// Model: logistic regression on standardised features (all free of the clouds' scale, so objects
// and LiDAR scans share one model with no per-dataset switch), then an isotonic
// (pool-adjacent-violators) map of its output, fitted by `rpsr calibrate` on held-back validation
// pairs of both protocols (confidence_calibration.h). Invalid results get 0; results with any
// degenerate direction are capped at `degenerate_cap` (they are invalid today, but the cap holds
// whatever the validity rules become).
//
// Text format (one file per model, core/models/<name>/confidence.txt, embedded beside the
// weights), '#' starts a comment:
//   rpsr_confidence 1
//   bias <b>
//   feature <name> <mean> <scale> <weight>      one line per feature used (any subset, any order)
//   isotonic <x_1> <y_1> ... <x_n> <y_n>        optional, x ascending, y non-decreasing in [0, 1];
//                                               linear between the points and on to (0, 0) and
//                                               (1, 1) beyond the ends
//   degenerate_cap <c>                          optional (default 0.05)
#ifndef RPSR_CORE_REGISTRAR_CONFIDENCE_MODEL_H_
#define RPSR_CORE_REGISTRAR_CONFIDENCE_MODEL_H_

#include <string>
#include <vector>

#include "absl/status/statusor.h"
#include "absl/strings/string_view.h"
#include "core/refine/symmetry_starts.h"
#include "core/refine/tree_refinement.h"
#include "core/registrar/registrar.h"
#include "core/tree/bh_tree.h"

namespace rpsr::core {

// The features, in the order ConfidenceFeatureVector returns them.
enum ConfidenceFeature {
  kFeatureFitness,                 // overlap fraction at the fitness depth
  kFeatureInlierRmseCells,         // inlier RMSE / the fitness depth's cell edge
  kFeatureFinestFitness,           // the same two at the finest depth
  kFeatureFinestInlierRmseCells,   //
  kFeatureMeanRobustWeight,        // mean robust weight of the fitness depth's correspondences
  kFeatureLogMinEigenvalue,        // log10 of the smallest normalised information eigenvalue
  kFeatureLogSecondEigenvalue,     // log10 of the second smallest
  kFeatureLogRotationStdDeg,       // log10 of the largest rotation std. dev. from information^-1
  kFeatureLogTranslationStdRel,    // log10 of the largest translation std. dev. / extent
  kFeatureConverged,               // 1 when every depth met its epsilons
  kFeatureIterationsPerDepth,      // Gauss-Newton iterations per visited depth
  kFeatureFinestIterations,        // Gauss-Newton iterations at the finest depth
  kFeatureLogLastUpdateCells,      // log10 of the finest depth's last update, in cells
  kFeatureNetScorePeak,            // the network's mean peak score (0 in mode refine)
  kFeatureLogNetPassChangeDeg,     // log10(1 + rotation change of the network's last pass, deg)
  kFeatureNetPassChangeRel,        // how far the last pass moved the source's CoM / extent
  kFeatureLogRefineCorrectionDeg,  // log10(1 + rotation from the start of refinement to T, deg)
  kFeatureRefineCorrectionRel,     // how far the refinement moved the source's CoM / extent
  kFeatureModeNet,                 // 1 in mode net
  kFeatureModeRefine,              // 1 in mode refine
  kFeatureSurfaceScatterCells,     // the source's scatter about the target's planes (0: unmeasured)
  kFeatureNoisePolished,           // 1 when the noise polish ran (tree_refinement.h)
  kFeatureSymmetricTwinMargin,     // answer's breaking-node match minus its best twin's, [-1, 1]
  kFeatureTurnContrast,  // how many more nodes the answer turned by 45 deg leaves unmatched
  kNumConfidenceFeatures,
};

// Snake-case names as they appear in the text file ("fitness", "inlier_rmse_cells", ...).
const std::vector<std::string>& ConfidenceFeatureNames();

// What the features are computed from. `refinement` is the refinement's (or, in mode net, the
// measuring evaluation's) result; `net_per_pass` the network's estimates after each pass run (empty
// in mode refine; one in net+refine when the later passes did not run, and then the last-pass
// change features read 0); `refine_start` the transform the refinement started from.
struct ConfidenceInputs {
  const RegistrationResult* result = nullptr;
  const TreeRefinementResult* refinement = nullptr;
  const Octree* source = nullptr;
  const Octree* target = nullptr;
  std::vector<Eigen::Isometry3d> net_per_pass;
  Eigen::Isometry3d refine_start = Eigen::Isometry3d::Identity();
  // The target's near-symmetries (FindSelfSymmetries; the registrar finds them once per
  // object-scale pair); null or empty: none.
  const std::vector<SelfSymmetry>* symmetries = nullptr;
};

std::vector<double> ConfidenceFeatureVector(const ConfidenceInputs& inputs);

// The extent the confidence's translation tolerance refers to (see the header comment).
double ConfidenceExtent(const Octree& target);

class ConfidenceModel {
 public:
  struct Feature {
    int index = 0;  // into ConfidenceFeatureVector
    double mean = 0.0;
    double scale = 1.0;
    double weight = 0.0;
  };

  // A conservative hand-set model for when no calibration is shipped: fitness, inlier RMSE,
  // convergence and the smallest eigenvalue only; it is not calibrated.
  static ConfidenceModel Uncalibrated();
  // InvalidArgument naming the line for anything malformed or an unknown feature name.
  static absl::StatusOr<ConfidenceModel> Parse(absl::string_view text);
  std::string ToText(absl::string_view comment = "") const;

  // The logistic model's probability before the isotonic map.
  double RawProbability(const std::vector<double>& features) const;
  // The calibrated probability (isotonic map applied), without the validity rules.
  double Probability(const std::vector<double>& features) const;
  // What the registrar reports: 0 when !valid, at most degenerate_cap when num_degenerate > 0.
  double Confidence(const std::vector<double>& features, bool valid, int num_degenerate) const;

  // false for Uncalibrated().
  bool calibrated = true;
  double bias = 0.0;
  std::vector<Feature> features;
  std::vector<double> isotonic_x;  // empty: identity
  std::vector<double> isotonic_y;
  double degenerate_cap = 0.05;
};

}  // namespace rpsr::core

#endif  // RPSR_CORE_REGISTRAR_CONFIDENCE_MODEL_H_
