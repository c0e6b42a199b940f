// The registration pipeline (issue 5): one call that returns the best pose rpsr can give and says
// how far to trust it. Network (core/net) -> refinement on the trees (core/refine) -> calibrated
// confidence (core/registrar/confidence_model.h).
//
// Plain C++ and Eigen only: LibTorch stays behind RpsrNet's pimpl, so the server and the client
// compile against this header without it.
//
// Conventions: T_target_source maps source points into the target frame
// (core/data/transform_convention.h); metres (the clouds' units), radians, seconds.
#ifndef RPSR_CORE_REGISTRAR_REGISTRAR_H_
#define RPSR_CORE_REGISTRAR_REGISTRAR_H_

#include <array>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "Eigen/Core"
#include "Eigen/Geometry"
#include "absl/status/statusor.h"
#include "absl/strings/string_view.h"
#include "absl/types/span.h"
#include "core/refine/dominant_plane.h"
#include "core/refine/symmetry_starts.h"
#include "core/refine/tree_refinement.h"
#include "core/tree/bh_tree.h"

namespace rpsr::core {

class RpsrNet;
class ConfidenceModel;

// What a registration runs, so users can compare and fall back.
enum class RegistrationMode {
  kNet,        // the network alone
  kNetRefine,  // the network, then refinement on the trees from its estimate (the default)
  kRefine,     // refinement alone, from identity or the caller's initial guess
};
// "net", "net+refine", "refine"; InvalidArgument naming the accepted values otherwise.
absl::StatusOr<RegistrationMode> ParseRegistrationMode(absl::string_view name);
absl::string_view RegistrationModeName(RegistrationMode mode);

// net+refine's default network passes (fewer if the model has fewer). The refinement finishes
// what the network's last pass leaves, so a third pass buys little there while it costs a sixth
// of an object pair's time. Measured, 3 passes against 2 (and 1), same pairs: unseen object
// study (`rpsr eval --protocol objects --split unseen --study --count 100`), mean recall at
// (1 deg, 0.01) over the 21 settings 0.713 vs 0.724 (0.718), 25.2 vs 21.3 (16.3) ms a pair; the
// same with `--count 200 --seed 2`: 0.724 vs 0.716; the confidence's held-out set (rpsr calibrate
// --evaluate, objects of all splits and settings, (1 deg, 1%)): 730 vs 715 of 1,008; 128
// simulated LiDAR pairs 5 and 10 frames apart, (1 deg, 0.3 m): 111 vs 114 (113); held-out LiDAR
// 102 vs 104 of 128; the KITTI-style K1/K2 pairs 1.000 / 1.000 either way. Pooled over the
// object sets, 2 passes lose about 0.4% of the pairs for 16% of the time. Two rather than one:
// the confidence reads how much the last pass still moved (ConfidenceFeatureVector), which one
// pass cannot say. A caller who wants the third pass asks for it (passes = 3). Since session 32
// the passes after the first run only for an unconfident first answer
// (RegistrationOptions::later_passes_only_when_unconfident), so a confident pair pays one pass
// and its confidence is read without a last-pass change (one pass alone, every answer's, had
// lost recall on two of three seeds: evaluation-notes.md).
inline constexpr int kNetRefinePasses = 2;

struct RegistrationOptions {
  RegistrationMode mode = RegistrationMode::kNetRefine;
  // Network passes; <= 0: the mode's default, DefaultPasses (net: the model's own,
  // RpsrNetConfig::passes; net+refine: at most kNetRefinePasses).
  int passes = 0;
  // net+refine with more than one pass: the first pass's estimate is refined first, and the
  // later passes run (from that estimate) only when that answer's confidence is below 0.9; their
  // estimate is then refined as a further start ("network_later_passes"), which replaces the
  // first answer unless that one is clearly better or, fitting alike, closer: the usual rule
  // with the roles swapped, since the later
  // answer is what every pass first would have returned. An answer confident after one pass
  // skips a pass (about a sixth of an object pair's time; its confidence features read no
  // last-pass change, and the calibration is fitted on this pipeline); an unconfident one gets
  // both passes' estimates as starts. false: every pass first, one start from the last (the
  // pipeline before session 32). Figures: tests/bench/notes/evaluation-notes.md, *The later
  // passes only for an unconfident first answer*.
  bool later_passes_only_when_unconfident = true;
  // A starting guess of T_target_source. The network starts from it (its passes estimate the
  // remaining motion); `refine` starts from it (identity when absent).
  std::optional<Eigen::Isometry3d> initial_T_target_source;
  // net+refine: when the answer refined from the network's estimate has a confidence below 0.9,
  // also refine from the initial guess (identity when absent) and keep that answer if it is
  // clearly better (valid where the first is not, or 1% more of the source overlapping), so that
  // a network estimate worse than the caller's guess (a scan pair with little motion, a model off
  // its training distribution) rarely makes the answer worse than `refine`; it can still be (a
  // confident wrong first answer, or two fits of equal overlap). Skipped when the two starts
  // nearly coincide. The confidence of either answer comes from the same model, calibrated on
  // this pipeline (its features include the network's, whichever start won).
  bool also_refine_from_initial = true;
  // net+refine on scene-scale trees (deep enough for the refinement's finer start: LiDAR scans):
  // when the answer is still below 0.9 confidence after those starts, search a start around the
  // initial guess (FindCorrelativeStart: turns about z within +-20 degrees, shifts within +-22.5 m
  // on a 240 m cube, scored by occupied cells; ~4 ms) and refine from it too, keeping that answer
  // if it is clearly better. The object network is no LiDAR network and the refinement's basin
  // does not hold every motion of 10 m: on 64 simulated LiDAR pairs 10 frames apart recall at
  // (1 deg, 0.3 m) went 0.781 -> 0.938, on 64 pairs 5 frames apart it stayed 1.000. When the
  // answer is still not confident, the same search over every turn about z (9-degree steps, ~5
  // ms) gives one more start, refined when it turns beyond +-20 degrees and scores 1.5 times the
  // narrower search's best (a vehicle turning at a junction: 40-70 degrees in 10 frames).
  bool search_scene_start = true;
  // net+refine on object-scale trees whose target has near-symmetries (FindSelfSymmetries,
  // core/refine/symmetry_starts.h: a gear's teeth): each cloud's nodes that break the symmetry
  // (a gear's pin: those its turns leave without a partner) are found, and the answer turned by
  // the symmetry under which they meet clearly better (TwinMatchingBreakingNodes) is refined
  // too, and kept when, refined, they still do and its fitness is within 0.05 of the answer's. A
  // refinement that ends a tooth off fits all but the feature that breaks the symmetry, and no
  // local step crosses a tooth. Unseen objects, ten settings of 100 pairs, seeds 1 / 2 / 3: mean
  // recall at (1 deg, 0.01) 0.804 / 0.777 / 0.793 -> 0.805 / 0.811 / 0.812, 54 answers a tooth
  // off brought back and none of the 3,000 turned wrong (tests/bench/notes/refinement-notes.md,
  // *The features that break a symmetry*). Targets without near-symmetries pay nothing.
  bool try_symmetric_starts = true;
  // net+refine on object-scale trees whose answer is still not confident and whose target has a
  // round principal axis but no near-symmetry: the answer turned about that axis by every
  // multiple of 15 degrees is scored by the nodes it leaves without a partner
  // (TurnsAboutRoundAxes, BestSymmetricTwin), and the best, when it leaves clearly fewer, is
  // refined as a further start and settled by the usual rule. A cup (a cylinder with a small
  // tab) whose network start is ~20 degrees off about its body ends there: the tab's few nodes
  // give a local step nothing to climb, while the turned pose that meets them fits better.
  bool search_round_axis_start = true;
  // With search_round_axis_start, where the target maps nearly onto itself under a screw about a
  // round axis (FindScrewSymmetry: a helix spring, a thread), the screw's turns by every multiple
  // of 15 degrees, each advanced by its share of the pitch (ScrewTurns), are scored beside the
  // plain turns. A plain turn leaves a coil a fraction of a pitch above itself, so none read
  // better than an answer tens of degrees off along the screw: an unseen spring 44 degrees off at
  // 0.04 confidence was 63% of 2,000 clean pairs' squared rotation error, and comes back to 0.12
  // (refinement-notes.md, *The screw turns*). Costs one lean self-registration of the target per
  // round axis tried (one, on most round targets) where the start runs. Proto
  // RegisterOptions.screw_turns, CLI --screw_turns.
  bool round_axis_screw_turns = true;
  // net+refine on object-scale trees whose target has no near-symmetry nor is a body of
  // revolution, whatever the confidence, answers fitting 0.95 or less: the answer turned by a half
  // turn about one of the target's principal axes (HalfTurnsAboutPrincipalAxes) where that leaves
  // about as few nodes without a partner as the answer (the target nearly maps onto itself: a
  // guitar flipped front to back), refined as a further start and kept only when it fits clearly
  // better by a wide margin (fitness 0.05 more and 0.85 at least, finest nodes 5% closer). A
  // flipped guitar fits all but its neck and bridge and read 0.985 confident 180 degrees off; under
  // crops and outliers the wrong flip often fits a percent or two better, hence the margins
  // (refinement-notes.md, *The half-turn start*). Proto RegisterOptions.half_turn_start, CLI
  // --half_turn_start.
  bool search_half_turn_start = true;
  // net+refine on object-scale trees under the weak-direction chamfer's gates (no near-symmetry,
  // not a body of revolution, answers below 0.95 confident fitting 0.98 or more, not noise
  // polished, the weakest direction still constrained), where the source leaves at most a tenth of
  // the target's nodes without a partner (a crop takes a wall with it): after the chamfer, the
  // answer moved along its weakest direction to the middle of the valley in the count of nodes
  // (one depth above the finest) without a partner, when both its walls rise within 6 cells, it
  // spans a cell or more and its middle lies half a cell or more away
  // (FarValleyAlongWeakestDirection), measured there and kept when it fits as well; its confidence
  // is at most the answer's. Clean helix springs 2-15 degrees off along their screw (two of them
  // moved there by the chamfer's measure) come back, most to within 1.5 degrees: 2,000 clean
  // unseen pairs 0.763 -> 0.479 degree RMSE (refinement-notes.md, *The far-count valley*). Proto
  // RegisterOptions.far_valley, CLI --far_valley.
  bool search_far_valley = true;
  // net+refine on object-scale trees whose target has no near-symmetry (nor is a body of
  // revolution), whatever the confidence: the answer stepped 0.5-3 cells (one depth above the
  // finest) either way along its information's weakest direction (a spring's screw, a slide
  // along a flat face) is scored by the two-way fraction of nodes it leaves without a partner
  // within 1.5 cells (BestWeakDirectionStart, core/refine/weak_direction_start.h); the best, when
  // it leaves at least 0.008 fewer, is refined, and kept when, refined, it still does and its
  // fitness is within 0.05 of the answer's. Plane-to-plane residuals barely see a coil turned
  // along its screw: unseen springs ended 0.75-7.2 degrees off, at confidence up to 0.94. Unseen
  // study (21 settings of 100 pairs), seeds 1 / 2 / 3: mean recall at (1 deg, 0.01) 0.8462 /
  // 0.8519 / 0.8543 -> 0.8543 / 0.8610 / 0.8586, 47 answers won and 2 lost, answers at 0.9 or
  // more beyond (5 deg, 0.05) 21 -> 13; objects ~1.5 ms more a pair (registrar_bench,
  // BM_RegisterWeakDirectionStart): refinement-notes.md, *Steps along the weakest direction*.
  bool search_weak_direction_start = true;
  // net+refine on object-scale trees whose answer is not confident (or, since session 41, is but
  // overlaps below 0.97; see the end of this comment): when the answer leaves the
  // source's centre of mass more than half a cell (one depth above the finest) from the target's,
  // the answer's rotation with the translation that puts the two centres together is refined too.
  // A whole object's two scans share their centre of mass whatever the sampling; an answer that
  // fits a part well and the rest less (a gear turned about a point of its rim, 8.9 degrees and
  // 0.14 off at fitness 0.978) is then pulled back where the refinement's basin holds the truth.
  // Unseen study (21 settings of 100 pairs), seeds 1 / 2 / 3: mean recall at (1 deg, 0.01) 0.8543
  // / 0.8610 / 0.8586 -> 0.8571 / 0.8643 / 0.8648, 31 answers won and 5 lost, clean rotation RMSE
  // of seed 3 1.04 -> 0.53 degrees: refinement-notes.md, *The centroid-aligned start*. Its answers
  // are taken by the usual rule between starts (clearly better fitness, or closer nodes). A
  // confident answer gets it too where it overlaps below 0.97 and leaves the centres more than 2
  // cells apart, kept only when the refined start overlaps at least 0.97 and clearly better (a
  // sofa slid along its length by 0.217 read 0.989 confident; session 41).
  bool search_centroid_start = true;
  // net+refine on object-scale trees whose answer is valid, fits under 80% of the source and is
  // still below 0.5 confident after the starts above: the source's principal frame mapped onto
  // the target's (four sign choices, centres together; none when a half turn maps the target onto
  // itself; core/refine/principal_axes_start.h), the two leaving the fewest nodes without a
  // partner refined, one kept when it fits clearly better and reads at least 0.5 and 0.1 more
  // confident. The one start that does
  // not come from the network's estimate: an estimate tens of degrees off (a real octopus, 45-49
  // degrees) lies beyond the others'. Unseen study, seeds 1 / 2 / 3: one answer won (45.6 ->
  // 0.78 degrees under 40% outliers), none lost, no other answer changed; 12 real meshes never
  // seen before: 6 of 600 answers won, none lost: refinement-notes.md, *The principal-axes start*.
  // Proto RegisterOptions.principal_axes_start, CLI --principal_axes_start.
  bool search_principal_axes_start = true;
  // With search_weak_direction_start, when its round kept nothing: the same round once more at the
  // finest depth, for answers that scatter little about the target's surface and overlap nearly
  // whole (WeakDirectionOptions::finest_max_scatter_cells, finest_min_fitness), where a few
  // degrees along a screw move a coil's ends by a cell. Off by default: on the unseen study, seeds
  // 1 / 2 / 3, mean recall 0.8543 / 0.8610 / 0.8586 -> 0.8552 / 0.8633 / 0.8605 (15 answers won,
  // 4 lost) and seed 1's clean rotation RMSE 0.84 -> 0.73 degrees, for objects of 2,048 points
  // 14.6 -> 18.1 ms a pair (registrar_bench, BM_RegisterWeakDirectionStart weak:1 -> weak:2):
  // refinement-notes.md, *A finest round for clean, whole answers*. The scatter is the noise
  // polish's measure: with refinement.noise_polish off the round never runs. Proto
  // RegisterOptions.weak_direction_finest_round, CLI --weak_direction_finest_round.
  bool weak_direction_finest_round = false;
  // net+refine on object-scale trees without near-symmetries or a round axis, after the starts
  // above, answers below 0.95 confident (laptops slid along their hinge read 0.38-0.90; a right
  // answer on a real hand at 0.985 was moved off by its fingertips' ends): the answer
  // moved along its weakest direction until the two clouds' outermost nodes at the finest depth
  // agree, when both ends ask for the same step (core/refine/extent_slide.h), measured there
  // without refining (the cost is flat along that direction: refined at the finest depth alone
  // from the moved pose, the laptops looked at stayed there) and kept when valid and fitting
  // within 0.05 of the answer. Unseen study (21 settings x 100 pairs), seeds 1 / 2 / 3: mean
  // recall at (1 deg, 0.01) 0.8567 / 0.8648 / 0.8657 -> 0.8695 / 0.8729 / 0.8814 (84 answers
  // won, 7 lost, under noise, outliers, crops and jitter), clean translation RMSE 0.0070 / 0.0075
  // / 0.0088 -> 0.0034 / 0.0023 / 0.0041; held-out calibration set objects net+refine 851 -> 862
  // of 1,008 within (1 deg, 1%): refinement-notes.md, *The extent slide*. Proto
  // RegisterOptions.extent_slide, CLI --extent_slide.
  bool search_extent_slide = true;
  // net+refine on object-scale trees without near-symmetries or a round axis, valid answers below
  // 0.95 confidence that overlap almost wholly (fitness 0.98 or more), that the noise polish left
  // alone and whose weakest direction is still constrained (normalised eigenvalue 0.1 or more;
  // core/refine/weak_direction_chamfer.h):
  // the answer moved along that direction to where the nodes the motion moves across their
  // surface meet the other cloud best (a spring turned along its screw, whose legs and wire ends
  // pin it), measured there without refining and kept when valid and fitting within 0.05 of the
  // answer; its confidence is at most the answer's. Unseen study seeds 1 / 2 / 3: clean rotation
  // RMSE 0.795 / 0.767 / 0.533 -> 0.561 / 0.619 / 0.244 degrees, mean recall at (1 deg, 0.01)
  // 0.8695 / 0.8729 / 0.8814 -> 0.8695 / 0.8743 / 0.8814, confident failures 13 -> 13
  // (refinement-notes.md, *The weak-direction chamfer*). Proto RegisterOptions.
  // weak_direction_chamfer, CLI --weak_direction_chamfer.
  bool search_weak_direction_chamfer = true;
  // net+refine on scene-scale trees whose answer (valid, or invalid only for degenerate
  // geometry) puts the two sensors within a search cell of each other (|t| under 3.75 m on a
  // 240 m LiDAR cube) and whose clouds both have a dominant plane (a ground,
  // core/refine/dominant_plane.h), whatever the confidence: a search scored on the structure off
  // the ground (FindCorrelativeStart with node masks) gives a further start,
  // kept when, refined, it leaves clearly fewer structure nodes without a partner. The ground's
  // rings and density move with the sensor, so on an open scene (a parking lot, 85% ground) the
  // sensor-aligned pose out-fits the true motion by fitness and reads confident. The clouds must
  // be in their sensors' frames (as scans are) for the trigger to mean that; elsewhere it only
  // costs the search. Held-out LiDAR pairs (`rpsr calibrate --evaluate --object_pairs 0
  // --lidar_pairs 64 --pair_seed S`, S = 3, 1003, 5003, 7003), net+refine within (1 deg, 1%):
  // 5 frames apart 253 -> 255 of 256, 10 frames apart 241 -> 251, confident failures 10 -> 1; no
  // answer lost. Where it runs and the search lands near the answer it costs ~0.4 ms (both trees'
  // planes ~0.3 ms, the search, shifts about the answer's turn, ~0.1 ms; the headline LiDAR pairs,
  // ~3 m apart, pay it); where it refines a further start, that refinement too (~20 ms).
  // Mode refine runs the same check on its one answer but keeps it (the caller's start refined):
  // when the other start wins, the answer is reported doubted, its confidence capped at the
  // model's degenerate_cap (0.05) and failure_reason naming the other pose. On the held-out draws
  // above, 14 of 512 refine answers were doubted, none of them right; confident (>= 0.9) refine
  // failures 7 -> 0.
  bool check_sensor_aligned_answers = true;
  // With initial_T_target_source given: when the answer's geometry is degenerate (num_degenerate
  // > 0), its motion from the initial guess is kept only off the degenerate directions; along
  // them the pose is the guess's (HoldDegenerateDirections, core/refine/degenerate_hold.h), and
  // the result says so (held_at_initial). Along an unconstrained direction the refinement's
  // answer is drift, the caller's guess (a tracker's constant-velocity motion) is the better
  // value. `rpsr odometry --local` on simulated open roads (`rpsr data lidar --frames 300 --style
  // open --seed 5/7/11/12`), KITTI translation error without -> with: 7.26/5.64/4.07/4.24% ->
  // 3.97/4.61/3.71/3.96% (60/10/33/40 of 299 frames degenerate); the suburban, urban and parking
  // sequences have no degenerate frame and are unchanged. The answer stays invalid (degenerate):
  // that component is the guess, not a measurement.
  bool hold_degenerate_at_initial = true;
  TreeRefinementOptions refinement;
};

// Seconds spent per stage of one pair (in a batch, the network's time is the batch's divided
// evenly among its pairs).
struct RegistrationTimings {
  double net_seconds = 0.0;
  double refine_seconds = 0.0;
  double confidence_seconds = 0.0;
  double total_seconds = 0.0;
};

struct RegistrationResult {
  Eigen::Isometry3d T_target_source = Eigen::Isometry3d::Identity();
  // false: do not use T. failure_reason says why in words a user can act on (no overlap, too
  // little fitness, degenerate geometry naming the axes, the network's output not finite). On a
  // valid result it is empty unless the pipeline doubts the answer (mode refine's sensor-aligned
  // check, check_sensor_aligned_answers; the confidence is capped then).
  bool valid = false;
  std::string failure_reason;
  // Calibrated probability that T is within (1 degree, 1% of the target's extent) of the truth.
  // 0 when invalid; low (never confident) when the geometry is degenerate.
  double confidence = 0.0;
  // From the refinement's last depth (see TreeRefinementResult); for mode kNet they are measured
  // by one evaluation of the refinement's cost at the network's estimate, without updates.
  double fitness = 0.0;      // overlap fraction of the source's points
  double inlier_rmse = 0.0;  // metres
  int iterations = 0;        // refinement Gauss-Newton iterations (0 for kNet)
  bool converged = false;
  Eigen::Matrix<double, 6, 6> information = Eigen::Matrix<double, 6, 6>::Zero();
  // The information's unconstrained directions, and on an object-scale target that is a body of
  // revolution (FindContinuousSymmetry, core/refine/symmetry_starts.h) the turn about its axis,
  // which no fit can measure (failure_reason names the axis).
  std::array<bool, 6> degenerate_axes = {};  // rotation x, y, z, translation x, y, z
  int num_degenerate = 0;
  // The pose along the degenerate directions is the caller's initial guess, not a measurement
  // (RegistrationOptions::hold_degenerate_at_initial).
  bool held_at_initial = false;
  // Whether line-shaped nodes took their ancestor plane's normal (the refinement options' rule, or
  // its choice for this pair: TreeRefinementResult::line_normals_from_planes).
  bool line_normals_from_planes = false;
  // The refinement's measure of the source's scatter about the target's surface, in finest cell
  // edges, and whether the noise polish ran (TreeRefinementResult::surface_scatter_cells,
  // noise_polished); -1 and false when not measured (mode kNet among others).
  double surface_scatter_cells = -1.0;
  bool noise_polished = false;
  // Mode refine, an answer doubted by the sensor-aligned check (check_sensor_aligned_answers): the
  // pose its other start refined to, which leaves clearly fewer of the structure's nodes off the
  // ground without a partner. The answer stays the caller's start refined, its confidence capped.
  std::optional<Eigen::Isometry3d> structure_alternative_T_target_source;
  // The network's estimate before refinement (identity / the initial guess in mode kRefine) and
  // its mean peak score (an input of the confidence), after every pass that ran (net+refine: the
  // first alone when its answer was confident, later_passes_only_when_unconfident; an answer
  // kept from the first pass's start keeps the confidence features measured with it).
  Eigen::Isometry3d net_T_target_source = Eigen::Isometry3d::Identity();
  double net_score_peak = 0.0;
  RegistrationMode mode = RegistrationMode::kNetRefine;
  // Where the returned pose's refinement started: "network" (net+refine's first start; mode net's
  // single evaluation), "network_later_passes" (net+refine's deferred passes' estimate,
  // RegistrationOptions::later_passes_only_when_unconfident), "initial" (the caller's guess or
  // identity: mode refine's only start, net+refine's second), "searched" (net+refine's third on
  // scene-scale trees, RegistrationOptions::search_scene_start), "searched_turns" (its fourth
  // there, the same search over every turn), "structure" (a further one there, the sensor-aligned
  // check's: check_sensor_aligned_answers), "round_axis" (its third on object-scale trees without
  // near-symmetries, search_round_axis_start), "weak_direction" (a further one there,
  // search_weak_direction_start), "centroid" (a further one there, search_centroid_start),
  // "principal_axes" (a further one on object-scale trees, search_principal_axes_start),
  // "extent_slide" (the answer moved until the clouds' ends agree and measured there,
  // search_extent_slide), "weak_direction_chamfer" (search_weak_direction_chamfer), "far_valley"
  // (the answer moved to the middle of the far-count valley and measured there,
  // search_far_valley), "half_turn" (search_half_turn_start) or "symmetric"
  // (its third on those with, try_symmetric_starts); and how many starts were refined or measured
  // for this pair (1-6 on scene-scale trees, 1-14 on object-scale ones, 15 with
  // weak_direction_finest_round; in mode refine 1, or 2 when the sensor-aligned check refined
  // another start to doubt the answer; 0 when the pipeline stopped before refining: the network's
  // output not finite).
  std::string start = "network";
  int starts = 0;
  RegistrationTimings timings;
  // The confidence model's inputs, in the order of confidence_model.h's ConfidenceFeatureNames()
  // (what `rpsr calibrate` fits on; for diagnosis too). Empty when the pipeline stopped before
  // measuring (the network's output not finite).
  std::vector<double> confidence_features;
};

// Whether a tracker may start its next frame from this answer (a constant-velocity prior): it is
// valid, or held at the previous motion along its degenerate directions and measured elsewhere
// (RegistrationOptions::hold_degenerate_at_initial). Any other invalid answer (too little overlap,
// a wrong start) leaves the last such motion in place. rpsrd's Track stream and `rpsr odometry
// --local` both follow it.
inline bool StartsNextFrame(const RegistrationResult& result) {
  return result.valid || result.held_at_initial;
}

class NetTargetEncoding;  // core/net/rpsr_net.h

// A target's share of the work of registering against it, done once (Registrar::PrepareTarget)
// for a caller that registers many sources against one target (a reference scan of an object, a
// map, the last frame of a stream): the network's encoding of the target (about 30% of an object
// pair's network time with two passes; registrar_bench, BM_RegisterObjectsPreparedTarget) and the
// refinement's target side (PreparedRefinementTarget: its cell indexes and node shapes; ~0.1-0.2
// ms of an object pair's refinement, ~1.3 ms of a 120k-point scan's) and an object-scale target's
// near-symmetries (~0.3-0.5 ms an object pair on the AVX2 host), or a scene-scale target's
// dominant plane (~0.15 ms a scan pair where the sensor-aligned check runs). Immutable and safe to
// share across threads; valid with the Registrar that made it, for the tree it was made from (which
// must outlive it).
class PreparedTarget {
 public:
  const Octree& tree() const { return *tree_; }
  // Memory it holds, for a caller's budget (rpsrd's prepared-target cache).
  size_t bytes() const { return bytes_; }
  // What was prepared: the network's encoding (null when prepared for mode refine only) and the
  // refinement's side (for the registrar's default TreeRefinementOptions; a request with another
  // min_count_for_covariance prepares its own).
  bool has_net_encoding() const { return net_encoding != nullptr; }
  // A scene-scale target's dominant plane (its ground), which the sensor-aligned check reads.
  bool has_dominant_plane() const { return dominant_plane.has_value(); }
  // An object-scale target's near-symmetries found when it was prepared (0: none, or not
  // object-scale), which the symmetric start and the confidence's twin margin read.
  size_t num_symmetries() const { return symmetries.has_value() ? symmetries->size() : 0; }
  // An object-scale target found to be a body of revolution when it was prepared.
  bool is_body_of_revolution() const { return revolution.has_value(); }

 private:
  friend class Registrar;
  const Octree* tree_ = nullptr;
  const void* registrar_ = nullptr;
  std::shared_ptr<const NetTargetEncoding> net_encoding;
  std::shared_ptr<const PreparedRefinementTarget> refinement;
  // The target's near-symmetries (FindSelfSymmetries), found once when it is object-scale on its
  // own (a scene's are never read); unset otherwise, and a pair that needs them finds its own.
  std::optional<std::vector<SelfSymmetry>> symmetries;
  // Whether it is a body of revolution (FindContinuousSymmetry), found with `symmetries` (read
  // only where those were found).
  std::optional<ContinuousSymmetry> revolution;
  // The target's dominant plane (FindDominantPlane) at its own finest depth, found once when it
  // is scene-scale on its own; the sensor-aligned check reads it for pairs refined to that depth
  // (a pair whose finest depth differs finds its own).
  std::optional<DominantPlane> dominant_plane;
  int dominant_plane_depth = 0;
  size_t bytes_ = 0;
};

// One pair of a batch, with its own options (a batch gathers requests of many clients).
// `prepared_target` (optional): PrepareTarget(*target) of the same Registrar.
struct RegistrationRequest {
  const Octree* source = nullptr;
  const Octree* target = nullptr;
  RegistrationOptions options;
  const PreparedTarget* prepared_target = nullptr;
};

struct RegistrarConfig {
  // Which model embedded in the binary (core/models/<name>/): "objects" (the default),
  // "objects-small" (a quarter of its convolution FLOPs) or, when shipped, "lidar". Ignored when
  // model_path is set.
  std::string model = "objects";
  // Weights (.rpsrw) from a file instead of an embedded model.
  std::string model_path;
  // Calibration of the confidence (see confidence_model.h). Empty: the one shipped beside the
  // model (core/models/<name>/confidence.txt, or confidence.txt beside model_path).
  std::string confidence_path;
};

// Thread-safe: one Registrar serves many threads (the network runs in inference mode).
class Registrar {
 public:
  static absl::StatusOr<std::unique_ptr<Registrar>> Create(const RegistrarConfig& config = {});
  ~Registrar();
  Registrar(const Registrar&) = delete;
  Registrar& operator=(const Registrar&) = delete;

  // InvalidArgument: null or empty trees, trees too shallow for the network (depth < 5) or for
  // the refinement's depths, a non-finite or non-rigid initial guess. Geometric failures are not
  // errors: they return valid = false with the reason.
  absl::StatusOr<RegistrationResult> Register(const Octree& source, const Octree& target,
                                              const RegistrationOptions& options = {}) const;
  // The same against a prepared target: equal results (within the network's batching tolerance),
  // less time in the network.
  absl::StatusOr<RegistrationResult> Register(const Octree& source, const PreparedTarget& target,
                                              const RegistrationOptions& options = {}) const;

  // Does a target's share of the work once (see PreparedTarget). InvalidArgument for a tree the
  // network cannot read (as Register would say). `for_network` false: the refinement's side only
  // (for mode refine: the network's encoding costs more than a refinement's target side and is
  // of no use there); such a target serves the network's modes too, encoding the target per call.
  absl::StatusOr<std::shared_ptr<const PreparedTarget>> PrepareTarget(
      const Octree& target, bool for_network = true) const;

  // One batched forward pass for all network modes' pairs (grouped by passes), then refinement
  // per pair. Results equal Register() pair by pair within the network's batching tolerance
  // (float rounding, ~1e-6) as the refinement carries it (0.055 degree at worst on 100 unseen
  // objects, see tree_refinement.h, Reproducibility).
  // Per-pair input errors come back as that pair's status; the others still run.
  std::vector<absl::StatusOr<RegistrationResult>> RegisterBatch(
      absl::Span<const RegistrationRequest> requests) const;
  std::vector<absl::StatusOr<RegistrationResult>> RegisterBatch(
      absl::Span<const std::pair<const Octree*, const Octree*>> pairs,
      const RegistrationOptions& options) const;

  // What the server reports as its model (name, parameters, default passes).
  std::string model_description() const;

 private:
  Registrar();
  struct State;
  std::unique_ptr<State> state_;
};

}  // namespace rpsr::core

#endif  // RPSR_CORE_REGISTRAR_REGISTRAR_H_
