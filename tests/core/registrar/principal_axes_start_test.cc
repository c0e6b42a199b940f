// net+refine's principal-axes starts (RegistrationOptions::search_principal_axes_start,
// core/refine/principal_axes_start.h) on unseen study pairs: an answer 45 degrees off under 40%
// outliers comes back from the start "principal_axes"; nearly right answers (a slid crop, a degree
// off under outliers) are not replaced by a flip half a turn off; where the start keeps nothing
// the answer and its confidence are the very ones without it.
#include <cstdint>
#include <cstdio>
#include <vector>

#include "core/registrar/registrar.h"
#include "gtest/gtest.h"
#include "tests/core/registrar/registrar_test_util.h"

namespace rpsr::core {
namespace {

using testing_util::AnswersWithAndWithout;

// Pair i of `rpsr eval --protocol objects --split unseen --seed S --disturbance D --level L`,
// without the start and with it.
AnswersWithAndWithout RegisterWithAndWithout(uint64_t seed, uint64_t i, DisturbanceKind disturbance,
                                             int level) {
  RegistrationOptions without;
  without.search_principal_axes_start = false;
  RegistrationOptions with;
  with.search_principal_axes_start = true;
  absl::StatusOr<AnswersWithAndWithout> answers =
      testing_util::RegisterStudyPair(seed, i, without, with, disturbance, level);
  EXPECT_TRUE(answers.ok()) << answers.status();
  return answers.ok() ? *std::move(answers) : AnswersWithAndWithout{};
}

TEST(RegistrarPrincipalAxesStartTest, BringsBackAnAnswerFortyFiveDegreesOff) {
  // Seed 2's pair 59 under 40% outliers: 45.6 degrees off without the start.
  const AnswersWithAndWithout answers =
      RegisterWithAndWithout(2, 59, DisturbanceKind::kUniformOutliers, 4);
  EXPECT_GT(answers.error_without.rotation_deg, 20.0);
  EXPECT_LT(answers.without.confidence, 0.1);
  EXPECT_LE(answers.error_with.rotation_deg, 1.0);
  EXPECT_LE(answers.error_with.translation, 0.01);
  EXPECT_EQ(answers.with.start, "principal_axes");
  EXPECT_GT(answers.with.starts, answers.without.starts);
  EXPECT_GT(answers.with.confidence, answers.without.confidence + 0.1);
}

TEST(RegistrarPrincipalAxesStartTest, NearlyRightAnswersAreNotFlippedByHalfATurn) {
  // Seed 1's pair 99 cropped by 30%: slid 0.18 without the start, the right turn (invalid, fitness
  // 0.97); a flip refined there fits 0.99 at 180 degrees (the gates on a valid answer that fits
  // poorly). Seed 3's pair 71
  // under 40% outliers: 1.3 degrees off at 0.13, a flip read 0.1 more (the confidence floor).
  struct Case {
    uint64_t seed;
    uint64_t pair;
    DisturbanceKind disturbance;
    int level;
  };
  for (const Case& c : {Case{1, 99, DisturbanceKind::kCrop, 3},
                        Case{3, 71, DisturbanceKind::kUniformOutliers, 4}}) {
    const AnswersWithAndWithout answers =
        RegisterWithAndWithout(c.seed, c.pair, c.disturbance, c.level);
    EXPECT_LT(answers.error_without.rotation_deg, 2.0) << c.pair;
    EXPECT_LT(answers.error_with.rotation_deg, 2.0) << c.pair;
    EXPECT_NE(answers.with.start, "principal_axes") << c.pair;
  }
}

// Under 40% outliers (seed 2, pairs 40-69) the start runs on the answers that fit poorly; where
// it keeps nothing the answer and its confidence are the very ones without it, and no answer
// within (1 deg, 0.01) without it is lost.
TEST(RegistrarPrincipalAxesStartTest, AnswersAreKeptWhereTheStartKeepsNothing) {
  int ran = 0;
  int kept = 0;
  for (uint64_t i = 40; i < 70; ++i) {
    const AnswersWithAndWithout answers =
        RegisterWithAndWithout(2, i, DisturbanceKind::kUniformOutliers, 4);
    if (answers.error_without.rotation_deg <= 1.0 && answers.error_without.translation <= 0.01) {
      EXPECT_LE(answers.error_with.rotation_deg, 1.0) << "pair " << i;
      EXPECT_LE(answers.error_with.translation, 0.01) << "pair " << i;
    }
    if (answers.with.start != "principal_axes") {
      EXPECT_TRUE(answers.with.T_target_source.isApprox(answers.without.T_target_source, 1e-12))
          << "pair " << i;
      EXPECT_EQ(answers.with.confidence, answers.without.confidence) << "pair " << i;
    } else {
      ++kept;
    }
    ran += answers.with.starts > answers.without.starts;
  }
  std::printf("answers whose principal-axes start ran: %d of 30, kept: %d\n", ran, kept);
  EXPECT_GE(ran, 2);
  EXPECT_GE(kept, 1);
}

}  // namespace
}  // namespace rpsr::core
