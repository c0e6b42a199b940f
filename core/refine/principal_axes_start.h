// Starts from the clouds' principal frames (issue 5). An object whose network estimate is tens of
// degrees off lies beyond every start the registrar derives from that estimate (the turns about a
// round axis, the centres put together, the steps along the weakest direction), and the
// refinement converges beside it. A real octopus (eight arms about a squat body) came back
// 45-49 degrees off at fitness 0.57, where the truth fits 0.98; a hornbug under jitter 43 degrees
// off. What does not depend on the estimate is each cloud's own frame: the principal axes of its
// points (the root node's covariance) and its centre of mass. Mapping the source's frame onto the
// target's gives a rotation within 3-28 degrees of the truth on those pairs, up to the axes'
// signs: four proper rotations, of which the refinement brought the right one back within 0.8
// degrees (tests/bench/notes/refinement-notes.md, *The principal-axes start*).
//
// PrincipalAxesStarts returns the four, scored by the two-way far fraction of their nodes
// (TwoWayFarNodeFractions: a wrong flip leaves the object's ends without partners), best first,
// so that the registrar refines only the likeliest
// (RegistrationOptions::search_principal_axes_start).
#ifndef RPSR_CORE_REFINE_PRINCIPAL_AXES_START_H_
#define RPSR_CORE_REFINE_PRINCIPAL_AXES_START_H_

#include <vector>

#include "Eigen/Geometry"
#include "core/tree/bh_tree.h"

namespace rpsr::core {

struct PrincipalAxesStart {
  Eigen::Isometry3d T_target_source = Eigen::Isometry3d::Identity();
  // TwoWayFarNodeFractions at the scoring depth (negative: unmeasurable, for all four alike).
  double far_fraction = -1.0;
};

// The source's principal frame mapped onto the target's, for the four sign choices that keep a
// rotation, each with the translation that puts the centres of mass together; sorted by
// far_fraction at `depth` (nodes beyond `far_cells` of that depth), ascending. Empty when either
// tree is empty, a cloud's points span less than a line (two variances zero: no frame), or a half
// turn about one of the target's principal axes maps it near onto itself (its nodes at `depth`
// within 0.9 cells on average, SelfSymmetryOptions::max_self_distance_cells before session 41: the
// signs are not the shape's).
std::vector<PrincipalAxesStart> PrincipalAxesStarts(const Octree& source, const Octree& target,
                                                    int depth, double far_cells);

}  // namespace rpsr::core

#endif  // RPSR_CORE_REFINE_PRINCIPAL_AXES_START_H_
