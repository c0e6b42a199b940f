// Flags read by more than one subcommand (see shared_flags.h).
#include "client/cli/shared_flags.h"

#include <algorithm>
#include <filesystem>
#include <system_error>

#include "absl/flags/flag.h"
#include "absl/flags/internal/parse.h"
#include "absl/strings/ascii.h"
#include "absl/strings/str_cat.h"
#include "core/registrar/embedded_models.h"

ABSL_FLAG(std::string, output, "",
          "the folder written: train: model.rpsrw, last.rpsrw, the state and the log; data: the "
          "clouds, manifest.csv and the simulated sequences; demo: the pictures (default "
          "rpsr-demo); odometry: the poses FILE (KITTI format)");
ABSL_FLAG(std::string, protocol, "objects",
          "objects: the paper's ModelNet-style protocol on procedural objects (train: the M2 seen "
          "classes; data: --split); lidar: pairs of frames i and i+5 (train: simulated HDL-64E "
          "streets, half without ground; data pairs: "
          "read from --kitti)");
ABSL_FLAG(uint64_t, seed, 1,
          "seed of everything drawn at random (train: weights and pair streams; data: objects, "
          "poses, disturbances, simulated streets and the choice of --max_pairs)");
ABSL_FLAG(int, num_points, 1024, "objects: points sampled per cloud");
ABSL_FLAG(int, count, 100,
          "data objects / data pairs --protocol objects: clouds or pairs to write; eval "
          "--protocol objects: pairs per setting");
ABSL_FLAG(std::string, split, "",
          "objects: m1 (all 24 families, the default of data), seen or unseen (the halves of the "
          "paper's M2 split; eval's default: unseen); pairs --protocol lidar: train, test (the "
          "default) or validation (the 70/20/10% blocks of each sequence)");
ABSL_FLAG(std::string, disturbance, "none",
          "object pairs (data pairs, eval): what is done to the source: none, noise, outliers, "
          "crop or jitter; or partial: both clouds cropped, each along its own direction "
          "(partial views)");
ABSL_FLAG(int, level, 2,
          "object pairs (data pairs, eval): disturbance level 0..4 (noise/outliers "
          "1,5,10,20,40% of the points; crop and partial 1,10,20,30,40% (of each cloud); "
          "jitter tolerance 0.01,0.02,0.03,0.05,0.08)");
ABSL_FLAG(int, batch_size, 16, "pairs per forward pass (train: per optimisation step)");
ABSL_FLAG(int, passes, 0,
          "network passes (Sec. 3.3); 0: 3 for train; elsewhere the mode's default: the "
          "model's own number for net, 2 for net+refine");
ABSL_FLAG(int, threads, 1, "LibTorch intra-op threads");
ABSL_FLAG(bool, later_passes_when_unconfident, true,
          "eval, register, odometry, bench, net+refine: refine the first network pass's estimate "
          "first and run the later passes only when that answer is below 0.9 confidence, "
          "refining their estimate as a further start (false: every pass first, one start)");
ABSL_FLAG(bool, refine_from_initial, true,
          "eval, register, odometry, bench, net+refine: when the answer refined from the network's "
          "estimate is below 0.9 confidence, refine from the initial guess (or identity) too and "
          "keep the clearly better answer");
ABSL_FLAG(
    bool, search_scene_start, true,
    "eval, register, odometry, bench, net+refine on scene-scale trees: when the answer is still "
    "below 0.9 confidence, search a start (turns about z, assumed up; shifts of whole "
    "cells) and refine from it too; still not confident, search every turn as well");
ABSL_FLAG(bool, round_axis_start, true,
          "eval, register, odometry, bench, net+refine on object-scale trees: when the answer is "
          "below 0.9 confidence and the target is round about a principal axis (a cup with a "
          "tab), also refine the answer turned about that axis to where it leaves the fewest "
          "nodes without a partner, and keep the clearly better answer");
ABSL_FLAG(bool, weak_direction_start, true,
          "eval, register, odometry, bench, net+refine on object-scale trees without "
          "near-symmetries: also refine the answer stepped along its weakest direction (a "
          "spring's screw, a slide along a face) when that leaves clearly fewer nodes without a "
          "partner, and keep it when it still does");
ABSL_FLAG(bool, centroid_start, true,
          "eval, register, odometry, bench, net+refine on object-scale trees: when the answer is "
          "below 0.9 confidence and leaves the clouds' centres of mass more than half a cell "
          "apart, also refine its rotation with the centres put together, and keep the clearly "
          "better answer; a confident answer too where it overlaps below 97% and leaves them "
          "more than 2 cells apart, kept only when the centred one overlaps at least 97%");
ABSL_FLAG(bool, principal_axes_start, true,
          "eval, register, odometry, bench, net+refine on object-scale trees: when the answer "
          "fits under 80% of the source and reads below 0.5 confident, also refine starts that "
          "map the source's principal axes onto the target's (the likeliest two of four sign "
          "choices), and keep one that fits clearly better and reads at least 0.5 and 0.1 more "
          "confident");
ABSL_FLAG(bool, extent_slide, true,
          "eval, register, odometry, bench, net+refine on object-scale trees without "
          "near-symmetries: move the answer along its least constrained direction until the "
          "clouds' outermost nodes agree at both ends (a laptop slid along its hinge), and keep "
          "it when it fits as well");
ABSL_FLAG(bool, weak_direction_chamfer, true,
          "eval, register, odometry, bench, net+refine on object-scale trees without "
          "near-symmetries: when the answer is below 0.95 confident, overlaps almost wholly and "
          "its least constrained direction is still constrained, move it along that direction to "
          "where the nodes the motion moves across their surface meet the other cloud best (a "
          "spring turned along its screw), and keep it when it fits as well");
ABSL_FLAG(bool, half_turn_start, true,
          "eval, register, odometry, bench, net+refine on object-scale trees without "
          "near-symmetries, answers overlapping 95% or less: where a half turn about one of the "
          "target's principal axes nearly maps it onto itself (a guitar flipped front to back), "
          "also refine the answer turned by it, and keep that when it fits clearly better by a "
          "wide margin");
ABSL_FLAG(bool, screw_turns, true,
          "with --round_axis_start: where the target nearly maps onto itself under a screw about "
          "a round axis (a helix spring), also try the screw's turns, each advanced along the "
          "axis by its share of the pitch (a spring tens of degrees off along its screw)");
ABSL_FLAG(bool, far_valley, true,
          "eval, register, odometry, bench, net+refine on object-scale trees without "
          "near-symmetries, answers below 0.95 confidence that overlap almost wholly (fitness "
          "0.98), were not noise-polished and leave at most a tenth of the target uncovered: when "
          "the least constrained direction is still constrained, move the answer along it to the "
          "middle of the valley in the count of nodes without a partner (a spring off along its "
          "screw), and keep it when it fits as well (never more confident than the answer)");
ABSL_FLAG(bool, weak_direction_finest_round, false,
          "with --weak_direction_start, when its step kept nothing and the answer is clean and "
          "whole: the same step once more at the finest depth (a little more accurate on clean "
          "object scans, about a quarter slower on objects; needs --noise_polish, which measures "
          "the scatter)");
ABSL_FLAG(bool, sensor_aligned_check, true,
          "eval, register, odometry, bench, net+refine on scene-scale trees: when the answer puts "
          "the two sensors within a search cell of each other and both clouds have a ground, "
          "also refine from a search scored on the structure off the ground and keep it when it "
          "leaves clearly fewer structure nodes without a partner (mode refine: keep the answer "
          "but report it doubted, its confidence capped)");
ABSL_FLAG(bool, symmetric_starts, true,
          "eval, register, odometry, bench, net+refine on object-scale trees: when the target "
          "has near-symmetries (a gear's teeth), also refine the answer turned by the one under "
          "which the features that break them (a gear's pin) meet clearly better");
ABSL_FLAG(
    bool, rebin_coarse_depths, true,
    "eval, register, odometry, bench (refining modes): the refinement's coarse depths compare the "
    "source re-binned on the target's cells; false: the source tree's own cells (the "
    "paper's Eq. 2 as written)");
ABSL_FLAG(bool, noise_polish, true,
          "eval, register, odometry, bench (refining modes): when the source's points scatter "
          "about the target's surface by a sizeable part of the finest cell (jitter, a noisy "
          "scanner), a last point-to-plane stage one depth coarser; false: never");
ABSL_FLAG(bool, joint_finest_stage, true,
          "eval, register, odometry, bench (refining modes, with --rebin_coarse_depths): the "
          "refinement's finest stage also fits the next coarser depth re-binned on the target's "
          "cells; false: the finest depth alone");
ABSL_FLAG(
    bool, coarse_wide_search, true,
    "eval, register, odometry, bench (refining modes, with --rebin_coarse_depths): the coarse "
    "stages look for each cell's partner within two cells (3x3x3 block); false: one cell, "
    "as the finest stage (faster, less accurate under jitter, crops and outliers)");
ABSL_FLAG(bool, line_normals_from_planes, false,
          "eval, register, odometry, bench (refining modes): nodes whose points lie along a "
          "line (a sparse scan's ring arcs) take the normal of the ancestor plane they lie on "
          "(a simulated VLP-16 drifts 1.9-3.5% with it, 6-56% without); not given: chosen per "
          "pair, on where most of the finest cells hold a single ring's arc (16- and 32-beam "
          "scanners), off elsewhere (the HDL-64E's streets, objects)");
ABSL_FLAG(bool, hold_degenerate_at_initial, true,
          "register (with --initial), odometry (with --constant_velocity): when the geometry is "
          "degenerate (an open road along its length), keep the guess (the previous motion) "
          "along the unconstrained directions (false: the refinement's drift there)");
ABSL_FLAG(std::string, model, "",
          "eval, calibrate: a weights file (.rpsrw) or the name of a model embedded in the binary "
          "(objects, objects-small; lidar when shipped); default: the embedded object model");
ABSL_FLAG(std::string, mode, "net+refine",
          "eval, register, odometry: net: the network alone; net+refine (eval's default): the "
          "network, then the multi-scale GICP on the trees (core/refine); refine: the refinement "
          "alone from the identity (when not given: net+refine, except odometry on LiDAR scenes "
          "with the object model: refine from the previous motion)");
ABSL_FLAG(int, tree_depth, 6,
          "depth of the trees built from the clouds (>= 5); register and odometry choose 6 for "
          "objects and 9 for LiDAR scenes when not given");

namespace rpsr::client {

void ApplyRegistrationFlags(core::RegistrationOptions& options) {
  options.passes = absl::GetFlag(FLAGS_passes);
  options.later_passes_only_when_unconfident = absl::GetFlag(FLAGS_later_passes_when_unconfident);
  options.also_refine_from_initial = absl::GetFlag(FLAGS_refine_from_initial);
  options.search_scene_start = absl::GetFlag(FLAGS_search_scene_start);
  options.try_symmetric_starts = absl::GetFlag(FLAGS_symmetric_starts);
  options.search_round_axis_start = absl::GetFlag(FLAGS_round_axis_start);
  options.search_weak_direction_start = absl::GetFlag(FLAGS_weak_direction_start);
  options.weak_direction_finest_round = absl::GetFlag(FLAGS_weak_direction_finest_round);
  options.search_centroid_start = absl::GetFlag(FLAGS_centroid_start);
  options.search_principal_axes_start = absl::GetFlag(FLAGS_principal_axes_start);
  options.search_extent_slide = absl::GetFlag(FLAGS_extent_slide);
  options.search_weak_direction_chamfer = absl::GetFlag(FLAGS_weak_direction_chamfer);
  options.search_half_turn_start = absl::GetFlag(FLAGS_half_turn_start);
  options.round_axis_screw_turns = absl::GetFlag(FLAGS_screw_turns);
  options.search_far_valley = absl::GetFlag(FLAGS_far_valley);
  options.check_sensor_aligned_answers = absl::GetFlag(FLAGS_sensor_aligned_check);
  options.refinement.rebin_coarse_depths = absl::GetFlag(FLAGS_rebin_coarse_depths);
  options.refinement.joint_finest_stage = absl::GetFlag(FLAGS_joint_finest_stage);
  options.refinement.noise_polish = absl::GetFlag(FLAGS_noise_polish);
  if (!absl::GetFlag(FLAGS_coarse_wide_search)) {
    core::SearchCoarseStagesAsTheFinest(options.refinement);
  }
  options.refinement.line_normals_from_planes = ExplicitLineNormalsFlag();
  options.hold_degenerate_at_initial = absl::GetFlag(FLAGS_hold_degenerate_at_initial);
}

// Abseil 20220623 keeps CommandLineFlag::IsSpecifiedOnCommandLine private; the parser's own
// record of the flags it saw is the same answer.
bool GivenOnCommandLine(const char* name) {
  return absl::flags_internal::WasPresentOnCommandLine(name);
}

std::vector<std::string> GivenAmong(std::initializer_list<const char*> names) {
  std::vector<std::string> given;
  for (const char* name : names) {
    if (GivenOnCommandLine(name)) given.push_back(absl::StrCat("--", name));
  }
  return given;
}

std::optional<bool> ExplicitLineNormalsFlag() {
  if (!GivenOnCommandLine("line_normals_from_planes")) return std::nullopt;
  return absl::GetFlag(FLAGS_line_normals_from_planes);
}

std::optional<core::DisturbanceKind> ParseDisturbanceFlag(const std::string& name) {
  if (name == "none") return core::DisturbanceKind::kNone;
  if (name == "noise") return core::DisturbanceKind::kGaussianNoise;
  if (name == "outliers") return core::DisturbanceKind::kUniformOutliers;
  if (name == "crop") return core::DisturbanceKind::kCrop;
  if (name == "jitter") return core::DisturbanceKind::kJitter;
  if (name == "partial") return core::DisturbanceKind::kPartialViews;
  return std::nullopt;
}

std::optional<core::ObjectSplit> ParseObjectSplitFlag(const std::string& name,
                                                      core::ObjectSplit empty_means) {
  const std::string lower = absl::AsciiStrToLower(name);
  if (lower.empty()) return empty_means;
  if (lower == "m1") return core::ObjectSplit::kM1All;
  if (lower == "seen") return core::ObjectSplit::kM2Seen;
  if (lower == "unseen") return core::ObjectSplit::kM2Unseen;
  return std::nullopt;
}

core::RegistrarConfig RegistrarConfigFromModelFlag(const std::string& model) {
  core::RegistrarConfig config;
  if (model.empty()) return config;
  std::error_code ec;
  const std::vector<std::string> embedded = core::EmbeddedModelNames();
  const bool is_embedded_name =
      std::find(embedded.begin(), embedded.end(), model) != embedded.end();
  if (is_embedded_name && !std::filesystem::exists(model, ec)) {
    config.model = model;
  } else {
    config.model_path = model;
  }
  return config;
}

}  // namespace rpsr::client
