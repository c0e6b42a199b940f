// Errors of registration results against the truth and their summary, as the paper reports them
// (Sec. 4): rotation angle phi = acos((tr(R_gt^T R) - 1) / 2) in degrees and translation distance
// ||t_gt - t||, with RMSE, MAE, median and recall at thresholds.
#ifndef RPSR_CORE_DATA_REGISTRATION_METRICS_H_
#define RPSR_CORE_DATA_REGISTRATION_METRICS_H_

#include <string>
#include <vector>

#include "Eigen/Geometry"

namespace rpsr::core {

struct PairError {
  double rotation_deg = 0.0;
  double translation = 0.0;
};

PairError ErrorOf(const Eigen::Isometry3d& estimate, const Eigen::Isometry3d& truth);

// A pair counts as recalled when rotation_deg <= rotation_deg and translation <= translation.
struct RecallThreshold {
  double rotation_deg = 1.0;
  double translation = 0.01;
  std::string Name() const;  // e.g. "recall@1deg/0.01"
};

struct ErrorSummary {
  int count = 0;
  double rotation_rmse_deg = 0.0;
  double rotation_mae_deg = 0.0;
  double rotation_median_deg = 0.0;
  double translation_rmse = 0.0;
  double translation_mae = 0.0;
  double translation_median = 0.0;
  std::vector<double> recall;  // one per threshold, in [0, 1]
};

ErrorSummary Summarize(const std::vector<PairError>& errors,
                       const std::vector<RecallThreshold>& thresholds);

// The thresholds issue 4 reports: (1 deg, 0.01) and (5 deg, 0.05) for objects in [-1, 1];
// (1 deg, 0.3 m) for LiDAR.
std::vector<RecallThreshold> ObjectRecallThresholds();
std::vector<RecallThreshold> LidarRecallThresholds();

}  // namespace rpsr::core

#endif  // RPSR_CORE_DATA_REGISTRATION_METRICS_H_
