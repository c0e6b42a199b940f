// Solution remapping for degenerate geometry (issue 5; Zhang, Kaess and Singh, "On degeneracy of
// optimization-based state estimation problems", ICRA 2016): where the refinement's information
// says a direction is unconstrained (a road between guard rails along its length, a plane in its
// own plane, a sphere about its centre), the refined pose's component along it is the drift of
// noise and bias, not a measurement. A caller with a prior (a tracker's constant-velocity guess)
// does better keeping the prior's component there and the refinement's everywhere else.
#ifndef RPSR_CORE_REFINE_DEGENERATE_HOLD_H_
#define RPSR_CORE_REFINE_DEGENERATE_HOLD_H_

#include "Eigen/Geometry"
#include "absl/strings/string_view.h"
#include "core/refine/tree_refinement.h"

namespace rpsr::core {

// `refined.T_target_source` with its motion relative to `prior` (both T_target_source) projected
// off the degenerate directions: the motion D = T prior^-1 is written in the refinement's own
// perturbation (TreeRefinementResult::information: rotation w about information_center, then a
// translation v, in the target frame), the rotation part scaled to metres by the lever arms as the
// directions are, its components along `degenerate_directions` removed, and the remainder applied
// to `prior`. With no degenerate direction it returns refined.T_target_source unchanged.
Eigen::Isometry3d HoldDegenerateDirections(const TreeRefinementResult& refined,
                                           const Eigen::Isometry3d& prior);

// Adds the turn about `axis` through `point` (target frame) to `refined`'s degenerate directions,
// where the information cannot show it (a body of revolution's turn about its axis: its samples
// break the symmetry by chance, so the eigenvalue stays above the threshold): the direction in
// the same units (rotation rows scaled by the lever arms, about information_center), made
// orthonormal to those already there (not added where they span it already); degenerate_axes,
// num_degenerate, valid = false and failure_reason (`why` appended) follow.
// HoldDegenerateDirections then holds that turn at the prior too.
void AddDegenerateTurn(const Eigen::Vector3d& axis, const Eigen::Vector3d& point,
                       absl::string_view why, TreeRefinementResult& refined);

}  // namespace rpsr::core

#endif  // RPSR_CORE_REFINE_DEGENERATE_HOLD_H_
