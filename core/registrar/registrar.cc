#include "core/registrar/registrar.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <map>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "absl/status/status.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "core/data/registration_metrics.h"
#include "core/io/file_bytes.h"
#include "core/net/rpsr_net.h"
#include "core/refine/cell_index.h"
#include "core/refine/correlative_start.h"
#include "core/refine/degenerate_hold.h"
#include "core/refine/dominant_plane.h"
#include "core/refine/extent_slide.h"
#include "core/refine/far_valley.h"
#include "core/refine/node_closeness.h"
#include "core/refine/principal_axes_start.h"
#include "core/refine/screw_turns.h"
#include "core/refine/symmetry_starts.h"
#include "core/refine/weak_direction_chamfer.h"
#include "core/refine/weak_direction_start.h"
#include "core/registrar/confidence_model.h"
#include "core/registrar/embedded_models.h"

namespace rpsr::core {
namespace {

// The refinement's default start (depth 3: 30 m cells on a 240 m LiDAR cube) pulls in large
// motions but on deep trees it can also lock onto a wrong coarse match that a start four depths
// above the finest (7.5 m cells) avoids: simulated LiDAR pairs fail either way on different sets
// (calibration pairs 5 and 10 frames apart: 80 of 128 from the finer start, 104 from depth 3;
// pairs 3 m apart: 46 of 48 from the finer start, 40 from depth 3; this fallback: 47 and 48 of 48).
// So on deep trees the finer start goes first and the depth-3 start runs only when it ends invalid;
// the valid result with the higher fitness (then the lower inlier RMSE) wins. Shallow trees
// (objects, depth 6) have one start: depth 3. A caller's coarsest_depth is kept.
bool Better(const TreeRefinementResult& a, const TreeRefinementResult& b) {
  if (a.valid != b.valid) return a.valid;
  if (a.fitness != b.fitness) return a.fitness > b.fitness;
  return a.inlier_rmse < b.inlier_rmse;
}

// Trees deep enough for the finer start below (scene-scale clouds: LiDAR scans to depth 9).
bool IsDeepPair(const Octree& source, const Octree& target, const TreeRefinementOptions& options) {
  const auto [coarsest, finest] = StageDepths(source, target, options);
  return options.coarsest_depth < 0 && finest - 4 > coarsest;
}

// `cache` is shared by every start on the pair (the nodes' regularisation is done once).
absl::StatusOr<TreeRefinementResult> RefineWithFallback(const Octree& source, const Octree& target,
                                                        const Eigen::Isometry3d& from,
                                                        const TreeRefinementOptions& options,
                                                        TreeRefinementCache& cache) {
  if (options.evaluate_only || !IsDeepPair(source, target, options)) {
    return RefineOnTrees(source, target, from, options, cache);
  }
  TreeRefinementOptions finer_start = options;
  finer_start.coarsest_depth = StageDepths(source, target, options).second - 4;
  absl::StatusOr<TreeRefinementResult> first =
      RefineOnTrees(source, target, from, finer_start, cache);
  if (!first.ok() || first->valid) return first;
  absl::StatusOr<TreeRefinementResult> second = RefineOnTrees(source, target, from, options, cache);
  if (!second.ok()) return first;
  return Better(*second, *first) ? second : first;
}

// A later start's result (the initial guess's, the searched one's) replaces the answer so far only
// when it is clearly better: valid where the other is not, or one more percent of the source
// overlapping. On objects with a translational or rotational symmetry both starts reach equally
// good fits in different poses, and the network's start, which saw the shapes, is the better
// prior there.
bool ClearlyBetter(const TreeRefinementResult& a, const TreeRefinementResult& b) {
  if (a.valid != b.valid) return a.valid;
  return a.valid && a.fitness > b.fitness + 0.01;
}

// Where neither answer is clearly better (both valid, within a percent of overlap), the later one
// still replaces the answer so far when its finest nodes lie closer to the target's
// (MeanNodeDistanceCells) by more than this fraction. Fitness counts a node as fitted near its
// partner's plane, so a twin slid or twisted along the surface (a helix spring turned along its
// screw) fits as well by it; the distance to the nearest node does not. Unseen object study
// (`rpsr eval --protocol objects --split unseen --count 100 --disturbance D --level L`, the ten
// settings): see tests/bench/notes/refinement-notes.md, *Two starts that fit alike*.
constexpr double kCloserBy = 0.01;

bool Closer(double later_cells, double so_far_cells) {
  return later_cells >= 0.0 && so_far_cells >= 0.0 &&
         later_cells < (1.0 - kCloserBy) * so_far_cells;
}

// The symmetric start's twin is kept at up to this much less fitness than the answer: refined
// from the right tooth, unseen gears fit 0.957-0.998 against their tooth-off answers' 0.987-1.000
// (tests/bench/notes/refinement-notes.md, *Gears a tooth off*), so ClearlyBetter's one percent
// would refuse the right tooth; its breaking nodes meeting decide instead.
constexpr double kTwinFitnessSlack = 0.05;

// The sensor-aligned check's margin: a searched answer replaces a sensor-aligned one when it
// leaves this much less of the source's structure off the ground without a target partner within
// a finest cell (OffPlaneFarFractions). Held-out LiDAR pairs 5 and 10 frames apart (pair seeds
// 3, 1003, 5003, 7003; 512 pairs): the 10 slides that ended within 1.9 m of the sensor-aligned
// pose leave 0.10-0.39 more than the searched start refined to the truth (an 11th, at 1.97 m, is
// why the trigger is a whole search cell); on 185 pairs 1-2 frames apart, where the check runs on
// right answers, an earlier variant's searched start (turns too, about the identity) refined back
// onto them (at most 0.002 fewer); the shipped one refines none of them (below).
constexpr double kStructureFarDrop = 0.05;

// What the sensor-aligned check found: another start, refined, that fits the structure off the
// ground clearly better than the answer.
struct StructureStart {
  Eigen::Isometry3d start_pose = Eigen::Isometry3d::Identity();
  TreeRefinementResult refined;
};

// The sensor-aligned check's search (see Finish): nullopt when the answer does not put the
// sensors within a search cell of each other, either tree lacks a dominant plane, the search lands
// near the answer, or the other start, refined, is invalid or not clearly better by the
// structure. `target_plane_prepared`: the target's FindDominantPlane at `finest_depth` when a
// prepared target holds it (null: found here). `starts` counts a refinement run here.
std::optional<StructureStart> FindStructureStart(const Octree& source, const Octree& target,
                                                 const DominantPlane* target_plane_prepared,
                                                 const Eigen::Isometry3d& answer, int finest_depth,
                                                 const TreeRefinementOptions& refinement,
                                                 TreeRefinementCache& cache, int& starts) {
  CorrelativeSearchOptions search;
  const int search_depth = CorrelativeSearchDepth(source, target, search);
  const double aligned_within = CellEdge(target, search_depth);
  if (answer.translation().norm() >= aligned_within) return std::nullopt;
  const DominantPlane source_plane = FindDominantPlane(source, finest_depth);
  if (!source_plane.found) return std::nullopt;
  DominantPlane found_here;
  if (target_plane_prepared == nullptr) found_here = FindDominantPlane(target, finest_depth);
  const DominantPlane& target_plane =
      target_plane_prepared != nullptr ? *target_plane_prepared : found_here;
  if (!target_plane.found) return std::nullopt;
  const std::vector<uint8_t> source_off = source_plane.OffPlaneNodes(source, search_depth);
  const std::vector<uint8_t> target_off = target_plane.OffPlaneNodes(target, search_depth);
  search.source_nodes = &source_off;
  search.target_nodes = &target_off;
  // Shifts only, about the answer: the rings are round, so a sensor-aligned answer's turn is
  // right (the slides' rotation errors were 0.02-0.08 degrees), and searching turns too would
  // cost ~2.5 ms a pair instead of ~0.1.
  search.max_yaw_deg = 0.0;
  absl::StatusOr<CorrelativeStart> searched = FindCorrelativeStart(source, target, answer, search);
  if (!searched.ok()) return std::nullopt;
  // A candidate within a search cell of the answer would be refined back onto it: on 256 scan
  // pairs 1-2 frames apart (pair seeds 1003, 5003), where the check runs on right answers, none
  // refined a further start and no answer moved.
  const Eigen::Vector3d source_centre = source.level(0).center_of_mass[0].cast<double>();
  if (ErrorOf(searched->T_target_source, answer).rotation_deg < 2.0 &&
      (searched->T_target_source * source_centre - answer * source_centre).norm() <
          aligned_within) {
    return std::nullopt;
  }
  absl::StatusOr<TreeRefinementResult> r =
      RefineWithFallback(source, target, searched->T_target_source, refinement, cache);
  ++starts;
  if (!r.ok() || !r->valid) return std::nullopt;
  const std::vector<double> far = OffPlaneFarFractions(
      source, source_plane, target, target_plane, {answer, r->T_target_source}, finest_depth, 1.0);
  if (far[0] < 0.0 || far[1] < 0.0 || far[1] > far[0] - kStructureFarDrop) return std::nullopt;
  return StructureStart{searched->T_target_source, *std::move(r)};
}

// The search over every turn (Finish) refines its candidate only when it scores at least this
// many times the search within +-20 degrees: a junction's turn lands twice as much of the scan in
// occupied cells, a turn of two unrelated streets about as much.
constexpr double kTurnedScoreRatio = 1.5;

// A first answer at least this confident (a calibrated probability of being within 1 degree and
// 1% of the extent) is kept without trying the initial guess as a second start.
constexpr double kConfidentEnough = 0.9;

// The centroid-aligned start (RegistrationOptions::search_centroid_start) runs when the answer
// leaves the two clouds' centres of mass farther apart than this many cells of SymmetryDepth:
// half a cell, chosen before measuring (a right answer on a whole object leaves them a sampling's
// worth apart); not tuned.
constexpr double kCentroidStartMinCells = 0.5;
// A confident answer gets the centroid-aligned start too when it leaves the centres of mass this
// many cells apart and overlaps below kWholeOverlap, and keeps it only when the refined start
// overlaps at least that (and clearly better, and is not the answer again): a sofa slid by 0.217
// along its length read 0.989 confident at fitness 0.946 (0.979 at the truth), stairs slid by a
// step under crops of 10% and 20% read 0.98-0.99 at 0.90-0.95. Under a crop of 40% a right
// answer (0.977) lost to its centred start (1.000), which the overlap rule now leaves alone; seed
// 5's sofa under a 40% crop is still lost (0.014 degree -> 0.18 off, at 0.25 confidence)
// (refinement-notes.md, *The centroid-aligned start for confident answers*).
constexpr double kConfidentCentroidStartMinCells = 2.0;
constexpr double kWholeOverlap = 0.97;

// A principal-axes start this close to the answer (degrees of rotation between them) would be
// refined back onto it; the right flip of a poor answer lay 43-49 degrees from it.
constexpr double kPrincipalAxesNearDeg = 20.0;

// The principal-axes starts run for answers below this confidence (a poor answer: the start owes
// nothing to the network's estimate, and its flips are refined only where that one is doubted),
// and refine at most this many of the four sign choices, the likeliest first (the right one was
// the likeliest on the real meshes' misses).
constexpr double kPrincipalAxesMaxAnswerConfidence = 0.5;
constexpr int kPrincipalAxesMaxStarts = 2;

// The principal-axes starts run for valid answers that leave more than a fifth of the source
// without a partner: on real meshes the answers tens of degrees off fit 0.49-0.63, right ones
// 0.95 or more on whole objects. An unseen object cropped by 30% whose answer was slid 0.18
// (invalid, at fitness 0.97) was flipped by half a turn at 0.988 confidence before both gates.
constexpr double kPrincipalAxesMaxFitness = 0.8;

// The extent slide leaves an answer already this confident alone: the ends of rounded shapes are
// sampled only near their tips, and on a real hand (12 real meshes of session 37's set B, 100
// clean pairs) the two fingertip ends agreed on a slide of a wrong 0.018 for a right answer at
// 0.985. On the unseen study no answer the slide brought back read 0.95 or more before it, and one
// it lost did (0.983).
constexpr double kExtentSlideMaxAnswerConfidence = 0.95;

// The weak-direction chamfer (search_weak_direction_chamfer) reads every finest node's nearest
// partner, so it runs on answers that overlap almost wholly (where the source is cropped, a node
// near the cut has no partner wherever it moves) and that the noise polish left alone (where the
// nodes scatter by half a cell or more about the surface, their distances are the noise's:
// jittered objects took 38 -> 44 ms a pair with the chamfer and gained nothing). The same below
// 0.95 confidence as the extent slide.
constexpr double kWeakChamferMinFitness = 0.98;

// A principal-axes start's answer must fit clearly better (ClearlyBetter) and read at least this
// much more confident than the answer: on partial views (each cloud cropped along its own
// direction) the two clouds' principal frames differ, and a flip turned half a circle can
// overlap more of the other view than the right pose while reading no more confident (0.04 and
// 0.05 against the answers' 0.06 and 0.17 on two real-mesh pairs).
constexpr double kPrincipalAxesConfidenceGain = 0.1;

// ... and read at least this confident: a start that owes nothing to the network's estimate must
// be believed more than doubted. Under 40% outliers an unseen answer 1.3 degrees off (0.13
// confident, its fitness low for the outliers) was replaced by a flip half a turn off that read
// 0.1 more.
constexpr double kPrincipalAxesMinConfidence = 0.5;

// The half-turn start (RegistrationOptions::search_half_turn_start). A half turn is tried where
// the answer turned by it leaves at most this many more of the nodes one depth above the finest
// without a partner within 1.9 cells (TwoWayFarNodeFractions) than the answer: a generic target's
// half turns leave ~0.25 of them, a guitar's front-to-back flip none (its neck and bridge lie
// within that reach of the body).
constexpr double kHalfTurnFarMargin = 0.02;
// The refined twin is kept when its fitness is at least this much above the answer's and at least
// kHalfTurnMinFitness, and its finest nodes lie kHalfTurnCloserBy closer. Set on the unseen
// study's three seeds (6,300 answers, every near-symmetric half turn refined and taken, then
// sorted by the truth): the three right twins were guitars flipped under crops and outliers
// (fitness +0.13 and +0.18 with nodes 13-15% closer, and one +0.00 that no margin keeps); of the
// 457 wrong ones, those fitting better did so by 0.03 or less but two under crops (0.57 -> 0.77,
// 18% closer; 0.71 -> 0.84, no closer). Checked after: seeds 4 and 5, 2,000 clean pairs, 1,200
// real-mesh answers (refinement-notes.md, *The half-turn start*).
constexpr double kHalfTurnFitnessGain = 0.05;
constexpr double kHalfTurnMinFitness = 0.85;
constexpr double kHalfTurnCloserBy = 0.05;

// Two starts closer than this converge to the same result: 0.25 degrees, and the source's centre
// of mass placed within 0.25% of the target cube's half-length (where it is placed, not the
// translations: those differ with the clouds' distance from their frame's origin).
bool NearlyEqual(const Eigen::Isometry3d& a, const Eigen::Isometry3d& b, const Octree& source,
                 const Octree& target) {
  const Eigen::Vector3d centre = source.level(0).center_of_mass[0].cast<double>();
  return ErrorOf(a, b).rotation_deg < 0.25 &&
         (a * centre - b * centre).norm() < 0.0025 * target.half_length();
}

using Clock = std::chrono::steady_clock;

double SecondsSince(Clock::time_point start) {
  return std::chrono::duration<double>(Clock::now() - start).count();
}

// The network reads depths 2..5 with neighbour tables to depth 5 (net_input.h).
constexpr int kNetMinDepth = 5;

bool UsesNet(RegistrationMode mode) { return mode != RegistrationMode::kRefine; }

// Whether net+refine runs its first pass alone and the rest only for an unconfident answer.
bool DefersLaterPasses(const RegistrationOptions& options) {
  return options.mode == RegistrationMode::kNetRefine && options.later_passes_only_when_unconfident;
}

int DefaultPasses(const RegistrationOptions& options, int model_passes) {
  if (options.passes > 0) return options.passes;
  if (options.mode == RegistrationMode::kNetRefine) return std::min(model_passes, kNetRefinePasses);
  return model_passes;
}

absl::Status CheckRigid(const Eigen::Isometry3d& T) {
  const Eigen::Matrix4d& m = T.matrix();
  if (!m.allFinite()) {
    return absl::InvalidArgumentError("initial_T_target_source is not finite");
  }
  const Eigen::Matrix3d R = m.topLeftCorner<3, 3>();
  if (!(R.transpose() * R).isApprox(Eigen::Matrix3d::Identity(), 1e-6) ||
      std::abs(R.determinant() - 1.0) > 1e-6 ||
      !m.bottomRows<1>().isApprox(Eigen::RowVector4d(0, 0, 0, 1), 1e-12)) {
    return absl::InvalidArgumentError(
        "initial_T_target_source is not rigid (its 3x3 block must be a rotation: orthonormal, "
        "determinant +1)");
  }
  return absl::OkStatus();
}

absl::Status CheckTree(const Octree* tree, absl::string_view which, RegistrationMode mode) {
  if (tree == nullptr) return absl::InvalidArgumentError(absl::StrCat("the ", which, " is null"));
  if (tree->max_depth() < 0 || tree->num_points() == 0) {
    return absl::InvalidArgumentError(absl::StrCat("the ", which, " tree is empty"));
  }
  if (UsesNet(mode) &&
      (tree->max_depth() < kNetMinDepth || tree->neighbor_max_depth() < kNetMinDepth)) {
    return absl::InvalidArgumentError(
        absl::StrCat("the ", which, " tree is too shallow for the network (depth ",
                     tree->max_depth(), ", neighbour tables to depth ", tree->neighbor_max_depth(),
                     "; mode ", RegistrationModeName(mode), " needs both >= ", kNetMinDepth,
                     ", the BarnesHutTreeOptions defaults)"));
  }
  return absl::OkStatus();
}

absl::Status ValidateRequest(const Octree* source, const Octree* target,
                             const RegistrationOptions& options) {
  if (absl::Status s = CheckTree(source, "source", options.mode); !s.ok()) return s;
  if (absl::Status s = CheckTree(target, "target", options.mode); !s.ok()) return s;
  const Eigen::Isometry3d initial =
      options.initial_T_target_source.value_or(Eigen::Isometry3d::Identity());
  if (absl::Status s = CheckRigid(initial); !s.ok()) return s;
  // The refinement's own checks (depths within the trees, option ranges); mode net measures with
  // the same options.
  if (absl::Status s = ValidateTreeRefinement(*source, *target, initial, options.refinement);
      !s.ok()) {
    return absl::InvalidArgumentError(s.message());
  }
  return absl::OkStatus();
}

// What the network produced for one pair (empty for mode refine).
struct NetOutput {
  NetEstimate estimate;
  double seconds = 0.0;
  // Passes held back until the first answer is known (RegistrationOptions::
  // later_passes_only_when_unconfident); `pair` is the pair those passes would continue, with the
  // target's encoding kept in `encoding` when the request had no prepared target.
  int deferred_passes = 0;
  NetPair pair;
  std::shared_ptr<const NetTargetEncoding> encoding;
};

bool IsFiniteRigid(const Eigen::Isometry3d& T) { return T.matrix().allFinite(); }

}  // namespace

absl::StatusOr<RegistrationMode> ParseRegistrationMode(absl::string_view name) {
  if (name == "net") return RegistrationMode::kNet;
  if (name == "net+refine") return RegistrationMode::kNetRefine;
  if (name == "refine") return RegistrationMode::kRefine;
  return absl::InvalidArgumentError(
      absl::StrCat("unknown registration mode '", name, "' (net, net+refine or refine)"));
}

absl::string_view RegistrationModeName(RegistrationMode mode) {
  switch (mode) {
    case RegistrationMode::kNet:
      return "net";
    case RegistrationMode::kNetRefine:
      return "net+refine";
    case RegistrationMode::kRefine:
      return "refine";
  }
  return "unknown";
}

struct Registrar::State {
  std::unique_ptr<RpsrNet> net;
  ConfidenceModel confidence;
  std::string description;

  // `prepared` (optional): the target's prepared side (its refinement part is used here).
  RegistrationResult Finish(const Octree& source, const Octree& target,
                            const RegistrationOptions& options, const NetOutput* net_output,
                            const PreparedTarget* prepared, Clock::time_point start) const;
};

Registrar::Registrar() : state_(std::make_unique<State>()) {}
Registrar::~Registrar() = default;

absl::StatusOr<std::unique_ptr<Registrar>> Registrar::Create(const RegistrarConfig& config) {
  std::unique_ptr<Registrar> registrar(new Registrar());
  State& state = *registrar->state_;
  std::string model_name;
  std::optional<std::string> confidence_text;
  std::string confidence_source;
  if (!config.model_path.empty()) {
    absl::StatusOr<std::unique_ptr<RpsrNet>> net = RpsrNet::Load(config.model_path);
    if (!net.ok()) return net.status();
    state.net = *std::move(net);
    model_name = config.model_path;
    // A calibration belongs to its weights: the one beside the file, if any.
    const std::filesystem::path beside =
        std::filesystem::path(config.model_path).parent_path() / "confidence.txt";
    std::error_code ec;
    if (config.confidence_path.empty() && std::filesystem::exists(beside, ec)) {
      absl::StatusOr<std::string> text = ReadFileBytes(beside.string(), size_t{1} << 24);
      if (!text.ok()) return text.status();
      confidence_text = *std::move(text);
      confidence_source = beside.string();
    }
  } else {
    const std::string name =
        config.model.empty() ? std::string(kDefaultEmbeddedModel) : config.model;
    absl::StatusOr<EmbeddedModel> embedded = FindEmbeddedModel(name);
    if (!embedded.ok()) return embedded.status();
    absl::StatusOr<std::unique_ptr<RpsrNet>> net =
        RpsrNet::LoadFromBytes(embedded->weights, absl::StrCat("embedded model '", name, "'"));
    if (!net.ok()) return net.status();
    state.net = *std::move(net);
    model_name = absl::StrCat(name, " (embedded)");
    if (config.confidence_path.empty() && embedded->confidence) {
      confidence_text = std::string(*embedded->confidence);
      confidence_source = absl::StrCat("embedded core/models/", name, "/confidence.txt");
    }
  }
  if (!config.confidence_path.empty()) {
    absl::StatusOr<std::string> text = ReadFileBytes(config.confidence_path, size_t{1} << 24);
    if (!text.ok()) return text.status();
    confidence_text = *std::move(text);
    confidence_source = config.confidence_path;
  }
  if (confidence_text) {
    absl::StatusOr<ConfidenceModel> model = ConfidenceModel::Parse(*confidence_text);
    if (!model.ok()) {
      return absl::InvalidArgumentError(
          absl::StrCat(confidence_source, ": ", model.status().message()));
    }
    state.confidence = *std::move(model);
  } else {
    state.confidence = ConfidenceModel::Uncalibrated();
    confidence_source = "none shipped: uncalibrated heuristic";
  }
  const RpsrNetConfig& c = state.net->config();
  state.description = absl::StrFormat(
      "%s: RPSRNet conv widths %d/%d/%d, embedding %d, %d heads, feed-forward %d, %d "
      "parameters, %d passes by default (net+refine: %d); confidence: %s",
      model_name, c.conv_widths[0], c.conv_widths[1], c.conv_widths[2], c.embedding_width,
      c.attention_heads, c.feedforward_width, state.net->NumParameters(), c.passes,
      std::min(c.passes, kNetRefinePasses), confidence_source);
  return registrar;
}

std::string Registrar::model_description() const { return state_->description; }

RegistrationResult Registrar::State::Finish(const Octree& source, const Octree& target,
                                            const RegistrationOptions& options,
                                            const NetOutput* net_output,
                                            const PreparedTarget* prepared,
                                            Clock::time_point start) const {
  RegistrationResult result;
  result.mode = options.mode;
  const Eigen::Isometry3d initial =
      options.initial_T_target_source.value_or(Eigen::Isometry3d::Identity());
  result.net_T_target_source = initial;
  result.T_target_source = initial;
  if (net_output != nullptr) {
    result.net_T_target_source = net_output->estimate.T_target_source;
    result.net_score_peak = net_output->estimate.score_peak;
    result.timings.net_seconds = net_output->seconds;
    if (!IsFiniteRigid(result.net_T_target_source)) {
      result.T_target_source = initial;
      result.failure_reason = "the network's output is not finite";
      result.timings.total_seconds = SecondsSince(start) + result.timings.net_seconds;
      return result;
    }
  }

  // Refinement (or, in mode net, one measuring evaluation at the network's estimate).
  const auto refine_start = Clock::now();
  TreeRefinementOptions refinement = options.refinement;
  Eigen::Isometry3d from = initial;
  if (options.mode != RegistrationMode::kRefine) from = result.net_T_target_source;
  if (options.mode == RegistrationMode::kNet) refinement.evaluate_only = true;
  TreeRefinementCache cache(prepared != nullptr ? prepared->refinement : nullptr);
  absl::StatusOr<TreeRefinementResult> refined =
      RefineWithFallback(source, target, from, refinement, cache);
  double confidence_seconds = 0.0;
  // The target's near-symmetries, object-scale pairs only: the confidence's twin margin reads
  // them, the round-axis start runs only without them, the symmetric start only with them. A
  // target without a round principal axis costs one 3x3 eigen-decomposition; a round one its
  // harmonics and one node-distance measure. A prepared target found them once.
  const auto symmetry_start = Clock::now();
  std::vector<SelfSymmetry> found_here;
  const std::vector<SelfSymmetry>* symmetries_of_target = &found_here;
  if (!IsDeepPair(source, target, refinement)) {
    if (prepared != nullptr && prepared->symmetries.has_value()) {
      symmetries_of_target = &*prepared->symmetries;
    } else {
      found_here = FindSelfSymmetries(target);
    }
  }
  const std::vector<SelfSymmetry>& symmetries = *symmetries_of_target;
  // A body of revolution (a vase, a round table; FindContinuousSymmetry): nothing measures the
  // turn about its axis, so it is reported as a degenerate direction below, as the information
  // reports a corridor's length. Looked for only without near-symmetries (a gear's teeth are not
  // a continuous symmetry: its turns by every 15 degrees left 0.09 or more of its nodes far).
  std::optional<ContinuousSymmetry> revolution;
  if (!IsDeepPair(source, target, refinement) && symmetries.empty()) {
    revolution = prepared != nullptr && prepared->symmetries.has_value()
                     ? prepared->revolution
                     : FindContinuousSymmetry(target);
  }
  confidence_seconds += SecondsSince(symmetry_start);
  // The network's estimates after each pass run so far (more when deferred passes run below).
  std::vector<Eigen::Isometry3d> net_per_pass;
  if (net_output != nullptr) net_per_pass = net_output->estimate.per_pass;
  // Fills `out` from a refinement that started at `start_pose`, confidence included.
  auto settle = [&](const TreeRefinementResult& r, const Eigen::Isometry3d& start_pose,
                    RegistrationResult& out) {
    out.T_target_source = r.T_target_source;
    out.valid = r.valid;
    out.failure_reason = r.failure_reason;
    out.fitness = r.fitness;
    out.inlier_rmse = r.inlier_rmse;
    out.iterations = r.iterations;
    out.converged = r.converged;
    out.information = r.information;
    out.degenerate_axes = r.degenerate_axes;
    out.num_degenerate = r.num_degenerate;
    out.line_normals_from_planes = r.line_normals_from_planes;
    out.surface_scatter_cells = r.surface_scatter_cells;
    out.noise_polished = r.noise_polished;
    const auto confidence_start = Clock::now();
    ConfidenceInputs inputs;
    inputs.result = &out;
    inputs.refinement = &r;
    inputs.source = &source;
    inputs.target = &target;
    inputs.net_per_pass = net_per_pass;
    inputs.refine_start = start_pose;
    inputs.symmetries = &symmetries;
    out.confidence_features = ConfidenceFeatureVector(inputs);
    out.confidence = confidence.Confidence(out.confidence_features, out.valid, out.num_degenerate);
    confidence_seconds += SecondsSince(confidence_start);
  };
  if (!refined.ok()) {
    // Inputs were validated: only an unexpected failure lands here.
    result.timings.refine_seconds = SecondsSince(refine_start);
    result.T_target_source = from;
    result.failure_reason = absl::StrCat("refinement failed: ", refined.status().message());
    result.timings.total_seconds = SecondsSince(start) + result.timings.net_seconds;
    return result;
  }
  settle(*refined, from, result);
  result.start = options.mode == RegistrationMode::kRefine ? "initial" : "network";
  result.starts = 1;
  TreeRefinementResult best = *std::move(refined);  // the answer settled so far
  // A further start: refined, and settled when clearly better than the answer so far, or as
  // good by fitness with its finest nodes closer (kCloserBy). The answer so far's
  // MeanNodeDistanceCells at the finest depth is measured when first needed.
  const int finest_depth = StageDepths(source, target, refinement).second;
  std::optional<double> best_closeness;
  auto closeness = [&](const TreeRefinementResult& r) {
    return MeanNodeDistanceCells(source, target, r.T_target_source, finest_depth);
  };
  // `replaces_unless_worse`: the roles of the rule swapped, the start's answer replacing the one
  // so far unless that one is clearly better or, fitting alike, closer (no twin rule).
  auto try_start = [&](const Eigen::Isometry3d& start_pose, const char* name,
                       bool replaces_unless_worse = false) {
    absl::StatusOr<TreeRefinementResult> r =
        RefineWithFallback(source, target, start_pose, refinement, cache);
    ++result.starts;
    if (!r.ok()) return;
    std::optional<double> r_closeness;
    bool take = false;
    if (replaces_unless_worse) {
      take = !ClearlyBetter(best, *r);
      if (take && r->valid && best.valid && !ClearlyBetter(*r, best) &&
          !NearlyEqual(r->T_target_source, best.T_target_source, source, target)) {
        if (!best_closeness) best_closeness = closeness(best);
        r_closeness = closeness(*r);
        take = !Closer(*best_closeness, *r_closeness);
      }
    } else if (r->valid && best.valid &&
               AreSymmetricTwins(source, target, r->T_target_source, best.T_target_source,
                                 symmetries)) {
      // Twins (a gear a tooth apart) fit alike by fitness and node distance; the few nodes of the
      // feature that breaks the symmetry decide (symmetry_starts.h).
      const SelfSymmetryOptions twin;
      take = TwoWayFarFraction(source, target, r->T_target_source, twin) <=
             TwoWayFarFraction(source, target, best.T_target_source, twin) -
                 twin.min_far_fraction_drop;
    } else if (ClearlyBetter(*r, best)) {
      take = true;
    } else if (r->valid && best.valid && !ClearlyBetter(best, *r) &&
               !NearlyEqual(r->T_target_source, best.T_target_source, source, target)) {
      if (!best_closeness) best_closeness = closeness(best);
      r_closeness = closeness(*r);
      take = Closer(*r_closeness, *best_closeness);
    }
    if (take) {
      settle(*r, start_pose, result);
      result.start = name;
      best = *std::move(r);
      best_closeness = r_closeness;  // unset when it was not measured
    }
  };
  // A start kept by a rule of its own (the weak-direction and symmetric starts', whose answers fit
  // alike with the answer so far by the rule above): refined, and settled when valid, within
  // kTwinFitnessSlack of the answer's fitness, and `keep(refined)`. Whether it was settled.
  auto try_start_kept_by = [&](const Eigen::Isometry3d& start_pose, const char* name,
                               const auto& keep) {
    absl::StatusOr<TreeRefinementResult> r =
        RefineWithFallback(source, target, start_pose, refinement, cache);
    ++result.starts;
    if (!r.ok() || !r->valid || !(r->fitness >= best.fitness - kTwinFitnessSlack) || !keep(*r)) {
      return false;
    }
    settle(*r, start_pose, result);
    result.start = name;
    best = *std::move(r);
    best_closeness.reset();
    return true;
  };
  // A move of the answer that is measured there, not refined (the extent slide, the
  // weak-direction chamfer: the stages would carry it back to their own minimum), kept when valid
  // and fitting within kTwinFitnessSlack of the answer (by fitness the two are alike). With
  // `cap_confidence`, the kept answer reads at most the answer's confidence.
  auto try_measured_move = [&](const Eigen::Isometry3d& moved, const char* name,
                               bool cap_confidence) {
    TreeRefinementOptions measure = refinement;
    measure.evaluate_only = true;
    absl::StatusOr<TreeRefinementResult> r =
        RefineWithFallback(source, target, moved, measure, cache);
    ++result.starts;
    if (!r.ok() || !r->valid || !(r->fitness >= best.fitness - kTwinFitnessSlack)) return;
    const double before = result.confidence;
    settle(*r, moved, result);
    if (cap_confidence) result.confidence = std::min(result.confidence, before);
    result.start = name;
    best = *std::move(r);
    best_closeness.reset();
  };
  const bool net_refine = options.mode == RegistrationMode::kNetRefine;
  // The network's deferred passes (RegistrationOptions::later_passes_only_when_unconfident): run
  // from the first pass's estimate only when its answer is not confident, their estimate refined
  // as a further start. Their time is the network's, not the refinement's.
  double deferred_net_seconds = 0.0;
  // (deferred_passes is set for net+refine requests only, DefersLaterPasses.)
  if (net_output != nullptr && net_output->deferred_passes > 0 &&
      result.confidence < kConfidentEnough) {
    NetPair pair = net_output->pair;
    pair.initial = net_output->estimate.T_target_source;
    const auto net_start = Clock::now();
    absl::StatusOr<std::vector<NetEstimate>> later =
        net->Estimate(absl::MakeConstSpan(&pair, 1), net_output->deferred_passes);
    deferred_net_seconds = SecondsSince(net_start);
    if (later.ok() && IsFiniteRigid(later->front().T_target_source)) {
      const NetEstimate& estimate = later->front();
      net_per_pass.insert(net_per_pass.end(), estimate.per_pass.begin(), estimate.per_pass.end());
      // The network's estimate of all its passes, whichever start the answer comes from.
      result.net_T_target_source = estimate.T_target_source;
      result.net_score_peak = estimate.score_peak;
      // The later passes' answer is what every pass first would have returned, so it replaces
      // the first answer unless that one is clearly better or closer (with the usual rule the
      // first answer stayed where the two fit alike, and 2-4 of 100 clean unseen pairs were lost
      // a seed). Twins are left to the symmetric start below. The variants measured and not
      // kept: evaluation-notes.md, *The later passes only for an unconfident first answer*.
      try_start(estimate.T_target_source, "network_later_passes", /*replaces_unless_worse=*/true);
    }
  }
  // The second start (RegistrationOptions::also_refine_from_initial) runs only when the first
  // answer is not already confident, and not when it would start where the first did.
  bool refined_from_initial = false;
  if (net_refine && options.also_refine_from_initial && result.confidence < kConfidentEnough &&
      !NearlyEqual(from, initial, source, target)) {
    try_start(initial, "initial");
    refined_from_initial = true;
  }
  // The third start (RegistrationOptions::search_scene_start): scene-scale trees whose answer is
  // still not confident. A search whose best candidate is the initial guess itself (no candidate
  // scored higher; ties go to it) would only repeat the second start when that one ran.
  if (net_refine && options.search_scene_start && result.confidence < kConfidentEnough &&
      IsDeepPair(source, target, refinement)) {
    absl::StatusOr<CorrelativeStart> searched = FindCorrelativeStart(source, target, initial);
    if (searched.ok() && (searched->score > searched->initial_score || !refined_from_initial)) {
      try_start(searched->T_target_source, "searched");
    }
    // Still not confident: the same search over every turn about z (41 angles, 9 degrees apart;
    // ~5 ms on a scan pair). A vehicle turning at a junction turns 40-70 degrees in a second (10
    // frames), beyond the search above: held-out pairs 10 frames apart ended 44-76 degrees off,
    // at confidence 0, where this search's best candidate was 0.3-4.3 degrees from the truth. Its
    // candidate is refined only when it turns beyond the search above, which covered the rest,
    // and lands clearly more of the source in occupied cells than that search's best
    // (kTurnedScoreRatio): on those four pairs 1.9-2.7 times as much; on 12 unrelated street
    // pairs, where a turned candidate refined to nothing better and cost ~15-70 ms, 0.86-1.07.
    if (result.confidence < kConfidentEnough && searched.ok()) {
      CorrelativeSearchOptions all_turns;
      all_turns.max_yaw_deg = 180.0;
      absl::StatusOr<CorrelativeStart> turned =
          FindCorrelativeStart(source, target, initial, all_turns);
      if (turned.ok() &&
          ErrorOf(turned->T_target_source, initial).rotation_deg >
              CorrelativeSearchOptions{}.max_yaw_deg &&
          turned->score >= kTurnedScoreRatio * searched->score) {
        try_start(turned->T_target_source, "searched_turns");
      }
    }
  }
  // The sensor-aligned check (RegistrationOptions::check_sensor_aligned_answers): a scene-scale
  // answer that puts the two sensors within a search cell of each other, where the ground's
  // rings and density line up whatever the scene did, is compared with the best start a search
  // over the structure off the ground finds. Judged by that structure alone: by fitness the
  // sensor-aligned pose wins. An answer invalid only for its degenerate geometry is checked too
  // (the rings' pull can leave a slide unconstrained along the street); the other start, refined,
  // must be valid and leave clearly fewer structure nodes without a partner (kStructureFarDrop).
  // net+refine takes it as its answer; mode refine, whose answer is the caller's start refined,
  // keeps its answer and reports it as doubted (its confidence capped), naming the other pose.
  // Mode refine doubts valid answers only (an invalid one reads 0 already); neither mode checks
  // when the caller asked for evaluation without updates.
  const bool checked = net_refine ? best.valid || best.num_degenerate > 0
                                  : options.mode == RegistrationMode::kRefine && best.valid;
  if (options.check_sensor_aligned_answers && !refinement.evaluate_only && checked &&
      IsDeepPair(source, target, refinement)) {
    const DominantPlane* prepared_plane = prepared != nullptr &&
                                                  prepared->dominant_plane.has_value() &&
                                                  prepared->dominant_plane_depth == finest_depth
                                              ? &*prepared->dominant_plane
                                              : nullptr;
    std::optional<StructureStart> structure =
        FindStructureStart(source, target, prepared_plane, best.T_target_source, finest_depth,
                           refinement, cache, result.starts);
    if (structure.has_value() && net_refine) {
      settle(structure->refined, structure->start_pose, result);
      result.start = "structure";
      best = std::move(structure->refined);
      best_closeness.reset();
    } else if (structure.has_value()) {
      result.confidence = std::min(result.confidence, confidence.degenerate_cap);
      result.structure_alternative_T_target_source = structure->refined.T_target_source;
      const Eigen::Vector3d t = structure->refined.T_target_source.translation();
      absl::StrAppend(&result.failure_reason, result.failure_reason.empty() ? "" : "; ",
                      absl::StrFormat("doubted: the structure off the ground plane fits "
                                      "another pose clearly better (translation %.3f %.3f %.3f, "
                                      "the sensors %.3g apart instead of %.3g); refine from it "
                                      "or use mode net+refine",
                                      t.x(), t.y(), t.z(), t.norm(),
                                      best.T_target_source.translation().norm()));
    }
  }
  // The round-axis start (RegistrationOptions::search_round_axis_start). Skipped where the target
  // has near-symmetries (`symmetries` non-empty: twins fit alike, and the twin margin speaks for
  // them); `symmetries` is also empty for scene-scale pairs, hence the depth test. A screw's turns
  // (round_axis_screw_turns: a helix spring) compete with the plain ones by the same count.
  if (net_refine && options.search_round_axis_start && best.valid &&
      result.confidence < kConfidentEnough && symmetries.empty() && !revolution.has_value() &&
      !IsDeepPair(source, target, refinement)) {
    constexpr double kRoundAxisStepDeg = 15.0;
    std::vector<SelfSymmetry> turns = TurnsAboutRoundAxes(target, kRoundAxisStepDeg);
    if (options.round_axis_screw_turns) {
      if (const std::optional<ScrewSymmetry> screw = FindScrewSymmetry(target)) {
        const std::vector<SelfSymmetry> screw_turns = ScrewTurns(*screw, kRoundAxisStepDeg);
        turns.insert(turns.end(), screw_turns.begin(), screw_turns.end());
      }
    }
    if (std::optional<SymmetricTwin> turned =
            BestSymmetricTwin(source, target, best.T_target_source, turns)) {
      try_start(turned->T_target_source, "round_axis");
    }
  }
  // The centroid-aligned start (RegistrationOptions::search_centroid_start): object-scale trees
  // whose answer is not confident and leaves the centres of mass apart. Taken by the usual rule:
  // under a crop the truth leaves them apart too, and the refined start then fits no better.
  // A confident answer only where it overlaps less than wholly and is farther off
  // (kConfidentCentroidStartMinCells), kept by the stricter rule of kWholeOverlap.
  if (net_refine && options.search_centroid_start && best.valid &&
      !IsDeepPair(source, target, refinement)) {
    const Eigen::Vector3d source_centre = source.level(0).center_of_mass[0].cast<double>();
    const Eigen::Vector3d target_centre = target.level(0).center_of_mass[0].cast<double>();
    const Eigen::Vector3d apart = target_centre - best.T_target_source * source_centre;
    const double apart_cells = apart.norm() / CellEdge(target, SymmetryDepth(source, target));
    Eigen::Isometry3d together = best.T_target_source;
    together.translation() += apart;
    if (result.confidence < kConfidentEnough) {
      if (apart_cells > kCentroidStartMinCells) try_start(together, "centroid");
    } else if (apart_cells > kConfidentCentroidStartMinCells && best.fitness < kWholeOverlap) {
      try_start_kept_by(together, "centroid", [&](const TreeRefinementResult& r) {
        return r.fitness >= kWholeOverlap && ClearlyBetter(r, best) &&
               !NearlyEqual(r.T_target_source, best.T_target_source, source, target);
      });
    }
  }
  // The principal-axes starts (RegistrationOptions::search_principal_axes_start): object-scale
  // trees whose answer is still poor. A flip within kPrincipalAxesNearDeg of the answer would be
  // refined back onto it and is skipped; a refined flip is taken by a rule of its own
  // (kPrincipalAxesConfidenceGain).
  if (net_refine && options.search_principal_axes_start && best.valid &&
      best.fitness < kPrincipalAxesMaxFitness &&
      result.confidence < kPrincipalAxesMaxAnswerConfidence &&
      !IsDeepPair(source, target, refinement)) {
    const int depth = SymmetryDepth(source, target);
    const std::vector<PrincipalAxesStart> flips =
        PrincipalAxesStarts(source, target, depth, WeakDirectionOptions{}.far_cells);
    int tried = 0;
    for (const PrincipalAxesStart& flip : flips) {
      if (tried >= kPrincipalAxesMaxStarts) break;
      if (ErrorOf(flip.T_target_source, best.T_target_source).rotation_deg <
          kPrincipalAxesNearDeg) {
        continue;
      }
      ++tried;
      absl::StatusOr<TreeRefinementResult> r =
          RefineWithFallback(source, target, flip.T_target_source, refinement, cache);
      ++result.starts;
      if (!r.ok() || !ClearlyBetter(*r, best)) continue;
      RegistrationResult candidate = result;
      settle(*r, flip.T_target_source, candidate);
      if (!(candidate.confidence >= result.confidence + kPrincipalAxesConfidenceGain) ||
          !(candidate.confidence >= kPrincipalAxesMinConfidence)) {
        continue;
      }
      candidate.start = "principal_axes";
      result = std::move(candidate);
      best = *std::move(r);
      best_closeness.reset();
    }
  }
  // The half-turn start (RegistrationOptions::search_half_turn_start): object-scale trees without
  // near-symmetries that are not bodies of revolution, whatever the confidence, where a half turn
  // about one of the target's principal axes maps it nearly onto itself (the answer turned by it
  // leaves at most kHalfTurnFarMargin more nodes without a partner than the answer: a guitar
  // flipped front to back). That twin is refined and kept only when it fits by a wide margin
  // better, overall and node by node (kHalfTurnFitnessGain, kHalfTurnMinFitness,
  // kHalfTurnCloserBy): under crops and outliers the wrong flip often fits a percent or two better.
  // An answer fitting above 1 - kHalfTurnFitnessGain is not searched.
  if (net_refine && options.search_half_turn_start && best.valid && symmetries.empty() &&
      !revolution.has_value() && !IsDeepPair(source, target, refinement) &&
      best.fitness + kHalfTurnFitnessGain <= 1.0) {
    // The twins of the answer as it stands here: the loop ends once one is kept.
    for (const Eigen::Isometry3d& twin :
         TwinsFittingAlike(source, target, best.T_target_source,
                           HalfTurnsAboutPrincipalAxes(target), kHalfTurnFarMargin)) {
      const bool kept = try_start_kept_by(twin, "half_turn", [&](const TreeRefinementResult& r) {
        // A twin refined back next to the answer is the answer better settled, not the other
        // flip: what it would change is the confidence alone.
        if (!(r.fitness >= best.fitness + kHalfTurnFitnessGain &&
              r.fitness >= kHalfTurnMinFitness) ||
            NearlyEqual(r.T_target_source, best.T_target_source, source, target)) {
          return false;
        }
        if (!best_closeness) best_closeness = closeness(best);
        const double twin_closeness = closeness(r);
        // Negative: not measurable, so not closer.
        return twin_closeness >= 0.0 && *best_closeness >= 0.0 &&
               twin_closeness <= (1.0 - kHalfTurnCloserBy) * *best_closeness;
      });
      if (kept) break;
    }
  }
  // The weak-direction start (RegistrationOptions::search_weak_direction_start), whatever the
  // confidence (springs off along their screw read up to 0.94). Kept by a rule of its own, as the
  // twins' is: along a shallow direction the truth and the answer fit alike by fitness and by the
  // nodes' mean distance, and only the nodes left without a partner tell them apart. First at
  // SymmetryDepth; when that keeps nothing, the caller asked for it (weak_direction_finest_round)
  // and the answer is clean and whole (its nodes scatter little about the target's surface,
  // nearly all of it overlaps), once more at the finest depth, where a few degrees of turn along a
  // screw move the coil's ends by a cell (WeakDirectionOptions' finest_* fields say why the gate).
  if (net_refine && options.search_weak_direction_start && best.valid && symmetries.empty() &&
      !revolution.has_value() && !IsDeepPair(source, target, refinement)) {
    const WeakDirectionOptions weak;
    // Whether the step at `depth` was refined and kept.
    auto try_weak_direction = [&](int depth) {
      std::optional<WeakDirectionStart> stepped =
          BestWeakDirectionStart(source, target, best, depth, weak);
      if (!stepped.has_value()) return false;
      return try_start_kept_by(
          stepped->T_target_source, "weak_direction", [&](const TreeRefinementResult& r) {
            return TwoWayFarNodeFractions(source, target, {r.T_target_source}, depth,
                                          weak.far_cells)
                       .front() <= stepped->answer_far_fraction - weak.min_far_fraction_drop;
          });
    };
    const int depth = SymmetryDepth(source, target);
    if (!try_weak_direction(depth) && options.weak_direction_finest_round && depth < finest_depth &&
        weak.FinestRoundAdmits(best.surface_scatter_cells, best.fitness)) {
      try_weak_direction(finest_depth);
    }
  }
  // The weak-direction chamfer (RegistrationOptions::search_weak_direction_chamfer): the answer
  // moved along its weakest direction to where the nodes that motion moves across their surface
  // meet the other cloud best (core/refine/weak_direction_chamfer.h), measured there as the
  // extent slide's is. Its confidence is at most the answer's: measured without refining, a moved
  // answer reads as settled as any (a spring moved 2 degrees the wrong way read 0.98), and the
  // move itself is not evidence the calibration has seen.
  // Read at each use: the chamfer's move changes the answer the valley then looks at.
  auto inside_weak_move_gates = [&] {
    return net_refine && best.valid && result.confidence < kExtentSlideMaxAnswerConfidence &&
           best.fitness >= kWeakChamferMinFitness && !best.noise_polished && symmetries.empty() &&
           !revolution.has_value() && !IsDeepPair(source, target, refinement);
  };
  if (options.search_weak_direction_chamfer && inside_weak_move_gates()) {
    if (std::optional<WeakChamferMove> moved =
            ChamferAlongWeakestDirection(source, target, best, finest_depth)) {
      try_measured_move(moved->T_target_source, "weak_direction_chamfer", /*cap_confidence=*/true);
    }
  }
  // The far-count valley (RegistrationOptions::search_far_valley): under the chamfer's gates,
  // the answer moved along its weakest direction to the middle of the valley in the count of
  // nodes without a partner (core/refine/far_valley.h, which also refuses a source that leaves a
  // tenth of the target uncovered), measured there as the chamfer's move is and for the same
  // reasons, its confidence at most the answer's.
  if (options.search_far_valley && inside_weak_move_gates()) {
    if (std::optional<FarValleyMove> moved =
            FarValleyAlongWeakestDirection(source, target, best, SymmetryDepth(source, target))) {
      try_measured_move(moved->T_target_source, "far_valley", /*cap_confidence=*/true);
    }
  }
  // The extent slide (RegistrationOptions::search_extent_slide): object-scale trees without
  // near-symmetries or a round axis, answers below kExtentSlideMaxAnswerConfidence. The answer
  // moved along its weakest direction until the clouds' ends agree (core/refine/extent_slide.h) is
  // measured there, not refined: the refinement's cost is flat along that direction (refined at the
  // finest depth alone from the moved pose, the laptops looked at stayed where it put them), and
  // the stages above would carry it back to where their coarse cells' minimum lies. Kept when valid
  // and fitting within kTwinFitnessSlack of the answer: by fitness the two are alike.
  if (net_refine && options.search_extent_slide && best.valid &&
      result.confidence < kExtentSlideMaxAnswerConfidence && symmetries.empty() &&
      !revolution.has_value() && !IsDeepPair(source, target, refinement)) {
    if (std::optional<ExtentSlide> slid = SlideToMatchExtents(source, target, best, finest_depth)) {
      try_measured_move(slid->T_target_source, "extent_slide", /*cap_confidence=*/false);
    }
  }
  // The symmetric start (RegistrationOptions::try_symmetric_starts): object-scale trees whose
  // target has near-symmetries, whatever the confidence (a tooth off can read confident). The
  // twin whose symmetry-breaking nodes meet clearly better than the answer's is refined, and kept
  // when, refined, they still meet clearly better and its fitness is within kTwinFitnessSlack; the
  // other starts' rule would not take it (the twins fit alike). (`symmetries` is empty for
  // scene-scale pairs.)
  if (net_refine && options.try_symmetric_starts && best.valid && !symmetries.empty()) {
    const SelfSymmetryOptions symmetry_options;
    const BreakingNodes breaking =
        FindBreakingNodes(source, target, best.T_target_source, symmetries, symmetry_options);
    if (std::optional<BreakingNodeTwin> twin = TwinMatchingBreakingNodes(
            source, target, best.T_target_source, symmetries, breaking, symmetry_options)) {
      try_start_kept_by(twin->T_target_source, "symmetric", [&](const TreeRefinementResult& r) {
        return BreakingNodeMatches(source, target, breaking, {r.T_target_source}, symmetry_options)
                   .front() >= twin->answer_match + symmetry_options.min_breaking_match_gain;
      });
    }
  }
  if (revolution.has_value()) {
    const Eigen::Vector3d& a = revolution->axis;
    const Eigen::Vector3d& c = revolution->centre;
    AddDegenerateTurn(a, c,
                      absl::StrFormat("the target is a body of revolution about the axis (%.3f "
                                      "%.3f %.3f) through (%.4g %.4g %.4g), so the turn about it "
                                      "is not measured",
                                      a.x(), a.y(), a.z(), c.x(), c.y(), c.z()),
                      best);
    result.valid = best.valid;
    result.failure_reason = best.failure_reason;
    result.degenerate_axes = best.degenerate_axes;
    result.num_degenerate = best.num_degenerate;
    result.confidence =
        confidence.Confidence(result.confidence_features, result.valid, result.num_degenerate);
  }
  if (options.hold_degenerate_at_initial && options.initial_T_target_source.has_value() &&
      best.num_degenerate > 0) {
    result.T_target_source = HoldDegenerateDirections(best, *options.initial_T_target_source);
    result.held_at_initial = true;
    absl::StrAppend(&result.failure_reason,
                    "; along the unconstrained direction(s) the pose is the initial guess's");
  }
  result.timings.refine_seconds =
      SecondsSince(refine_start) - confidence_seconds - deferred_net_seconds;
  result.timings.confidence_seconds = confidence_seconds;
  // The deferred passes ran within this function, so SecondsSince(start) counts them already.
  result.timings.total_seconds = SecondsSince(start) + result.timings.net_seconds;
  result.timings.net_seconds += deferred_net_seconds;
  return result;
}

absl::StatusOr<RegistrationResult> Registrar::Register(const Octree& source, const Octree& target,
                                                       const RegistrationOptions& options) const {
  const RegistrationRequest request{&source, &target, options};
  std::vector<absl::StatusOr<RegistrationResult>> results =
      RegisterBatch(absl::MakeConstSpan(&request, 1));
  return std::move(results.front());
}

absl::StatusOr<RegistrationResult> Registrar::Register(const Octree& source,
                                                       const PreparedTarget& target,
                                                       const RegistrationOptions& options) const {
  const RegistrationRequest request{&source, &target.tree(), options, &target};
  std::vector<absl::StatusOr<RegistrationResult>> results =
      RegisterBatch(absl::MakeConstSpan(&request, 1));
  return std::move(results.front());
}

absl::StatusOr<std::shared_ptr<const PreparedTarget>> Registrar::PrepareTarget(
    const Octree& target, bool for_network) const {
  // What Register checks of a target for the modes it is prepared for.
  if (absl::Status s =
          CheckTree(&target, "target",
                    for_network ? RegistrationMode::kNetRefine : RegistrationMode::kRefine);
      !s.ok()) {
    return s;
  }
  auto prepared = std::make_shared<PreparedTarget>();
  prepared->tree_ = &target;
  prepared->registrar_ = this;
  prepared->bytes_ = sizeof(PreparedTarget);
  if (for_network) {
    absl::StatusOr<std::shared_ptr<const NetTargetEncoding>> encoding =
        state_->net->EncodeTarget(target);
    if (!encoding.ok()) return encoding.status();
    prepared->net_encoding = *std::move(encoding);
    prepared->bytes_ += RpsrNet::EncodingBytes(*prepared->net_encoding);
  }
  // For the options a request has by default (RegistrationOptions::refinement).
  absl::StatusOr<std::shared_ptr<const PreparedRefinementTarget>> refinement =
      PreparedRefinementTarget::Prepare(target, TreeRefinementOptions{});
  if (!refinement.ok()) return refinement.status();
  prepared->refinement = *std::move(refinement);
  prepared->bytes_ += prepared->refinement->bytes();
  // Object-scale on its own, so with any source at the default depths: Finish reads them.
  if (!IsDeepPair(target, target, TreeRefinementOptions{})) {
    prepared->symmetries = FindSelfSymmetries(target);
    prepared->bytes_ += prepared->symmetries->size() * sizeof(SelfSymmetry);
    if (prepared->symmetries->empty()) prepared->revolution = FindContinuousSymmetry(target);
  } else {
    prepared->dominant_plane_depth = StageDepths(target, target, TreeRefinementOptions{}).second;
    prepared->dominant_plane = FindDominantPlane(target, prepared->dominant_plane_depth);
    prepared->bytes_ += prepared->dominant_plane->on_plane.size();
  }
  return std::shared_ptr<const PreparedTarget>(std::move(prepared));
}

std::vector<absl::StatusOr<RegistrationResult>> Registrar::RegisterBatch(
    absl::Span<const std::pair<const Octree*, const Octree*>> pairs,
    const RegistrationOptions& options) const {
  std::vector<RegistrationRequest> requests;
  requests.reserve(pairs.size());
  for (const auto& [source, target] : pairs) requests.push_back({source, target, options});
  return RegisterBatch(requests);
}

std::vector<absl::StatusOr<RegistrationResult>> Registrar::RegisterBatch(
    absl::Span<const RegistrationRequest> requests) const {
  std::vector<absl::StatusOr<RegistrationResult>> results(requests.size(),
                                                          absl::UnknownError("not registered"));
  std::vector<bool> ok(requests.size(), false);
  for (size_t i = 0; i < requests.size(); ++i) {
    const RegistrationRequest& r = requests[i];
    absl::Status status = ValidateRequest(r.source, r.target, r.options);
    if (status.ok() && r.prepared_target != nullptr &&
        (r.prepared_target->registrar_ != this || r.prepared_target->tree_ != r.target)) {
      status = absl::InvalidArgumentError(absl::StrCat(
          "the prepared target was made ",
          r.prepared_target->registrar_ != this ? "by another Registrar" : "from another tree"));
    }
    if (!status.ok()) {
      results[i] = status;
    } else {
      ok[i] = true;
    }
  }

  // One batched forward pass per pass count, over every network mode's valid request.
  std::vector<NetOutput> net_outputs(requests.size());
  std::vector<bool> net_failed(requests.size(), false);
  std::map<int, std::vector<size_t>> groups;
  for (size_t i = 0; i < requests.size(); ++i) {
    if (!ok[i] || !UsesNet(requests[i].options.mode)) continue;
    const int passes = DefaultPasses(requests[i].options, state_->net->config().passes);
    if (DefersLaterPasses(requests[i].options) && passes > 1) {
      net_outputs[i].deferred_passes = passes - 1;
      groups[1].push_back(i);
    } else {
      groups[passes].push_back(i);
    }
  }
  for (const auto& [passes, members] : groups) {
    std::vector<NetPair> batch;
    batch.reserve(members.size());
    const auto start = Clock::now();
    for (size_t i : members) {
      const PreparedTarget* prepared = requests[i].prepared_target;
      NetPair pair{
          requests[i].source, requests[i].target,
          requests[i].options.initial_T_target_source.value_or(Eigen::Isometry3d::Identity()),
          prepared != nullptr ? prepared->net_encoding.get() : nullptr};
      // Deferred passes would encode the target again: encode it once here instead (on CPU,
      // where a batch runs its pairs one at a time, the same arithmetic Estimate does for a pair
      // without an encoding, so the estimates are equal). Should it fail, Estimate encodes the
      // target itself and reports what failed for this pair alone.
      if (net_outputs[i].deferred_passes > 0 && pair.target_encoding == nullptr) {
        absl::StatusOr<std::shared_ptr<const NetTargetEncoding>> encoding =
            state_->net->EncodeTarget(*pair.target);
        if (encoding.ok()) {
          net_outputs[i].encoding = *std::move(encoding);
          pair.target_encoding = net_outputs[i].encoding.get();
        }
      }
      net_outputs[i].pair = pair;
      batch.push_back(pair);
    }
    absl::StatusOr<std::vector<NetEstimate>> estimates = state_->net->Estimate(batch, passes);
    const double seconds = SecondsSince(start) / static_cast<double>(members.size());
    for (size_t k = 0; k < members.size(); ++k) {
      const size_t i = members[k];
      if (!estimates.ok()) {
        results[i] = estimates.status();
        net_failed[i] = true;
        continue;
      }
      net_outputs[i].estimate = std::move((*estimates)[k]);
      net_outputs[i].seconds = seconds;
    }
  }

  for (size_t i = 0; i < requests.size(); ++i) {
    if (!ok[i] || net_failed[i]) continue;
    const RegistrationRequest& r = requests[i];
    const auto start = Clock::now();
    results[i] = state_->Finish(*r.source, *r.target, r.options,
                                UsesNet(r.options.mode) ? &net_outputs[i] : nullptr,
                                r.prepared_target, start);
  }
  return results;
}

}  // namespace rpsr::core
