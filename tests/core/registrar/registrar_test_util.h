// Shared fixtures of the registrar's tests: trees, one registrar per process (loading the model
// costs ~30 ms), seeded object pairs of asymmetric families (degenerate clouds and perturbed poses
// come from tests/core/refine/refinement_test_geometry.h).
#ifndef RPSR_TESTS_CORE_REGISTRAR_REGISTRAR_TEST_UTIL_H_
#define RPSR_TESTS_CORE_REGISTRAR_REGISTRAR_TEST_UTIL_H_

#include <random>
#include <string>

#include "core/data/object_pairs.h"
#include "core/data/registration_metrics.h"
#include "core/data/transform_convention.h"
#include "core/registrar/registrar.h"
#include "core/synth/seeded_random.h"
#include "core/synth/shape_families.h"
#include "gtest/gtest.h"
#include "tests/core/refine/refinement_test_geometry.h"

namespace rpsr::core::testing_util {

inline Octree TreeOf(const PointCloud& cloud, int max_depth = 6) {
  BarnesHutTreeOptions options;
  options.max_depth = max_depth;
  options.neighbor_max_depth = std::min(5, max_depth);
  auto tree = BuildOctree(cloud, options);
  EXPECT_TRUE(tree.ok()) << tree.status();
  return *std::move(tree);
}

inline const Registrar& SharedRegistrar() {
  static const Registrar* registrar = [] {
    auto r = Registrar::Create();
    EXPECT_TRUE(r.ok()) << r.status();
    return r->release();
  }();
  return *registrar;
}

// The first object pair at or after `seed` whose family has no rotational symmetry (so the truth
// is the only right answer), 2,048 points, unseen classes.
inline ObjectPair AsymmetricObjectPair(uint64_t seed, double max_angle_deg) {
  PairOptions options;
  options.num_points = 2048;
  options.max_angle_deg = max_angle_deg;
  options.max_translation = 0.2;
  options.split = ObjectSplit::kM2Unseen;
  for (;; ++seed) {
    auto pair = MakeObjectPair(options, seed);
    EXPECT_TRUE(pair.ok()) << pair.status();
    if (ShapeFamilies()[pair->family_index].symmetry == RotationalSymmetry::kNone) return *pair;
  }
}

// The unseen pair `i` of pair seed `seed` (the study's `--seed`; `disturbance` at `level`, as
// `rpsr eval --disturbance D --level L`), on trees of depth 6, registered with `without` and with
// `with`, and both answers' errors.
struct AnswersWithAndWithout {
  RegistrationResult without;
  RegistrationResult with;
  PairError error_without;
  PairError error_with;
};
inline absl::StatusOr<AnswersWithAndWithout> RegisterStudyPair(
    uint64_t seed, uint64_t i, const RegistrationOptions& without, const RegistrationOptions& with,
    DisturbanceKind disturbance = DisturbanceKind::kNone, int level = 0) {
  PairOptions options;
  options.split = ObjectSplit::kM2Unseen;
  options.disturbance = disturbance;
  options.disturbance_level = level;
  absl::StatusOr<ObjectPair> pair = MakeObjectPair(options, DeriveSeed(seed, i));
  if (!pair.ok()) return pair.status();
  const Octree source = TreeOf(pair->source, 6);
  const Octree target = TreeOf(pair->target, 6);
  absl::StatusOr<RegistrationResult> a = SharedRegistrar().Register(source, target, without);
  if (!a.ok()) return a.status();
  absl::StatusOr<RegistrationResult> b = SharedRegistrar().Register(source, target, with);
  if (!b.ok()) return b.status();
  AnswersWithAndWithout answers{*std::move(a), *std::move(b), {}, {}};
  answers.error_without = ErrorOf(answers.without.T_target_source, pair->T_target_source);
  answers.error_with = ErrorOf(answers.with.T_target_source, pair->T_target_source);
  return answers;
}

// Pair i of `rpsr eval --protocol objects --split unseen --seed S` (clean), with the registrar's
// `option` off and on (everything else default).
inline AnswersWithAndWithout RegisterStudyPairWithSwitch(uint64_t seed, uint64_t i,
                                                         bool RegistrationOptions::*option,
                                                         const RegistrationOptions& base = {}) {
  RegistrationOptions without = base;
  without.*option = false;
  RegistrationOptions with = base;
  with.*option = true;
  absl::StatusOr<AnswersWithAndWithout> answers = RegisterStudyPair(seed, i, without, with);
  EXPECT_TRUE(answers.ok()) << answers.status();
  return answers.ok() ? *std::move(answers) : AnswersWithAndWithout{};
}

// A step that moves answers (`option`, naming its kept answers `start`) over seed S's clean study
// pairs 0 .. count - 1: every answer within (1 deg, 0.01) without it stays within it, and where the
// step keeps nothing, the answer and its confidence are the very ones without it (both arms with
// `base`'s other options, so that a later step can be kept out of the comparison). Returns how many
// answers the step kept.
inline int ExpectAnswersKeptWhereTheStepKeepsNothing(uint64_t seed, uint64_t count,
                                                     bool RegistrationOptions::*option,
                                                     const std::string& start,
                                                     const RegistrationOptions& base = {}) {
  int kept = 0;
  for (uint64_t i = 0; i < count; ++i) {
    const AnswersWithAndWithout answers = RegisterStudyPairWithSwitch(seed, i, option, base);
    if (answers.error_without.rotation_deg <= 1.0 && answers.error_without.translation <= 0.01) {
      EXPECT_LE(answers.error_with.rotation_deg, 1.0) << "pair " << i;
      EXPECT_LE(answers.error_with.translation, 0.01) << "pair " << i;
    }
    if (answers.with.start == start) {
      ++kept;
      continue;
    }
    EXPECT_TRUE(answers.with.T_target_source.isApprox(answers.without.T_target_source, 0.0))
        << "pair " << i;
    EXPECT_EQ(answers.with.confidence, answers.without.confidence) << "pair " << i;
  }
  return kept;
}

}  // namespace rpsr::core::testing_util

#endif  // RPSR_TESTS_CORE_REGISTRAR_REGISTRAR_TEST_UTIL_H_
