// Further starts for near-symmetric objects (issue 5). A gear's teeth, a guitar's two faces:
// rotations about one of the object's principal axes map it onto itself except for a small
// feature (a gear's pin), and a refinement that ends a tooth off fits everything but that
// feature. By fitness, inlier RMSE and the nodes' mean distance it fits as well as the truth
// (unseen gears refined from the truth read no better), its confidence is high, and no local
// step crosses a tooth. What tells the twins apart is the feature's few nodes left without any
// partner nearby (FarNodeFraction, node_closeness.h).
//
// FindSelfSymmetries finds the target's near-symmetries on its tree alone: the half turn about
// each principal axis through the centre of mass, and, about an axis around which the spread is
// round (its two other principal variances alike, as an n-fold symmetry needs), the turns by
// k/n of a circle for the n whose circular harmonic of the finest nodes' angles is strongest;
// each kept when the turned target's nodes lie as near its own as a twin's do.
// BestSymmetricTwin then turns the answer by each and returns the turn that leaves the fewest
// source nodes without a partner, when it leaves clearly fewer than the answer.
#ifndef RPSR_CORE_REFINE_SYMMETRY_STARTS_H_
#define RPSR_CORE_REFINE_SYMMETRY_STARTS_H_

#include <optional>
#include <vector>

#include "Eigen/Geometry"
#include "core/tree/bh_tree.h"

namespace rpsr::core {

struct SelfSymmetryOptions {
  // A turn is a near-symmetry when the turned target's nodes one depth above the finest lie at
  // most this far from its own on average, in cells (MeanNodeDistanceCells: 0 unturned; a gear
  // turned by a tooth 0.77-0.88 on 1,024-point objects to depth 6, between teeth ~1.1; a generic
  // object half turned 1.0-1.7).
  double max_self_distance_cells = 0.9;
  // An axis is round when its two other principal variances are within this ratio.
  double min_round_ratio = 0.8;
  // Folds tried about a round axis (circular harmonics 3..max_folds).
  int max_folds = 36;
  // A twin of the answer is tried when it leaves at least this fraction of the source's nodes
  // (one depth above the finest) fewer without a partner within far_cells than the answer does.
  double far_cells = 1.5;
  double min_far_fraction_drop = 0.008;
};

struct SelfSymmetry {
  // The rotation in the target's frame, about the target's centre of mass.
  Eigen::Isometry3d S = Eigen::Isometry3d::Identity();
  int axis = 0;  // principal axis, 0 = the smallest variance
  double angle_deg = 0.0;
  double self_distance_cells = 0.0;
};

// The target's near-symmetries other than the identity; empty for trees shallower than 2.
std::vector<SelfSymmetry> FindSelfSymmetries(const Octree& target,
                                             const SelfSymmetryOptions& options = {});

struct SymmetricTwin {
  Eigen::Isometry3d T_target_source = Eigen::Isometry3d::Identity();
  double far_fraction = 0.0;         // of the twin
  double answer_far_fraction = 0.0;  // of the answer
};

// Among S * answer for the given symmetries, the one with the fewest far source nodes, when
// fewer than the answer's by min_far_fraction_drop; nullopt otherwise.
std::optional<SymmetricTwin> BestSymmetricTwin(const Octree& source, const Octree& target,
                                               const Eigen::Isometry3d& answer,
                                               const std::vector<SelfSymmetry>& symmetries,
                                               const SelfSymmetryOptions& options = {});

// The mean of the fractions of the source's nodes far from the target's under T and of the
// target's far from the source's (a feature the twin misplaces is missed on both sides).
double TwoWayFarFraction(const Octree& source, const Octree& target, const Eigen::Isometry3d& T,
                         const SelfSymmetryOptions& options = {});

// The depth both use: one above the shallower tree's deepest (at least 1).
int SymmetryDepth(const Octree& source, const Octree& target);

}  // namespace rpsr::core

#endif  // RPSR_CORE_REFINE_SYMMETRY_STARTS_H_
