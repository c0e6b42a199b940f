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
  const Eigen::Vector3d& c = refined.information_center;
  const Eigen::Isometry3d motion = refined.T_target_source * prior.inverse();
  // motion = [exp(w) | c - exp(w) c + v], the perturbation TreeRefinementResult::information
  // is written for.
  const Eigen::AngleAxisd turn(motion.linear());
  const Eigen::Vector3d w = turn.angle() * turn.axis();
  const Eigen::Vector3d v = motion.translation() - c + motion.linear() * c;
  Eigen::Matrix<double, 6, 1> u;  // in the directions' units: metres throughout
  u << w.cwiseProduct(refined.rotation_lever_arms), v;
  u -= directions * (directions.transpose() * u);
  const Eigen::Vector3d kept_w = u.head<3>().cwiseQuotient(refined.rotation_lever_arms);
  const Eigen::Vector3d kept_v = u.tail<3>();
  Eigen::Isometry3d kept = Eigen::Isometry3d::Identity();
  const double angle = kept_w.norm();
  if (angle > 0.0) kept.linear() = Eigen::AngleAxisd(angle, kept_w / angle).toRotationMatrix();
  kept.translation() = c - kept.linear() * c + kept_v;
  return kept * prior;
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
