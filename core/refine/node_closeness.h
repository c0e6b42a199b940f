// How closely a moved source tree's nodes lie to a target tree's nodes of the same depth: the mean
// distance from each source node's centre of mass to the nearest target centre of mass, capped
// (issue 5). The registrar uses it to choose between two starts' answers that fit equally well
// by the refinement's own measures.
//
// Why another measure: fitness and inlier RMSE count a node as fitted when it lies near its
// partner's PLANE, so a pose slid or twisted along a surface (a helix spring turned along its
// screw, a part slid along a flat face) reads as good as the true one. Distances to the nearest
// centre of mass also see the offsets along the surface, and at the finest depth of an object's
// tree (a point or two a cell) the wrong twin leaves more nodes without a close partner. Measured
// on the unseen object study (10 settings x 100 pairs, net+refine's answer against the refinement
// from the identity where they differ, offline on the pairs' points): keeping the closer answer
// would recover 12 of 1,000 pairs (722 -> 734; cap 1, 1.5, 2 and 5 finest cells: 722, 731, 734,
// 736).
#ifndef RPSR_CORE_REFINE_NODE_CLOSENESS_H_
#define RPSR_CORE_REFINE_NODE_CLOSENESS_H_

#include <cstddef>
#include <cstdint>
#include <limits>
#include <vector>

#include "Eigen/Geometry"
#include "core/tree/bh_tree.h"

namespace rpsr::core {

struct NodeClosenessOptions {
  // Distances are capped at this many cell edges of `depth` (a node without a partner that near
  // counts the cap): two cells, searched as the 27 cells of depth - 1 around the moved node.
  // Fixed at 2 by that search.
  static constexpr double kCapCells = 2.0;
  // An even stride over the source's nodes of the depth, at most this many (bounds the cost on
  // a scan's depth 9, ~7,600 nodes in a simulated street scan; 2,048 put the mean within ~1% on
  // objects).
  size_t max_source_nodes = 2048;
  // When set (sized as the level of `depth`): only the source nodes marked 1 are sampled and only
  // the target nodes marked 1 are partners (the structure off a scan's ground,
  // dominant_plane.h). Null: every node. No source node marked, or a mask of the wrong size: not
  // measurable (negative); no target node marked: every source node is far.
  const std::vector<uint8_t>* source_nodes = nullptr;
  const std::vector<uint8_t>* target_nodes = nullptr;
};

// Mean over the source's nodes of `depth` (an even sample) of min(distance from T_target_source *
// CoM to the nearest target CoM of `depth`, cap), in cell edges of the TARGET's `depth`: 0 when
// every node sits on a target node, kCapCells when none has a partner within the cap. Negative
// when it cannot be measured: depth < 1 or beyond either tree, an empty level, or
// max_source_nodes == 0.
double MeanNodeDistanceCells(const Octree& source, const Octree& target,
                             const Eigen::Isometry3d& T_target_source, int depth,
                             const NodeClosenessOptions& options = {});

// Per pose (the target's lookup built once for all): MeanNodeDistanceCells with each sampled
// source node counted by weights[node] (sized as the level of `depth`). Negative where it cannot be
// measured (as MeanNodeDistanceCells), where the weights have the wrong size, or where the
// sampled nodes' weights add up to nothing.
std::vector<double> WeightedMeanNodeDistanceCells(const Octree& source, const Octree& target,
                                                  const std::vector<Eigen::Isometry3d>& poses,
                                                  int depth, const std::vector<double>& weights);

// Per pose (the target's lookup built once for all): the fraction of the same sampled source
// nodes farther than `far_cells` (below kCapCells) from every target CoM of `depth`, the nodes the
// pose leaves without any partner nearby. A near-twin of the answer (a gear turned by a tooth)
// fits the rest alike and differs only there, in the few nodes of the feature that breaks the
// symmetry (symmetry_starts.h). Negative where it cannot be measured (as MeanNodeDistanceCells).
// `stop_above` (a fraction): a pose's count stops once its far nodes alone exceed that fraction of
// the sampled nodes, and its entry is then the fraction counted so far (above `stop_above`, at
// most its own): for a caller that only needs to know which poses stay at or below it
// (TwoWayFarNodeFractionsWithinDrop's candidates that can still qualify, the body-of-revolution
// test's turns).
std::vector<double> FarNodeFractions(const Octree& source, const Octree& target,
                                     const std::vector<Eigen::Isometry3d>& poses, int depth,
                                     double far_cells, const NodeClosenessOptions& options = {},
                                     double stop_above = std::numeric_limits<double>::infinity());

// Per pose: the mean of FarNodeFractions from the source to the target under the pose and from
// the target to the source under its inverse (a feature a wrong pose misplaces is missed on both
// sides, while a node only one cloud sampled is missed on one). Negative where either side cannot
// be measured.
std::vector<double> TwoWayFarNodeFractions(const Octree& source, const Octree& target,
                                           const std::vector<Eigen::Isometry3d>& poses, int depth,
                                           double far_cells);

// An answer's TwoWayFarNodeFractions and its candidates' (steps or twins of the answer), measured
// only as far as the question "which candidate leaves at least `min_drop` less than the answer,
// and least" needs. A candidate's two-way fraction is at least half its way there, so one whose
// way there alone exceeds twice the answer's less the drop cannot qualify: its way there stops
// counting there (FarNodeFractions' stop_above) and its way back is not measured. `candidates`
// reads the exact two-way fraction of every candidate that may qualify and -1 for the others;
// all -1 when the answer, measured first, leaves less than the drop or cannot be measured
// (`answer` negative then). The least qualifying candidate is the same, bit for bit, as
// TwoWayFarNodeFractions of every pose would give.
struct TwoWayFarWithinDrop {
  double answer = -1.0;
  std::vector<double> candidates;
};
TwoWayFarWithinDrop TwoWayFarNodeFractionsWithinDrop(
    const Octree& source, const Octree& target, const Eigen::Isometry3d& answer,
    const std::vector<Eigen::Isometry3d>& candidates, int depth, double far_cells, double min_drop);

// Marks (1) each node of the source's `depth` that lies farther than `far_cells` (below kCapCells)
// from every target CoM of `depth` under all but at most `max_near` of the poses; every node is
// visited (no sampling). With the poses a target's near-symmetries, the marked nodes are the
// feature that breaks the symmetry (a gear's pin, symmetry_starts.h): a node left without a
// partner by sampling alone is rarely left so under nearly every turn. Empty where nothing can
// be measured (as MeanNodeDistanceCells) or without poses.
std::vector<uint8_t> NodesFarUnderAllButFewPoses(const Octree& source, const Octree& target,
                                                 const std::vector<Eigen::Isometry3d>& poses,
                                                 int depth, double far_cells, int max_near);

}  // namespace rpsr::core

#endif  // RPSR_CORE_REFINE_NODE_CLOSENESS_H_
