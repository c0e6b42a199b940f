// Why net+refine fails where it fails (issue 5's objects RMSE): for each unseen object pair of the
// protocol that misses (1 deg, 0.01), the same pair refined from the TRUE pose. If that ends with a
// clearly better fit (valid, 1% more overlap), a better start would have found it (a basin miss a
// search could fix); if it ends no better -- or drifts away from the truth itself -- the geometry
// does not single out the pose (a symmetric twin, a slide along a symmetric direction), and only
// the confidence can help. A last column refines from the truth with the finest depth alone: when
// that stays and the whole refinement does not, the coarse stages carry the error in.
//
// The last line gives, over all pairs, net+refine's rotation / translation RMSE beside that of
// every pair refined from the truth: the floor the refinement's own minima leave to any start
// search.
//
//   build/tests/bench/object_failure_anatomy --count 100 [--seed 2] [--disturbance jitter --level
//   2]
#include <cmath>
#include <cstdio>
#include <memory>
#include <string>

#include "absl/flags/flag.h"
#include "absl/flags/parse.h"
#include "core/data/object_pairs.h"
#include "core/data/registration_metrics.h"
#include "core/net/openblas_core_choice.h"
#include "core/registrar/registrar.h"
#include "core/synth/seeded_random.h"

ABSL_FLAG(int, count, 100, "unseen object pairs (the eval study's seeds: DeriveSeed(seed, i))");
ABSL_FLAG(int, seed, 1, "the pairs' seed, as rpsr eval's --seed");
ABSL_FLAG(std::string, disturbance, "none",
          "none, gaussian_noise, uniform_outliers, crop or jitter (DisturbanceName)");
ABSL_FLAG(int, level, 0, "disturbance level 0..4");

namespace rpsr::core {
namespace {

bool Success(const PairError& e) { return e.rotation_deg <= 1.0 && e.translation <= 0.01; }

int Run() {
  absl::StatusOr<std::unique_ptr<Registrar>> registrar = Registrar::Create();
  if (!registrar.ok()) {
    std::fprintf(stderr, "%s\n", std::string(registrar.status().message()).c_str());
    return 1;
  }
  PairOptions options;
  options.split = ObjectSplit::kM2Unseen;
  bool known = false;
  for (DisturbanceKind kind :
       {DisturbanceKind::kNone, DisturbanceKind::kGaussianNoise, DisturbanceKind::kUniformOutliers,
        DisturbanceKind::kCrop, DisturbanceKind::kJitter}) {
    if (DisturbanceName(kind) == absl::GetFlag(FLAGS_disturbance)) {
      options.disturbance = kind;
      known = true;
    }
  }
  if (!known) {
    std::fprintf(stderr, "unknown --disturbance '%s'\n", absl::GetFlag(FLAGS_disturbance).c_str());
    return 2;
  }
  options.disturbance_level = absl::GetFlag(FLAGS_level);
  BarnesHutTreeOptions tree_options;
  tree_options.max_depth = 6;
  int failures = 0, clearly_better = 0, right_from_truth = 0, right_from_truth_finest_only = 0,
      confident = 0;
  double squared_deg = 0.0, squared_translation = 0.0, truth_squared_deg = 0.0,
         truth_squared_translation = 0.0;
  const int seed = absl::GetFlag(FLAGS_seed);
  const int count = absl::GetFlag(FLAGS_count);
  for (int i = 0; i < count; ++i) {
    absl::StatusOr<ObjectPair> pair = MakeObjectPair(options, DeriveSeed(seed, i));
    if (!pair.ok()) return 1;
    absl::StatusOr<Octree> source = BuildOctree(pair->source, tree_options);
    absl::StatusOr<Octree> target = BuildOctree(pair->target, tree_options);
    if (!source.ok() || !target.ok()) return 1;
    absl::StatusOr<RegistrationResult> got = (*registrar)->Register(*source, *target);
    if (!got.ok()) return 1;
    const PairError error = ErrorOf(got->T_target_source, pair->T_target_source);
    RegistrationOptions from_truth;
    from_truth.mode = RegistrationMode::kRefine;
    from_truth.initial_T_target_source = pair->T_target_source;
    absl::StatusOr<RegistrationResult> truth = (*registrar)->Register(*source, *target, from_truth);
    if (!truth.ok()) return 1;
    const PairError truth_error = ErrorOf(truth->T_target_source, pair->T_target_source);
    squared_deg += error.rotation_deg * error.rotation_deg;
    squared_translation += error.translation * error.translation;
    truth_squared_deg += truth_error.rotation_deg * truth_error.rotation_deg;
    truth_squared_translation += truth_error.translation * truth_error.translation;
    if (Success(error)) continue;
    ++failures;
    // The finest depth alone from the truth: whether the coarse depths carried the error in or
    // the finest depth's own minimum lies away from the truth.
    RegistrationOptions finest_only = from_truth;
    finest_only.refinement.coarsest_depth = tree_options.max_depth;
    absl::StatusOr<RegistrationResult> finest =
        (*registrar)->Register(*source, *target, finest_only);
    if (!finest.ok()) return 1;
    const PairError finest_error = ErrorOf(finest->T_target_source, pair->T_target_source);
    right_from_truth_finest_only += Success(finest_error);
    const bool better = truth->valid && truth->fitness > got->fitness + 0.01;
    clearly_better += better;
    right_from_truth += Success(truth_error);
    confident += got->confidence >= 0.9;
    std::printf(
        "pair %3d: net+refine %6.2f deg %.3f, fitness %.3f, confidence %.2f, start %-8s | from the "
        "truth %5.2f deg %.3f, fitness %.3f%s | finest depth only %5.2f deg %.3f\n",
        i, error.rotation_deg, error.translation, got->fitness, got->confidence, got->start.c_str(),
        truth_error.rotation_deg, truth_error.translation, truth->fitness,
        better ? "  CLEARLY BETTER" : "", finest_error.rotation_deg, finest_error.translation);
  }
  std::printf(
      "%d of %d pairs beyond (1 deg, 0.01); refined from the truth: %d end with a clearly better "
      "fit, %d end within (1 deg, 0.01) (%d refining the finest depth alone); %d of the failures "
      "were confident (>= 0.9)\n",
      failures, count, clearly_better, right_from_truth, right_from_truth_finest_only, confident);
  std::printf(
      "all %d pairs: net+refine rotation / translation RMSE %.3f deg / %.4f; refined from the "
      "truth %.3f deg / %.4f\n",
      count, std::sqrt(squared_deg / count), std::sqrt(squared_translation / count),
      std::sqrt(truth_squared_deg / count), std::sqrt(truth_squared_translation / count));
  return 0;
}

}  // namespace
}  // namespace rpsr::core

int main(int argc, char** argv) {
  absl::ParseCommandLine(argc, argv);
  rpsr::core::net::MatchOpenBlasCoreToCpu();  // as rpsrd and rpsr do
  return rpsr::core::Run();
}
