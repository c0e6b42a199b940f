// Fine registration on two Barnes-Hut trees (issue 5): the multi-scale cost of the paper's Eq. 2,
//     U(R, t) = sum_d sum_{l, l^} rho^y_{d,l} rho^x_{d,l^} || (R mu^y_{d,l} + t) - mu^x_{d,l^}
//     ||^2,
// minimised coarse to fine over depths with generalized (plane-to-plane, GICP) residuals built
// from the nodes' covariances and a robust kernel. It reads only what a cached tree holds (count,
// centre of mass, covariance, inverse density, Morton codes): NO raw points, so the service can
// refine from its tree cache.
//
// Why these choices:
//  - Coarse to fine, one depth at a time (a continuation of Eq. 2's sum over depths): coarse cells
//    average away noise and give a wide basin; each finer depth starts where the coarser one
//    stopped, so by the finest depth the remaining error is below a cell and correspondences are
//    right. Summing all depths at once would let the many fine nodes dominate before they are
//    reliable.
//  - One correspondence per source node, the nearest target CoM among the target cells of the same
//    depth around the moved CoM (the paper's multiply-linked sum over (l, l^) restricted to the
//    pairs that matter: the far pairs carry vanishing robust weight anyway).
//  - Generalized residuals: r = mu_t - T mu_s with information (C_t + R C_s R^T)^-1, each
//    covariance regularised as in GICP (eigenvalues set to (1, 1, eps) so a planar node constrains
//    only its normal) and scaled by the squared cell edge so the Mahalanobis distance is unitless
//    and comparable across depths. Nodes with fewer than 3 points have no meaningful covariance
//    and get an isotropic one.
//  - Robust kernel (Geman-McClure) on that Mahalanobis distance: a node whose partner is a
//    different surface (occlusion, dynamic objects, partial overlap) fades out smoothly.
//  - Weights: see WeightScheme.
//  - Coarse depths on the target's cells: before each coarse stage the source's nodes three
//    depths finer (with their covariances) are re-binned on the target's grid at the current pose
//    (rebin_coarse_depths), so Eq. 2 compares cells holding the same part of the surface. With
//    the source's own cells the coarse stages drifted from the TRUE pose by up to a cell along
//    weakly constrained directions (a laptop's hinge, a spring's axis), which the finer stages
//    could not undo (refined from the truth, 15 of 100 unseen clean object pairs ended beyond
//    (1 deg, 0.01)). From network-sized errors under jitter 0.03, 24 of 60 unseen pairs fail on
//    the source's own cells, 14 re-binned (tree_refinement_test). Unseen objects, net+refine (three
//    network passes then), 100 pairs: clean rotation RMSE 18.4 -> 1.5 deg, recall (1 deg, 0.01)
//    over the 21 study settings 0.659 -> 0.713.
//  - The finest depth jointly with the next coarser one (joint_finest_stage): Eq. 2's sum over
//    depths for the last two, so that where the finest cells hold noise the coarser ones still
//    constrain the pose.
//  - Levenberg-Marquardt step control at the finest depth (step_control).
//  - When the source's points scatter about the surface by a sizeable part of a finest cell
//    (jitter), a last point-to-plane stage one depth coarser (noise_polish, noise_polish.h).
//  - Reproducibility: deterministic for a given start; re-binning is discontinuous in the pose,
//    so starts 1e-6 apart (the network's batching tolerance) can end slightly apart: on 100
//    unseen 2,048-point objects 0.055 deg at worst, 3 pairs beyond (0.01 deg, 1e-4).
//
// Conventions: T_target_source maps source points into the target frame
// (core/data/transform_convention.h); metres (the clouds' units), radians, seconds.
#ifndef RPSR_CORE_REFINE_TREE_REFINEMENT_H_
#define RPSR_CORE_REFINE_TREE_REFINEMENT_H_

#include <array>
#include <memory>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "Eigen/Core"
#include "Eigen/Geometry"
#include "absl/status/statusor.h"
#include "core/tree/bh_tree.h"

namespace rpsr::core {

// How a correspondence (source node l, target node l^) is weighted, before the robust kernel.
enum class WeightScheme {
  // Eq. 2: rho^y_l * rho^x_l^ (each inverse density sums to 1 per depth; sparse nodes weigh more),
  // rescaled so the weights of a depth average 1. This is the paper's importance weighting: every
  // occupied region of the surface counts about equally, whatever the sampling density (a LiDAR's
  // near ground would otherwise outweigh everything).
  kInverseDensity,
  // count_l of the source node: reproduces point-level GICP on the raw points (every point votes
  // once), dominated by densely sampled regions.
  kSourceCount,
  // Every correspondence 1: every occupied cell votes once, i.e. the inverse-density weighting
  // without the target factor.
  kUniform,
};

struct TreeRefinementOptions {
  // Depths visited, coarse to fine. finest_depth < 0: the deepest depth both trees hold.
  // coarsest_depth < 0: depth 3 (or the finest, if shallower), whose cells pull in an initial
  // error of about a cell (30 m on a 240 m LiDAR cube, 0.25 on an object in [-1, 1]) while still
  // holding a few dozen nodes. (It was max(3, finest - 4), five stages: on trees to depth 9 that
  // starts at 7.5 m cells, and simulated LiDAR pairs 5 and 10 frames apart refined from the
  // identity reached (1 deg, 1%) in 80 of 128 cases against 104 from depth 3; objects, whose trees
  // stop at depth 6, are unchanged.) Coarse stages hold few nodes and cost little.
  int coarsest_depth = -1;
  int finest_depth = -1;
  // Depths coarser than the finest refine the source's finest nodes re-binned on the TARGET's
  // cells at the current pose (RebinOnTargetCells in tree_refinement.cc) instead of the source's
  // own cells, so both trees' cells hold the same part of the surface at the true pose; a stage
  // that moves the source by more than a quarter cell is re-binned and run again, up to
  // max_rebin_rounds times. false: the source tree's own cells (the paper's Eq. 2 as written).
  bool rebin_coarse_depths = true;
  int max_rebin_rounds = 2;
  // The finest stage minimises the finest depth's cost plus that of the next coarser depth, the
  // source re-binned on the target's cells at the stage's starting pose (needs
  // rebin_coarse_depths and at least two stages):
  // Eq. 2's sum over depths, restricted to the last two, each residual unitless (Mahalanobis in
  // its own cells) so that a correspondence counts once at either depth. A 1,024-point object's
  // depth-6 cells hold single samples, fewer of which find a partner within a cell (~230
  // correspondences against ~440 at depth 5, mean over 50 unseen pairs refined from the
  // identity), and under noise their borrowed normals are noise too, so the finest
  // depth alone barely moved from where the coarser stages handed it the pose (refined from the
  // truth it kept 33 of 35 jitter misses in place, object_failure_anatomy before this change). The
  // coarser cells average the noise and keep constraining the pose while the finest ones add their
  // detail. Measured against the finest depth alone (`--joint_finest_stage=false`), recall at (1
  // deg, 0.01) on unseen objects (`rpsr eval --protocol objects --split unseen --count 200 --seed
  // 2` per setting): jitter 0.03 0.715 -> 0.760, jitter 0.05 0.315 -> 0.395, clean 0.845 -> 0.855,
  // noise 0.1 / 0.4, outliers 0.4 and crop 0.4 within two pairs; KITTI-style pairs refined from the
  // identity, rotation / translation RMSE 0.168 deg / 0.033 m -> 0.157 / 0.025 (ground removed)
  // and 0.110 / 0.0095 -> 0.064 / 0.0040 (kept). It costs a second linearisation per finest
  // iteration: objects refine 3.5 -> 4.7 ms, 120k-point scans 10.3 -> 12.3 ms (registrar_bench,
  // BM_Register*FinestAlone against BM_Register*). All measured when it was introduced, its
  // coarser depth then counting cells. With the two-cell coarse search and joint_coarser_weights
  // below: jitter 0.03 / 0.05 / 0.08 0.765 / 0.465 / 0.13 -> 0.79 / 0.515 / 0.175 on the same 200
  // pairs a setting (the others within two pairs); KITTI-style rotation / translation RMSE 0.167
  // / 0.033 -> 0.169 / 0.030 (removed), 0.104 / 0.0094 -> 0.099 / 0.0080 (kept); the refinement
  // inside net+refine 4.0 -> 5.2 ms an object, 10.5 -> 12.0 ms a scan
  // (tests/bench/results/registrar_bench_coarse_search.txt).
  // The information the result reports is that of the joint cost (both depths), the estimate's
  // own; fitness and inlier RMSE stay the finest depth's.
  bool joint_finest_stage = true;
  // The weights of the joint finest stage's coarser depth. Eq. 2's inverse densities (as the
  // finest depth), not the coarse stages' cell counting (coarse_weights): counting cells, a scan's
  // re-binned cells near the sensor, which hold arcs of the rings that move with it, pulled every
  // consecutive-frame estimate the same way. `rpsr odometry` on simulated 10 Hz sequences (KITTI
  // translation error over 50-100 m segments; 300 suburban frames over 100-200 m): suburban 1.20%
  // -> 0.29%, parking lot 2.81% -> 1.36%, urban 0.50% -> 0.51% (without the joint stage 0.28%,
  // 1.48%, 0.59%); objects within three pairs per setting (200 seed-2 unseen pairs a setting;
  // held-out calibration set objects net+refine 801 -> 803 of 1,008 (802 refitted), LiDAR 122 ->
  // 123 of 128);
  // but KITTI-style pairs five frames apart refined from the identity lose some precision: rotation
  // / translation RMSE 0.056 deg / 0.0042 m -> 0.099 / 0.0080 (ground kept), 0.158 / 0.025 -> 0.169
  // / 0.030 (removed), still within the 0.2 degree / 0.10 m goal.
  WeightScheme joint_coarser_weights = WeightScheme::kInverseDensity;
  // covariance_epsilon of the re-binned stages: their cells hold the same part of the surface as
  // the target's at the true pose, so their CoMs may also pull along the surface (a looser plane
  // than at the finest depth, whose own-grid CoMs do not correspond along it) -- but only a
  // little: a LiDAR's cells are sampled denser toward the sensor, so two scans' CoMs differ along
  // the surface wherever the sensor moved. Measured (60 unseen object pairs x 8 settings; 64
  // simulated LiDAR pairs 5 and 10 frames apart): 1e-3 objects recall 0.66, LiDAR net+refine
  // 1.00 / 0.84; 3e-3 0.70 and 1.00 / 0.88; 1e-2 0.70 and 0.97 / 0.81.
  double coarse_covariance_epsilon = 3e-3;
  // Gauss-Newton iterations per depth at most (each re-finds the correspondences).
  int max_iterations_per_depth = 12;
  // A depth stops when one update rotates less than this (radians) AND translates less than
  // translation_epsilon_cells * the depth's cell edge (so the threshold scales with the data:
  // ~3e-5 on a depth-6 object, ~5e-4 m on a depth-9 LiDAR cube).
  double rotation_epsilon_rad = 1e-4;
  double translation_epsilon_cells = 1e-3;
  // A refused finest step (step_control) that would have moved the matched points by less than
  // this many finest cell edges also ends the stage (RMS displacement: the translation about
  // their centroid and the rotation at their RMS lever arm). A refused step leaves the pose where
  // it is, and the damped retries that follow are shorter still, so ending there leaves the
  // answer within this of where they would have crept; on scans they were 5-8 linearisations of
  // both finest depths moving it by millimetres (cost changes of 1e-5 relative), on objects two
  // or three more refusals. Measured against 0 (session 24, tests/bench/notes/speed-notes.md,
  // *Settled refused steps*): registrar_bench refine LiDAR 18.6 -> 15.7 ms, objects 6.97 -> 6.52;
  // KITTI-style K1 / K2 RMSE and recall the same to the tables' digits; the objects' ten settings
  // x 3 seeds the same mean recall; twelve simulated drives' odometry error 1.896 -> 1.906% mean
  // (0.01 read 1.903% and saved about half as much). 0: only the epsilons above and the damping's
  // ceiling end a controlled stage (the refinement before it).
  double settled_step_cells = 0.02;
  // Depths above the finest stop at epsilons this many times looser (they only need to leave the
  // next depth an error well inside its cells; tight convergence there is wasted time).
  double coarse_epsilon_factor = 10.0;
  // Correspondence search: the target cells around the moved CoM (the 2x2x2 block nearest to it,
  // which holds every target cell within half a cell; or the full 3x3x3 block), the nearest
  // target CoM no farther than max_correspondence_distance_cells cell edges. 8 cells is ~3x
  // cheaper than 27 and, after the coarser depth converged, misses nothing that matters.
  bool search_27_neighbors = false;
  double max_correspondence_distance_cells = 1.0;
  // GICP covariance regularisation: eigenvalues become (1, 1, covariance_epsilon) * edge^2.
  double covariance_epsilon = 1e-3;
  // Nodes with fewer points (a point or two has no shape) borrow the shape of their nearest
  // ancestor with enough points; isotropic edge^2 * I only if none has.
  int min_count_for_covariance = 3;
  // Nodes whose points lie along a line (the middle eigenvalue of their covariance under 5% of the
  // largest: in a sparse LiDAR scan, one ring's arc crossing a cell) have no surface normal of
  // their own: the smallest eigenvector is whichever perpendicular noise made smaller, and a
  // ring arc given a normal across the ring pulls consecutive scans together (the ring moves with
  // the sensor). With this on, such a node takes the normal of its nearest ancestor (at most three
  // depths up) that is not a line and contains it (within 60 degrees of its plane): the ground
  // or the wall the ring lies on. It helps sparse scanners a lot and the HDL-64E on open roads,
  // but costs the HDL-64E's structured scenes, hence chosen per pair when unset (below). `rpsr
  // odometry --local`, KITTI translation error off -> on, suburban / urban / parking / open road
  // (tests/bench/notes/odometry-notes.md, *Sparser scanners drift more*): VLP-16 6.11 / 31.8 / 8.18
  // / 55.6%
  // -> 1.93 / 3.49 / 1.88 / 2.87%; HDL-32E 3.07 / 5.17 / 2.77 / 10.8% -> 1.61 / 2.36 / 1.34 /
  // 1.43%; HDL-64E 0.29 / 0.82 / 1.28 / 3.71% -> 0.35 / 1.07 / 2.90 / 2.11%. Unset (the default):
  // chosen for each pair from the two trees, on where their rings are farther apart than the
  // finest cells (ChooseLineNormalsFromPlanes), the result says which rule ran. The proto's
  // RegisterOptions.line_normals_from_planes, the CLI's --line_normals_from_planes.
  std::optional<bool> line_normals_from_planes;
  // Geman-McClure kernel on the Mahalanobis distance, w = (c^2 / (c^2 + e^2))^2 with
  // c^2 = robust_scale_cells^2 / (2 covariance_epsilon): a plane-to-plane offset of
  // robust_scale_cells cell edges along the normal gets weight 1/4 at any depth.
  double robust_scale_cells = 0.25;
  // Fitness and inlier RMSE count a source node as an inlier when its partner's plane (the
  // target node's normal; the CoM for isotropic nodes) lies within this many cell edges of its
  // moved CoM at the finest depth. Half a cell: two independent samples of one surface put their
  // cell CoMs up to a few tenths of a cell apart along the normal where it curves.
  double inlier_distance_cells = 0.5;
  // They are measured at the finest depth whose source nodes hold at least this many points on
  // average (never coarser than coarsest_depth): finer cells than the sampling split a surface
  // into single samples whose partners are often beyond a cell, which would read as partial
  // overlap (a 2,048-point object at depth 6 does; depth 5 holds ~3-4 points a node).
  double fitness_min_mean_count = 3.0;
  WeightScheme weights = WeightScheme::kInverseDensity;
  // The weighting of the re-binned coarse depths (rebin_coarse_depths). Every occupied cell votes
  // once there: inverse densities amplify sparse cells, and a disturbed source's sparse cells are
  // mostly the ones the disturbance made -- a uniform outlier alone in its cell weighed as much as
  // a patch of surface and pulled the coarse stages off the pose (refined from 5-15 degree
  // starts, 40% outliers: 15 -> 8 of 60 unseen pairs fail, tree_refinement_test). Counting cells,
  // not points, keeps what the inverse density is for on scans (the dense ground near the sensor
  // does not outweigh the rest); counting points (kSourceCount) lost a third of the LiDAR pairs
  // refined from the identity. Measured against kInverseDensity on the confidence's held-out set
  // (pair seed 1003): objects net+refine within (1 deg, 1%) 716 -> 778 of 1,008, refine 336 ->
  // 410; LiDAR pairs 5 and 10 frames apart net+refine 119 -> 121 of 128, refine 98 -> 103
  // (kSourceCount: 765, 115, 61). Jitter gains in net+refine too (unseen study, 0.03: recall
  // 0.59 -> 0.65), though not from the starts of the test above (14 and 15 of 60 fail).
  WeightScheme coarse_weights = WeightScheme::kUniform;
  // The correspondence search of the re-binned coarse stages (rebin_coarse_depths), which carry
  // the pose from where it starts: the nearest target CoM within this many cell edges, in the
  // 3x3x3 block around the moved CoM (as search_27_neighbors above). Under jitter, crops and
  // outliers a coarse cell's partner often lies beyond one cell, and a stage that cannot see it
  // settles short of the truth. The finest stage (its coarser depth too) polishes within a cell
  // and keeps the search above. Measured against the search above at every depth (1 cell, 8
  // cells), 100 unseen pairs a setting (`rpsr eval --protocol objects --split unseen --count 100
  // --disturbance D --level L`), recall at (1 deg, 0.01): clean 0.85 -> 0.87, jitter 0.03 / 0.05 /
  // 0.08 0.73 / 0.44 / 0.09 -> 0.76 / 0.51 / 0.21, crop 20% / 40% 0.77 / 0.55 -> 0.77 / 0.72,
  // noise 20% / 40% 0.86 / 0.82 -> 0.85 / 0.87, outliers 20% / 40% 0.83 / 0.78 -> 0.85 / 0.82;
  // 200 other pairs (--count 200 --seed 2): jitter 0.76 / 0.40 / 0.07 -> 0.78 / 0.53 / 0.19,
  // crop 20% / 40% 0.75 / 0.61 -> 0.77 / 0.68, the others within three pairs (clean 0.855 ->
  // 0.850, outliers 20% 0.845 -> 0.830). KITTI-style K1 / K2 refine: the same recall (1.000) and
  // rotation RMSE within 0.01 degree (all before the confidence was refitted to it). Cost
  // (registrar_bench's *CoarseOneCell rows against the default, interleaved,
  // tests/bench/results/registrar_bench_coarse_search.txt, with joint_coarser_weights above): the
  // refinement inside net+refine, objects 4.1 -> 5.2 ms and scans 11.6 -> 12.0 ms; refine from the
  // identity 3.9 -> 5.4 and 11.1 -> 11.9 ms. The finest stage's coarser depth searching two cells
  // as well gained another pair or two under jitter for about as much again, and every depth
  // searching so added nothing on scans at 30% more of their refinement (scratch runs).
  bool coarse_search_27_neighbors = true;
  double coarse_max_correspondence_distance_cells = 2.0;
  // The noise polish (noise_polish.h): when the source's finest nodes scatter about the
  // target's planes by a median of at least noise_polish_min_scatter_cells finest cell edges
  // (MedianSurfaceScatterCells, normals read two depths up), a last point-to-plane stage one
  // depth coarser on kernel-smoothed surfaces (the source's nodes and the target about them,
  // smoothed_surface.h); the result's statistics are then measured at the polished pose. 0.45 lies
  // above the clean unseen objects' 95th percentile (0.37) and near the 5th of jitter 0.05 (0.43);
  // scans (0.02-0.04) never reach it. Unseen objects, recall at (1 deg, 0.01), jitter 0.05 / 0.08:
  // 0.54 / 0.19 -> 0.74 / 0.66 (noise_polish.h). The proto's
  // RegisterOptions.noise_polish, the CLI's --noise_polish.
  // It polishes an answer the stages found, and only one where most of the source lies on the
  // target's surface (fitness at least noise_polish_min_fitness): unrelated clouds scatter as much
  // as heavy jitter (median 0.61 against 0.59) and, polished, read more confident (held-out
  // unrelated pairs, mean confidence 0.020 -> 0.041 with the refitted confidence, random volumes
  // up to 0.38), but their fitness is lower (median 0.48 against 0.985; jitter 0.08's 5th
  // percentile 0.83).
  bool noise_polish = true;
  double noise_polish_min_scatter_cells = 0.45;
  double noise_polish_min_fitness = 0.8;
  // Source nodes used per depth at most (an even stride over the Morton order keeps the spatial
  // spread): bounds the cost on 120k-point scans. A simulated HDL-64E street scan's depth 9
  // holds ~7,600 nodes (CellIndexTest.AScansDeepLevelsAreBlocked prints it), so its finest
  // stage uses 6,000 of them; scans of denser or larger surroundings hold more.
  int max_source_nodes_per_depth = 6000;
  // Levenberg-Marquardt damping added to the diagonal of H (relative to its mean diagonal): the
  // least; with step_control, a finest-depth step that raises the robust cost is taken back and
  // the damping raised tenfold until a step descends (or the damping passes 1e4: converged
  // there). Only the finest depth: on the coarse ones the plain steps' overshoot is what carries
  // a far start (LiDAR pairs 10 frames apart) into the basin (with control there, 3 to 4 of 32
  // such pairs more failed), while the finest depth is where the plain iteration oscillated.
  double damping = 1e-6;
  bool step_control = true;
  // Measure only: no update, the initial transform is returned as it is with the statistics of
  // the finest depth (information, degeneracy) and the fitness and inlier RMSE, as a refinement
  // ending there would report them. iterations 0, converged false. The registrar's mode `net`
  // uses it to judge the network's estimate by the same yardsticks as a refined one.
  bool evaluate_only = false;
  // Validity. A depth with fewer correspondences than this ends the refinement as invalid ("no
  // overlap"); a final fitness below min_fitness is invalid too.
  int min_correspondences = 12;
  double min_fitness = 0.05;
  // Degeneracy: the information matrix, expressed about the matched points' centroid with its
  // rotation about each axis scaled by the points' RMS lever arm about that axis (so all six
  // directions are displacements in metres), has eigenvalues normalised by the largest; those below
  // this are degenerate. Planar residuals leave tangential directions an information ratio
  // ~covariance_epsilon, so the threshold must sit well above it; and below the ratios of
  // elongated or flat but well-posed objects: on the calibration pairs (rpsr calibrate), results
  // between 0.01 and 0.02 were within (1 deg, 1%) twice as often as not, those below 0.01 in 1 of
  // 25 (0.02 was the first choice).
  double degeneracy_threshold = 0.01;
};

// The coarse stages search as the finest does (search_27_neighbors,
// max_correspondence_distance_cells) instead of two cells in the 3x3x3 block: the refinement before
// coarse_search_27_neighbors, ~1.1 ms less an object's refinement and 0.4-0.8 ms less a scan's,
// less accurate under jitter, crops and outliers (figures at coarse_search_27_neighbors). The
// proto's RegisterOptions.coarse_wide_search = false and the CLI's --coarse_wide_search=false.
inline void SearchCoarseStagesAsTheFinest(TreeRefinementOptions& options) {
  options.coarse_search_27_neighbors = options.search_27_neighbors;
  options.coarse_max_correspondence_distance_cells = options.max_correspondence_distance_cells;
}

// Per depth: what the stage did.
struct DepthStage {
  int depth = 0;
  double cell_edge = 0.0;   // metres (target tree)
  int source_nodes = 0;     // used at this depth
  int correspondences = 0;  // at the last iteration
  int iterations = 0;       // over all rounds
  // Re-binned depths (TreeRefinementOptions::rebin_coarse_depths): how many times the source was
  // re-binned and the depth run; the other fields are the last round's (times and iterations add
  // up).
  int rounds = 1;
  // A joint finest stage (TreeRefinementOptions::joint_finest_stage): the coarser depth's
  // correspondences at the last iteration (0 otherwise).
  bool joint = false;
  int coarser_correspondences = 0;
  bool converged = false;
  // The last Gauss-Newton update's size: rotation (radians) and translation about the matched
  // centroid (metres); 0 when the stage made none.
  double last_update_rotation_rad = 0.0;
  double last_update_translation = 0.0;
  double seconds = 0.0;  // the whole stage, preparation included
  // Re-binning the source, listing its nodes, indexing the target's level (near 0 where a
  // TreeRefinementCache already held the last two). Both sides' shapes are computed on first use,
  // inside the iterations' time.
  double prepare_seconds = 0.0;
  // The target's side came from a PreparedRefinementTarget (not built by this call or its cache).
  bool target_side_prepared = false;
  // The noise polish's stage (TreeRefinementOptions::noise_polish): point-to-plane at `depth`,
  // one above the finest.
  bool noise_polish = false;
};

struct TreeRefinementResult {
  // The refined transform (source -> target); the initial one when invalid before any update.
  Eigen::Isometry3d T_target_source = Eigen::Isometry3d::Identity();
  // false: do not trust T. failure_reason says why (no overlap, too little fitness, degenerate
  // geometry naming the axes, a singular system). Empty when valid.
  bool valid = false;
  std::string failure_reason;
  // Every depth stopped by the epsilon test (not by max_iterations_per_depth).
  bool converged = false;
  int iterations = 0;  // Gauss-Newton iterations over all depths
  // At fitness_depth (see TreeRefinementOptions::fitness_min_mean_count): fraction of the source's
  // points (by node count) whose node has an inlier correspondence within inlier_distance_cells of
  // the partner's plane, and the RMS of their distances to the partner's plane (the target node's
  // normal; the CoM distance for isotropic nodes), metres.
  double fitness = 0.0;
  double inlier_rmse = 0.0;
  int inliers = 0;        // nodes
  int fitness_depth = 0;  // where fitness and inlier_rmse were measured
  // The same two at the finest depth (equal to the above when fitness_depth is the finest): a
  // finer yardstick, lower on sparse clouds, that the confidence reads beside them.
  double finest_fitness = 0.0;
  double finest_inlier_rmse = 0.0;
  // Mean Geman-McClure weight of the correspondences at fitness_depth (1: every partner within a
  // small fraction of a cell of its plane).
  double mean_robust_weight = 0.0;
  // 6x6 Gauss-Newton information (J^T W J) at the final transform, finest depth (plus the
  // coarser one of a joint finest stage, TreeRefinementOptions::joint_finest_stage), ordered
  // (rotation x, y, z [1/rad^2], translation x, y, z [1/m^2]) for a perturbation applied in the
  // TARGET frame about `information_center`: T <- [exp(w) | c - exp(w) c + v] T. Weights are
  // normalised to average 1 per correspondence and the residual covariance is the regularised one.
  Eigen::Matrix<double, 6, 6> information = Eigen::Matrix<double, 6, 6>::Zero();
  Eigen::Vector3d information_center = Eigen::Vector3d::Zero();
  // Eigen-analysis of the scaled information (see TreeRefinementOptions::degeneracy_threshold):
  // normalised eigenvalues ascending, the directions (columns, rotation part scaled to metres) of
  // those below the threshold, and per axis whether it lies mostly (> 1/2 of its squared norm) in
  // that degenerate subspace. Axes ordered as `information`.
  Eigen::Matrix<double, 6, 1> normalized_eigenvalues = Eigen::Matrix<double, 6, 1>::Zero();
  Eigen::MatrixXd degenerate_directions;
  // The RMS lever arms (metres) of the matched points about the axes through
  // information_center, by which the directions' rotation rows are scaled (radians x lever arm =
  // metres); what HoldDegenerateDirections needs to read them back.
  Eigen::Vector3d rotation_lever_arms = Eigen::Vector3d::Ones();
  std::array<bool, 6> degenerate_axes = {};
  int num_degenerate = 0;
  std::vector<DepthStage> stages;  // coarse to fine
  double total_seconds = 0.0;
  // The line rule that ran (TreeRefinementOptions::line_normals_from_planes, or its choice).
  bool line_normals_from_planes = false;
  // The source's finest nodes' median distance to the target's planes, in finest cell edges, at
  // the pose the stages ended at (MedianSurfaceScatterCells; about 0.67 sigma / edge for a
  // scatter sigma about the surface); negative when not measured (noise_polish off, an invalid
  // result, measuring only). noise_polished: the noise polish ran, its stage is the last in
  // `stages` (DepthStage::noise_polish).
  double surface_scatter_cells = -1.0;
  bool noise_polished = false;
};

// The depths RefineOnTrees visits, {coarsest, finest}, with the options' -1 resolved (finest: the
// deepest depth both trees hold; coarsest: depth 3, or the finest if shallower).
std::pair<int, int> StageDepths(const Octree& source, const Octree& target,
                                const TreeRefinementOptions& options);

// A node's points lie along a line when the middle eigenvalue of their covariance is under this
// fraction of the largest (one scan ring's arc: ~1e-3; a cell of surface holding two rings already
// ~0.5). The refinement's line rule reads it, and so does the weak-direction chamfer's weighting.
inline constexpr double kLineEigenvalueRatio = 0.05;

// The node whose shape `node` of `depth` reads: the nearest on its path to the root (itself first)
// holding at least min_count points, as {depth, node}; {-1, -1} when none does. A node with too
// few points for a covariance of its own borrows its nearest such ancestor's (the parent's patch of
// the same surface).
std::pair<int, int> ShapeNodeOf(const Octree& tree, int depth, int node, int min_count);

// What TreeRefinementOptions::line_normals_from_planes left unset is chosen from: the fraction of
// a tree's deepest nodes with a shape (min_count_for_covariance points or more) whose points lie
// along a line (kLineEigenvalueRatio), over an even stride of at most 2,048
// nodes. nullopt when fewer than 100 of those have a shape, too few to tell (an object's tree at
// depth 6: most of its fine nodes hold one or two points and read an ancestor's shape).
std::optional<double> LineShapedFraction(const Octree& tree, int min_count_for_covariance);

// The line rule for a pair whose trees have these fractions: on when both are known and their mean
// is at least 0.67, i.e. when most fine cells hold a single ring's arc because the scanner's rings
// lie farther apart than a cell (0.67: midway between the closest structured scenes of the two
// kinds below, HDL-64E parking 0.63 and HDL-32E urban 0.71; at 0.7 the HDL-32E's urban drive
// took the rule in 143 of 199 pairs and drifted 2.93% instead of 2.36%). Measured on simulated
// drives at depth 9 (`rpsr data lidar --sensor S`, four frames each of suburban / urban / parking
// / open road): HDL-64E 0.47-0.50 / 0.38-0.43 / 0.61-0.63 / 0.49-0.76, HDL-32E 0.75-0.83 /
// 0.71-0.73 / 0.75-0.80 / 0.77-0.83, VLP-16 0.89-0.91 / 0.84-0.87 / 0.86-0.90 / 0.90-0.94; the
// KITTI-style pairs (HDL-64E) 0.17-0.54 (pair means); 2,048-point objects too few. So the 16- and
// 32-beam scanners get the rule, the HDL-64E's structured scenes, where it costs, do not, and its
// open roads, where it helps, in most pairs.
bool ChooseLineNormalsFromPlanes(std::optional<double> source_fraction,
                                 std::optional<double> target_fraction);

// The input checks of RefineOnTrees alone (the errors listed below), so that a caller can reject
// a request before spending time on it.
absl::Status ValidateTreeRefinement(const Octree& source, const Octree& target,
                                    const Eigen::Isometry3d& initial_T_target_source,
                                    const TreeRefinementOptions& options = {});

// What several RefineOnTrees calls on the same two trees share (the registrar's starts, a
// re-binned depth's rounds): per depth, the target's cell index and its nodes' shapes (or a
// PreparedRefinementTarget's), and per depth and regularisation the source's own nodes. The values
// are the same as without it; only the work is done once (the eigen-decompositions of the nodes'
// shapes were a quarter of a LiDAR refinement's time). Bound to the trees of the call that uses it
// (by address; a call on other trees starts it afresh), so the trees must stay alive and unchanged
// while it is used with them. One thread at a time.
class PreparedRefinementTarget;

class TreeRefinementCache {
 public:
  TreeRefinementCache();
  // Reads the target's side from `prepared` when the calls' target is its tree (and the options'
  // min_count_for_covariance and line rule are the ones it was prepared with); otherwise prepares
  // it as usual.
  explicit TreeRefinementCache(std::shared_ptr<const PreparedRefinementTarget> prepared);
  ~TreeRefinementCache();
  TreeRefinementCache(TreeRefinementCache&&) noexcept;
  TreeRefinementCache& operator=(TreeRefinementCache&&) noexcept;

  struct Impl;  // tree_refinement.cc

 private:
  friend absl::StatusOr<TreeRefinementResult> RefineOnTrees(const Octree&, const Octree&,
                                                            const Eigen::Isometry3d&,
                                                            const TreeRefinementOptions&,
                                                            TreeRefinementCache&);
  std::unique_ptr<Impl> impl_;
};

// A target tree's side of the refinement, prepared once for a target that many sources are refined
// against (a reference scan, a map, a cloud cached by the service): per depth, its cell index
// (Morton code -> node) now, and its nodes' shapes (the normal each regularised covariance keeps;
// see TreeRefinementOptions::covariance_epsilon) on first use, published for the calls after it.
// Without it each refinement builds them for itself (registrar_bench, mode refine, interleaved:
// 4.48 -> 4.35 ms on 2,048-point objects, 12.4 -> 11.1 ms on 120k-point scans to depth 9).
// Preparing builds the indexes (0.02 ms for an object, 0.08 ms for a scan) and measures the tree's
// LineShapedFraction (~0.12 ms for a depth-9 scan, what a refinement would otherwise measure for
// it); the shapes are
// computed by the first refinement that matches them, so the first source pays what it would
// have paid anyway. Results are the same bit for bit. Safe to share across threads (a shape is
// computed by the one thread that claims it; a thread that finds it being computed computes its own
// copy). It points at the tree, which must outlive it and stay unchanged.
class PreparedRefinementTarget {
 public:
  // Depths from the options' coarsest (StageDepths' rule) to the tree's deepest, for the options'
  // min_count_for_covariance and line_normals_from_planes (unset: the choice for a source like the
  // target, ChooseLineNormalsFromPlanes on its own fraction twice; a pair whose choice differs
  // builds its own side). The other options do not matter. InvalidArgument: an empty tree, a
  // negative min_count_for_covariance, a coarsest_depth beyond the tree.
  static absl::StatusOr<std::shared_ptr<const PreparedRefinementTarget>> Prepare(
      const Octree& target, const TreeRefinementOptions& options = {});
  ~PreparedRefinementTarget();
  PreparedRefinementTarget(const PreparedRefinementTarget&) = delete;
  PreparedRefinementTarget& operator=(const PreparedRefinementTarget&) = delete;

  const Octree& tree() const { return *tree_; }
  // Memory it holds (indexes and shapes), for a caller's budget.
  size_t bytes() const { return bytes_; }

  struct Sides;  // tree_refinement.cc
  const Sides& sides() const { return *sides_; }
  // LineShapedFraction of the tree for the options it was prepared with.
  std::optional<double> line_shaped_fraction() const { return line_shaped_fraction_; }

 private:
  PreparedRefinementTarget();
  const Octree* tree_ = nullptr;
  std::optional<double> line_shaped_fraction_;
  std::unique_ptr<const Sides> sides_;
  size_t bytes_ = 0;
};

// `result.information` with its rotation rows and columns divided by rotation_lever_arms, so
// that every direction is a displacement in metres: the matrix whose eigenvalues
// normalized_eigenvalues are and whose weakest directions degenerate_directions hold.
Eigen::Matrix<double, 6, 6> InformationInMetres(const TreeRefinementResult& result);

// A motion D (applied on the left of a T_target_source) in the information's perturbation,
// D = [exp(w) | c - exp(w) c + v] with c = information_center, as (w scaled by
// rotation_lever_arms, v): metres throughout, the units of InformationInMetres' directions.
Eigen::Matrix<double, 6, 1> MotionInMetres(const TreeRefinementResult& result,
                                           const Eigen::Isometry3d& motion);
// The inverse: the motion D of `u` (rotation rows in metres of lever arm, then translation).
Eigen::Isometry3d MotionFromMetres(const TreeRefinementResult& result,
                                   const Eigen::Matrix<double, 6, 1>& u);

// Refines `initial_T_target_source`. Errors (InvalidArgument): a non-finite or non-rigid initial
// transform, empty trees, depths outside the trees or coarsest > finest, non-positive iteration
// counts, thresholds or scales. Geometric failures (no overlap, degeneracy) are NOT errors: they
// come back as a result with valid = false and the reason. Deterministic, one thread.
absl::StatusOr<TreeRefinementResult> RefineOnTrees(const Octree& source, const Octree& target,
                                                   const Eigen::Isometry3d& initial_T_target_source,
                                                   const TreeRefinementOptions& options = {});
// The same, sharing `cache` with other calls on these two trees.
absl::StatusOr<TreeRefinementResult> RefineOnTrees(const Octree& source, const Octree& target,
                                                   const Eigen::Isometry3d& initial_T_target_source,
                                                   const TreeRefinementOptions& options,
                                                   TreeRefinementCache& cache);

}  // namespace rpsr::core

#endif  // RPSR_CORE_REFINE_TREE_REFINEMENT_H_
