#include "core/refine/degenerate_hold.h"

#include "absl/strings/str_cat.h"

namespace rpsr::core {

Eigen::Isometry3d HoldDegenerateDirections(const TreeRefinementResult& refined,
                                           const Eigen::Isometry3d& prior) {
  const Eigen::MatrixXd& directions = refined.degenerate_directions;
  if (refined.num_degenerate <= 0 || directions.cols() != refined.num_degenerate ||
      directions.rows() != 6) {
    return refined.T_target_source;
  }
  // The motion from the prior in the directions' units (metres throughout), its degenerate
  // components removed.
  Eigen::Matrix<double, 6, 1> u =
      MotionInMetres(refined, refined.T_target_source * prior.inverse());
  u -= directions * (directions.transpose() * u);
  return MotionFromMetres(refined, u) * prior;
}

void AddDegenerateTurn(const Eigen::Vector3d& axis, const Eigen::Vector3d& point,
                       absl::string_view why, TreeRefinementResult& refined) {
  const Eigen::Vector3d a = axis.normalized();
  // A turn w about the axis through `point` is, about information_center c, the turn w and the
  // translation w x (c - point).
  Eigen::Matrix<double, 6, 1> d;
  d << a.cwiseProduct(refined.rotation_lever_arms), a.cross(refined.information_center - point);
  Eigen::MatrixXd& directions = refined.degenerate_directions;
  if (directions.rows() != 6) directions.resize(6, 0);
  d -= directions * (directions.transpose() * d);
  const double norm = d.norm();
  if (norm > 1e-9 * (a.cwiseProduct(refined.rotation_lever_arms).norm() + 1e-300)) {
    directions.conservativeResize(6, directions.cols() + 1);
    directions.col(directions.cols() - 1) = d / norm;
  }
  refined.num_degenerate = static_cast<int>(directions.cols());
  for (int i = 0; i < 6; ++i) {
    refined.degenerate_axes[i] = directions.row(i).squaredNorm() > 0.5;
  }
  refined.valid = false;
  absl::StrAppend(&refined.failure_reason, refined.failure_reason.empty() ? "" : "; ",
                  "degenerate geometry: ", why);
}

}  // namespace rpsr::core
