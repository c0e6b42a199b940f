#include "core/refine/degenerate_hold.h"

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

}  // namespace rpsr::core
