// Fitting and measuring the confidence (confidence_model.h) on seeded registration pairs of both
// protocols: `rpsr calibrate` and the registrar's tests use these.
//
// A sample is one registration (one pair, one mode) with its features and its true errors.
// Success: within (1 degree, 1% of the target's extent), the event the confidence predicts.
// Failure (for the AUROC): beyond 5 degrees or 5% of the extent; the pairs in between count for
// the calibration error but not for the AUROC.
#ifndef RPSR_CORE_REGISTRAR_CONFIDENCE_CALIBRATION_H_
#define RPSR_CORE_REGISTRAR_CONFIDENCE_CALIBRATION_H_

#include <cstdint>
#include <functional>
#include <string>
#include <vector>

#include "absl/status/statusor.h"
#include "core/data/object_pairs.h"
#include "core/data/training_pairs.h"
#include "core/registrar/confidence_model.h"
#include "core/registrar/registrar.h"

namespace rpsr::core {

struct CalibrationSample {
  std::string protocol;  // "objects" or "lidar"
  std::string setting;   // e.g. "unseen/crop@0.2", "lidar+5/ground_removed"
  RegistrationMode mode = RegistrationMode::kNetRefine;
  bool valid = false;
  int num_degenerate = 0;
  std::string failure_reason;
  double confidence = 0.0;  // what the registrar reported
  std::vector<double> features;
  double rotation_error_deg = 0.0;
  double translation_error_rel = 0.0;  // translation error / ConfidenceExtent(target)

  bool success() const;  // <= 1 degree and <= 1% of the extent
  bool failure() const;  // > 5 degrees or > 5% of the extent
};

struct CalibrationSetOptions {
  // Seeds every pair. The fit uses validation seeds; measure on others (held out).
  uint64_t seed = 3;
  // Objects: per split, for clean and each of the four disturbances at each of the five levels
  // (21 settings), this many pairs, each a different object and pose; clouds alternate 1,024 and
  // 2,048 points.
  std::vector<ObjectSplit> object_splits = {ObjectSplit::kM1All, ObjectSplit::kM2Seen,
                                            ObjectSplit::kM2Unseen};
  int object_pairs_per_setting = 4;
  // Also partial views (both clouds cropped, each along its own direction: two scans of an
  // object from different viewpoints) at the five levels, 26 settings in all. Off for the shipped
  // fits: fitted with them (session 39), the held-out set with them read ECE 0.0166 against the
  // shipped fit's 0.0170 but 18 confident failures against 13, and without them 10 against 5
  // (tests/bench/notes/confidence-notes.md, *Partial views in the calibration set*).
  bool partial_views = false;
  int object_tree_depth = 6;
  // LiDAR: pairs of simulated sequences (core/data/training_pairs.h's stream, all four street
  // styles, half with ground removed) per frame offset (5 is the paper's; 10 adds harder ones).
  int lidar_pairs_per_offset = 32;
  std::vector<int> lidar_frame_offsets = {5, 10};
  int lidar_tree_depth = 9;
  // Unrelated pairs, this many of each kind: two random volumes (uniform points in boxes), two
  // different objects (families apart), two scans of different streets. No pose aligns them, so
  // every answer is a failure (protocol "unrelated"): the confidence learns what no match looks
  // like instead of extrapolating (two random clouds read 0.24 before).
  int unrelated_pairs_per_kind = 0;
  // Each pair is registered in each of these modes.
  std::vector<RegistrationMode> modes = {RegistrationMode::kNet, RegistrationMode::kNetRefine,
                                         RegistrationMode::kRefine};
  // Pairs in flight at once (the registrar is thread-safe); samples come back in a fixed order.
  int threads = 1;
  std::function<void(int done, int total)> progress;
};

// The simulated LiDAR pairs `frame_offset` frames apart that a calibration set with this pair seed
// draws (CalibrationSetOptions::seed; `rpsr calibrate --pair_seed`): its i-th LiDAR pair of that
// offset is pair i here (four street styles in turn, 8 consecutive pairs a sequence). Tests and
// benchmarks name held-out pairs by it.
RegistrationPairGenerator CalibrationLidarPairs(uint64_t pair_seed, int frame_offset);

// Generates the pairs, registers them and returns the samples (pair-major, modes in order).
absl::StatusOr<std::vector<CalibrationSample>> CollectCalibrationSamples(
    const Registrar& registrar, const CalibrationSetOptions& options);

struct ConfidenceFitOptions {
  // L2 penalty on the standardised weights (relative to the number of samples).
  double l2 = 1e-3;
  int max_newton_iterations = 50;
  // Isotonic map of the logistic output (pool adjacent violators).
  bool isotonic = true;
  double degenerate_cap = 0.05;
};

// Logistic regression (Newton's method) on the valid samples' features, then the isotonic map.
// InvalidArgument without both successes and non-successes among the valid samples.
absl::StatusOr<ConfidenceModel> FitConfidenceModel(const std::vector<CalibrationSample>& samples,
                                                   const ConfidenceFitOptions& options = {});

struct ReliabilityBin {
  double lower = 0.0, upper = 0.0;
  int count = 0;
  double mean_confidence = 0.0;
  double success_rate = 0.0;
};

struct ReliabilityReport {
  int count = 0;
  int successes = 0;
  int failures = 0;
  double mean_confidence = 0.0;
  double success_rate = 0.0;
  // Expected calibration error: sum over equal-width bins of (count / N) |success rate - mean
  // confidence|.
  double ece = 0.0;
  // Probability that a random success scores above a random failure (ties count half); NaN
  // without both.
  double auroc = 0.0;
  double brier = 0.0;
  std::vector<ReliabilityBin> bins;
};

// Of `confidences[i]` against samples[i]'s outcome.
ReliabilityReport MeasureReliability(const std::vector<CalibrationSample>& samples,
                                     const std::vector<double>& confidences, int num_bins = 10);

}  // namespace rpsr::core

#endif  // RPSR_CORE_REGISTRAR_CONFIDENCE_CALIBRATION_H_
