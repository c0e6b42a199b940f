#include "core/data/registration_metrics.h"

#include <algorithm>
#include <cmath>

#include "absl/strings/str_cat.h"
#include "core/data/transform_convention.h"

namespace rpsr::core {
namespace {

double Median(std::vector<double> values) {
  if (values.empty()) return 0.0;
  const size_t mid = values.size() / 2;
  std::nth_element(values.begin(), values.begin() + mid, values.end());
  if (values.size() % 2 == 1) return values[mid];
  const double upper = values[mid];
  return 0.5 * (upper + *std::max_element(values.begin(), values.begin() + mid));
}

}  // namespace

PairError ErrorOf(const Eigen::Isometry3d& estimate, const Eigen::Isometry3d& truth) {
  return {RotationErrorRad(truth.linear(), estimate.linear()) * 180.0 / M_PI,
          TranslationError(truth.translation(), estimate.translation())};
}

std::string RecallThreshold::Name() const {
  // No comma: the name is a CSV column header.
  return absl::StrCat("recall@", rotation_deg, "deg/", translation);
}

ErrorSummary Summarize(const std::vector<PairError>& errors,
                       const std::vector<RecallThreshold>& thresholds) {
  ErrorSummary s;
  s.count = static_cast<int>(errors.size());
  s.recall.assign(thresholds.size(), 0.0);
  if (errors.empty()) return s;
  std::vector<double> rotations, translations;
  for (const PairError& e : errors) {
    rotations.push_back(e.rotation_deg);
    translations.push_back(e.translation);
    s.rotation_rmse_deg += e.rotation_deg * e.rotation_deg;
    s.rotation_mae_deg += e.rotation_deg;
    s.translation_rmse += e.translation * e.translation;
    s.translation_mae += e.translation;
    for (size_t k = 0; k < thresholds.size(); ++k) {
      if (e.rotation_deg <= thresholds[k].rotation_deg &&
          e.translation <= thresholds[k].translation) {
        s.recall[k] += 1.0;
      }
    }
  }
  const double n = static_cast<double>(errors.size());
  s.rotation_rmse_deg = std::sqrt(s.rotation_rmse_deg / n);
  s.rotation_mae_deg /= n;
  s.translation_rmse = std::sqrt(s.translation_rmse / n);
  s.translation_mae /= n;
  s.rotation_median_deg = Median(rotations);
  s.translation_median = Median(translations);
  for (double& r : s.recall) r /= n;
  return s;
}

std::vector<RecallThreshold> ObjectRecallThresholds() { return {{1.0, 0.01}, {5.0, 0.05}}; }
std::vector<RecallThreshold> LidarRecallThresholds() { return {{1.0, 0.3}}; }

}  // namespace rpsr::core
