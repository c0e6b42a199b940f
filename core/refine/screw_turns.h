// Screw near-symmetries (issue 5). A helix spring (a bolt's thread, a spiral stair) maps onto
// itself when turned about its axis AND advanced along it by the pitch's share of the turn; only
// its legs and the coil's ends tell such twins apart. A plain turn about the axis leaves the coil
// a fraction of a pitch above itself, so the round-axis start's turns (TurnsAboutRoundAxes) all
// read worse than an answer tens of degrees off along the screw, and refined from them the
// answer does not slide that far (an unseen spring 44 degrees off at 0.04 confidence was 63% of
// the squared rotation error of 2,000 clean pairs; refinement-notes.md, *The screw turns*).
//
// FindScrewSymmetry registers the target onto itself from a quarter turn about a round principal
// axis, as FindContinuousSymmetry does for bodies of revolution, and reads the motion it ends at
// as a screw (Chasles): the turn's axis, a point on it and the advance along it per radian.
// ScrewTurns gives the screw's turns in steps, each with its advance, as SelfSymmetry entries the
// round-axis start scores beside the plain turns (BestSymmetricTwin).
#ifndef RPSR_CORE_REFINE_SCREW_TURNS_H_
#define RPSR_CORE_REFINE_SCREW_TURNS_H_

#include <optional>
#include <vector>

#include "Eigen/Geometry"
#include "core/refine/symmetry_starts.h"
#include "core/tree/bh_tree.h"

namespace rpsr::core {

struct ScrewOptions {
  // The self-registration must end turned by at least this much (a small turn's axis and advance
  // are noise) ...
  double min_turn_deg = 30.0;
  // ... and advanced along the axis by at least this many cells of SymmetryDepth: less is a plain
  // turn, which TurnsAboutRoundAxes already gives.
  double min_advance_cells = 0.5;
  // ... and the target turned by a quarter of that screw must leave at most this fraction of its
  // nodes at SymmetryDepth without a partner within SelfSymmetryOptions::far_cells
  // (FarNodeFractions): it nearly maps onto itself. Springs whose screw was found about their
  // coil's axis read 0.07-0.29 (the coil's ends and legs), laptops 0.54-0.70 and a stair 0.31,
  // where the self-registration ended at some other motion (unseen clean pairs, seeds 1-5;
  // refinement-notes.md, *The screw turns*).
  double max_far_fraction = 0.3;
};

struct ScrewSymmetry {
  Eigen::Vector3d axis = Eigen::Vector3d::UnitZ();  // unit, target frame
  Eigen::Vector3d point = Eigen::Vector3d::Zero();  // on the axis, nearest the centre of mass
  double advance_per_rad = 0.0;                     // metres along `axis` per radian of turn
};

// The screw `T` is (Chasles' decomposition), its point the axis's nearest to `near`, for a turn of
// at least min_turn_rad; nullopt for a smaller turn, no turn at all, or a non-finite one.
std::optional<ScrewSymmetry> ScrewOf(const Eigen::Isometry3d& T, const Eigen::Vector3d& near,
                                     double min_turn_rad);

// The target's screw near-symmetry about its roundest round principal axis that shows one: the
// target registered onto itself from a quarter turn about that axis (one depth above
// SymmetryDepth, as FindContinuousSymmetry levels an axis) ends at a screw turning by at least
// min_turn_deg and advancing by at least min_advance_cells, and the quarter of that screw leaves
// at most max_far_fraction of the target's nodes without a partner. nullopt otherwise (no round
// axis, a plain turn, another motion, a failed refinement, trees shallower than 2). One lean
// self-registration and one node lookup per round axis tried.
std::optional<ScrewSymmetry> FindScrewSymmetry(const Octree& target,
                                               const ScrewOptions& options = {},
                                               const SelfSymmetryOptions& symmetry = {});

// The screw's turns by k * 360 / n degrees (n = round(360 / step_deg), k = 1 .. n - 1; none for a
// step under a tenth of a degree), each taken
// in (-180, 180] so that it advances by the shorter way), each advanced by advance_per_rad times
// its angle, as SelfSymmetry entries (axis -1: not a principal axis; self_distance_cells -1: not
// checked to be near-symmetries).
std::vector<SelfSymmetry> ScrewTurns(const ScrewSymmetry& screw, double step_deg);

}  // namespace rpsr::core

#endif  // RPSR_CORE_REFINE_SCREW_TURNS_H_
