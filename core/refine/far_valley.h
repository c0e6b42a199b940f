// A move along the answer's weakest direction to the middle of the valley in the count of nodes
// that lack a partner (issue 5).
//
// A helix spring turned along its screw by 5-15 degrees fits its coil as well as at the truth;
// what tells the two apart is its legs and the wire's ends, a few nodes that the screw moves off
// the other cloud. Counted along the weakest direction (TwoWayFarNodeFractions one depth above the
// finest), the nodes left without a partner form a valley a few cells wide around the truth whose
// walls rise on both sides as a leg moves off. The valley's floor is a node or two of sampling
// noise, flat, so where its least value lies says little (a first version that took the middle of
// the steps within two nodes of the least moved right springs under the slightest noise 4-5
// degrees off); the walls are steep and well placed, so the middle between them, where they have
// risen a fifth of the way, is what is read. On the clean springs of 20 draws of 100 that ended
// 4.7-15 degrees off along the screw it lay 0.4-3.3 degrees from the truth
// (tests/bench/notes/refinement-notes.md, *The far-count valley*), where the weak-direction
// chamfer's own measure had moved two of them further off (seed 14's pair 97 8.4 -> 14.9 degrees).
//
// FarValleyAlongWeakestDirection steps the answer along that direction (StepAlongWeakestDirection)
// and returns the valley's middle when both walls rise within the search and the middle is far
// enough from the answer to be more than the estimate's own spread; the registrar measures the
// moved answer without refining (RegistrationOptions::search_far_valley).
#ifndef RPSR_CORE_REFINE_FAR_VALLEY_H_
#define RPSR_CORE_REFINE_FAR_VALLEY_H_

#include <optional>

#include "Eigen/Geometry"
#include "core/refine/tree_refinement.h"
#include "core/refine/weak_direction_chamfer.h"
#include "core/tree/bh_tree.h"

namespace rpsr::core {

struct FarValleyOptions {
  // The steps: -reach_cells .. +reach_cells in step_cells, cell edges of the `depth` of the
  // matched points' RMS motion (StepAlongWeakestDirection). A spring 15 degrees off lay 2.5 cells
  // one depth above the finest from its truth.
  double reach_cells = 6.0;
  double step_cells = 0.25;
  // Nodes farther than this (cells of `depth`) from every node of the other cloud are without a
  // partner (SelfSymmetryOptions::far_cells, as the twins are counted).
  double far_cells = 1.9;
  // The valley: the steps, contiguous with the least one, whose fraction lies within wall_share of
  // the way from the least up to the highest (the walls, where the legs have moved off), and at
  // least floor_tolerance above the least (a node or two of the ~700 one depth above the finest of
  // a 1,024-point object).
  double wall_share = 0.2;
  double floor_tolerance = 0.002;
  // The valley must span at least this many cells (one of a step or two is the least value's
  // sampling, not a stretch the legs bound) ...
  double min_valley_cells = 1.0;
  // ... and its middle lie at least this far from the answer (a move within the estimate's own
  // spread would only add noise). With the first version's floor the middle strayed up to three
  // quarter-cells, and at half a cell 11 right springs of the 20 draws' 2,000 clean pairs were
  // moved 1.8-3.6 degrees off; read between the walls it strays less: at a cell the 20 draws
  // read 0.519 degree and the study won 4 answers and lost 1, at half a cell 0.479 (9 won, 2
  // lost) and the study won 33 more and lost 9 more (refinement-notes.md, *The far-count
  // valley*).
  double min_move_cells = 0.5;
  // Only where at most this fraction of the target's nodes (at `depth`) lie farther than far_cells
  // from every source node at the answer: a source cut short lacks one of the walls, and the
  // valley's middle moves. Without this gate the unseen study's seeds 1-5 lost 3 right springs
  // under crops of 10-30% (0.3-1.0 -> 4.7-5.8 degrees), whose answers left 0.08, 0.17 and 0.26
  // uncovered; but a clean spring 10-12 degrees off leaves its legs uncovered too (0.063 and 0.075
  // on the 20 draws' two worst), so the gate stops at a tenth, and the crop of 10% is not told
  // apart.
  double max_uncovered_fraction = 0.1;
  // Only where the weakest direction's normalised information eigenvalue is at least this (the
  // weak-direction chamfer's gate, WeakChamferOptions: springs 0.12-0.27; a nearly unconstrained
  // direction, a blob's turn or a laptop's hinge, leaves no feature to raise a wall).
  double min_weakest_eigenvalue = WeakChamferOptions{}.min_weakest_eigenvalue;
};

struct FarValleyMove {
  Eigen::Isometry3d T_target_source = Eigen::Isometry3d::Identity();
  double move_cells = 0.0;      // signed, along the weakest direction
  double valley_cells = 0.0;    // the valley's span
  double least_fraction = 0.0;  // its floor's least two-way far fraction
  double answer_fraction = 0.0;
};

// The answer moved along its weakest direction to the middle of the far-count valley, or nullopt:
// no weakest direction, the direction too weakly constrained, the depth not in both trees, the
// target not covered by the source, the answer's own count unmeasurable, a wall not within the
// reach, or a valley too narrow or its
// middle too near the answer (options above).
std::optional<FarValleyMove> FarValleyAlongWeakestDirection(const Octree& source,
                                                            const Octree& target,
                                                            const TreeRefinementResult& answer,
                                                            int depth,
                                                            const FarValleyOptions& options = {});

}  // namespace rpsr::core

#endif  // RPSR_CORE_REFINE_FAR_VALLEY_H_
