// A start along the refined answer's weakest direction (issue 5). A helix spring turned about its
// axis by a few degrees, slid along its screw, fits nearly as well as the truth: the residuals
// are plane-to-plane, and a coil's surface runs along the screw, so the cost's basin there is
// shallow and wide and the refinement stops where the network's start put it (unseen springs
// ended 0.75-7.2 degrees off, where refining from the truth ends 1.2-2). The information matrix
// names that direction (its smallest eigenvalue once rotation is scaled to metres by the lever
// arms), and what tells the truth from the answer there is not the fit to the planes but the
// nodes left without any partner nearby: the coil ends and the turns of the wire the twist
// misplaces.
//
// BestWeakDirectionStart steps the answer along that direction by a few finest cells either way
// and scores each step by the two-way far fraction (TwoWayFarNodeFractions); the step that
// leaves clearly fewer nodes without a partner than the answer is the start the registrar
// refines (RegistrationOptions::search_weak_direction_start).
#ifndef RPSR_CORE_REFINE_WEAK_DIRECTION_START_H_
#define RPSR_CORE_REFINE_WEAK_DIRECTION_START_H_

#include <optional>
#include <vector>

#include "Eigen/Geometry"
#include "core/refine/tree_refinement.h"
#include "core/tree/bh_tree.h"

namespace rpsr::core {

struct WeakDirectionOptions {
  // Steps along the weakest direction, in cell edges of the target's `depth` of the RMS motion
  // of the matched points; each is tried with both signs. An unseen spring's answer lay 2-3
  // cells of the depth above the finest off along it.
  std::vector<double> steps_cells = {0.5, 1.0, 1.5, 2.0, 3.0};
  // Nodes of `depth` farther than this (cells, below NodeClosenessOptions::kCapCells) from every
  // node of the other cloud are without a partner. One depth above the finest (the registrar's
  // SymmetryDepth), 1.5 cells read a higher mean recall on all three study seeds than 1.9 (the
  // twins' far_cells); 1.25 was mixed (seed 2 lower, seed 3's clean rotation RMSE 1.04 -> 1.65)
  // (refinement-notes.md, *Steps along the weakest direction*).
  double far_cells = 1.5;
  // The best step must leave at least this fraction fewer nodes without a partner (the twins'
  // min_far_fraction_drop).
  double min_far_fraction_drop = 0.008;
  // The registrar's second round, at the finest depth, when the round at SymmetryDepth kept
  // nothing (RegistrationOptions::weak_direction_finest_round, off by default: objects take about
  // a quarter longer): only for answers whose source nodes scatter about the target's surface by a
  // median of at most finest_max_scatter_cells finest cells
  // (TreeRefinementResult::surface_scatter_cells) and whose fitness is at least finest_min_fitness.
  // At the finest depth a node of an object's 1,024-2,048 points is a point or two, so under noise,
  // jitter, outliers or a crop a node lacks a partner by sampling alone, and an ungated round lost
  // more answers than it won on the unseen study's seed 1 (9 won, 13 lost). Chosen on seed 1
  // (0.28-0.30 and 0.97-0.98 read the same), checked on seeds 2 and 3 (refinement-notes.md, *A
  // finest round for clean, whole answers*). The scatter is measured by the refinement's noise
  // polish (TreeRefinementOptions::noise_polish): without it the round never runs.
  double finest_max_scatter_cells = 0.3;
  double finest_min_fitness = 0.98;

  // Whether an answer with this surface scatter (finest cells; negative: not measured) and
  // fitness is inside the finest round's gate.
  bool FinestRoundAdmits(double surface_scatter_cells, double fitness) const {
    return surface_scatter_cells >= 0.0 && surface_scatter_cells <= finest_max_scatter_cells &&
           fitness >= finest_min_fitness;
  }
};

struct WeakDirectionStart {
  Eigen::Isometry3d T_target_source = Eigen::Isometry3d::Identity();
  double step_cells = 0.0;           // signed
  double far_fraction = 0.0;         // of the step
  double answer_far_fraction = 0.0;  // of the answer
};

// `answer.T_target_source` moved along the weakest direction of `answer.information` by
// `step_m` metres of RMS point motion: the direction's rotation part (about information_center,
// scaled by rotation_lever_arms) and translation part applied in the target frame, as
// TreeRefinementResult::information's perturbation is written. The answer itself where the
// information is empty.
Eigen::Isometry3d StepAlongWeakestDirection(const TreeRefinementResult& answer, double step_m);

// StepAlongWeakestDirection for each of `steps_m`, with one eigen-decomposition of the information
// for all (a search along the direction asks for dozens of steps); empty where the information
// has no weakest direction.
std::vector<Eigen::Isometry3d> StepsAlongWeakestDirection(const TreeRefinementResult& answer,
                                                          const std::vector<double>& steps_m);

// The step (options.steps_cells, both signs) whose two-way far fraction at `depth` is least, when
// it is at least min_far_fraction_drop below the answer's; nullopt otherwise, when the information
// has no direction to step along, or when nothing can be measured at `depth`.
std::optional<WeakDirectionStart> BestWeakDirectionStart(const Octree& source, const Octree& target,
                                                         const TreeRefinementResult& answer,
                                                         int depth,
                                                         const WeakDirectionOptions& options = {});

}  // namespace rpsr::core

#endif  // RPSR_CORE_REFINE_WEAK_DIRECTION_START_H_
