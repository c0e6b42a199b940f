#include "core/refine/screw_turns.h"

#include <cmath>

#include "Eigen/SVD"
#include "core/refine/cell_index.h"
#include "core/refine/node_closeness.h"
#include "core/refine/tree_refinement.h"

namespace rpsr::core {

std::optional<ScrewSymmetry> ScrewOf(const Eigen::Isometry3d& T, const Eigen::Vector3d& near,
                                     double min_turn_rad) {
  const Eigen::AngleAxisd turn(T.linear());
  // No turn at all has no axis (and its advance per radian no value).
  if (!(turn.angle() >= min_turn_rad) || !(turn.angle() > 0.0) || !turn.axis().allFinite() ||
      !T.translation().allFinite()) {
    return std::nullopt;
  }
  ScrewSymmetry screw;
  screw.axis = turn.axis().normalized();
  const double advance = screw.axis.dot(T.translation());
  screw.advance_per_rad = advance / turn.angle();
  // The axis's points p satisfy (I - R) p = t - advance * axis; (I - R) is singular along the
  // axis only, so the least-norm correction from `near` lies across it: the nearest point.
  const Eigen::Matrix3d across = Eigen::Matrix3d::Identity() - T.linear();
  const Eigen::Vector3d residual = T.translation() - advance * screw.axis - across * near;
  screw.point = near + across.jacobiSvd(Eigen::ComputeFullU | Eigen::ComputeFullV).solve(residual);
  // A rotation a refinement returned is orthonormal only to rounding, so the solve may keep a
  // little of the axis's own direction: the point is put back at the foot of `near`.
  screw.point -= screw.axis * screw.axis.dot(screw.point - near);
  if (!screw.point.allFinite()) return std::nullopt;
  return screw;
}

std::optional<ScrewSymmetry> FindScrewSymmetry(const Octree& target, const ScrewOptions& options,
                                               const SelfSymmetryOptions& symmetry) {
  if (target.max_depth() < 2 || target.num_points() == 0) return std::nullopt;
  const PrincipalAxes principal = PrincipalAxesOf(target, symmetry);
  const int depth = SymmetryDepth(target, target);
  const double cell = CellEdge(target, depth);
  TreeRefinementCache cache;  // the target's cells and shapes, once for every axis tried
  for (int axis : RoundAxesRoundestFirst(principal)) {
    const absl::StatusOr<TreeRefinementResult> refined =
        SelfRegisteredFromQuarterTurn(target, principal.centre, principal.axes.col(axis), cache);
    // As for a body of revolution's axis: read when valid or invalid only for degenerate
    // directions (a spring's coil leaves its screw itself unconstrained).
    if (!refined.ok() || !(refined->valid || refined->num_degenerate > 0)) continue;
    std::optional<ScrewSymmetry> screw =
        ScrewOf(refined->T_target_source, principal.centre, options.min_turn_deg * M_PI / 180.0);
    if (!screw.has_value()) continue;
    const double advance = screw->axis.dot(refined->T_target_source.translation());
    if (!(std::abs(advance) >= options.min_advance_cells * cell)) continue;
    const std::vector<SelfSymmetry> quarter = ScrewTurns(*screw, 90.0);  // +90, 180, -90
    const double far =
        FarNodeFractions(target, target, {quarter.front().S}, depth, symmetry.far_cells).front();
    if (far >= 0.0 && far <= options.max_far_fraction) return screw;
  }
  return std::nullopt;
}

std::vector<SelfSymmetry> ScrewTurns(const ScrewSymmetry& screw, double step_deg) {
  std::vector<SelfSymmetry> turns;
  // At least a tenth of a degree (a smaller step would ask for millions of turns).
  if (!(step_deg >= 0.1)) return turns;
  const int steps = static_cast<int>(std::lround(360.0 / step_deg));
  for (int k = 1; k < steps; ++k) {
    double angle = 2.0 * M_PI * k / steps;
    if (angle > M_PI) angle -= 2.0 * M_PI;
    Eigen::Isometry3d S = TurnAbout(screw.point, screw.axis, angle);
    S.pretranslate(screw.advance_per_rad * angle * screw.axis);
    turns.push_back({S, -1, angle * 180.0 / M_PI, -1.0});
  }
  return turns;
}

}  // namespace rpsr::core
