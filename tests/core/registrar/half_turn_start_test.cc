// net+refine's half-turn start (RegistrationOptions::search_half_turn_start): a guitar whose
// answer ended flipped front to back (it fits all but its neck and bridge) comes back to the truth
// from the answer turned by a half turn about the target's principal axis, clean and under a
// crop; answers within (1 deg, 0.01) without it stay within it, and where it keeps nothing the
// answer and its confidence are the very ones without it.
#include <cstdint>
#include <cstdio>

#include "core/registrar/registrar.h"
#include "gtest/gtest.h"
#include "tests/core/registrar/registrar_test_util.h"

namespace rpsr::core {
namespace {

using testing_util::AnswersWithAndWithout;

TEST(RegistrarHalfTurnStartTest, BringsAGuitarFlippedFrontToBackBack) {
  RegistrationOptions without;
  without.search_half_turn_start = false;
  const RegistrationOptions with;  // on by default
  // Seed 1's clean pair 616 (`rpsr eval --protocol objects --split unseen --count 2000 --seed 1`:
  // 179.86 degrees off at 0.985 confidence, fitness 0.887), and its pair 26 under a crop of 10%
  // (179.98 degrees off at 0.892).
  struct Case {
    uint64_t pair;
    DisturbanceKind disturbance;
    int level;
  };
  for (const Case& c :
       {Case{616, DisturbanceKind::kNone, 0}, Case{26, DisturbanceKind::kCrop, 1}}) {
    absl::StatusOr<AnswersWithAndWithout> answers =
        testing_util::RegisterStudyPair(1, c.pair, without, with, c.disturbance, c.level);
    ASSERT_TRUE(answers.ok()) << answers.status();
    std::printf("pair %d: %.2f deg (%s, %.3f) -> %.2f deg (%s, %.3f)\n", static_cast<int>(c.pair),
                answers->error_without.rotation_deg, answers->without.start.c_str(),
                answers->without.confidence, answers->error_with.rotation_deg,
                answers->with.start.c_str(), answers->with.confidence);
    EXPECT_GT(answers->error_without.rotation_deg, 170.0) << c.pair;
    EXPECT_LT(answers->error_with.rotation_deg, 1.0) << c.pair;
    EXPECT_LT(answers->error_with.translation, 0.01) << c.pair;
    EXPECT_EQ(answers->with.start, "half_turn") << c.pair;
    EXPECT_GT(answers->with.fitness, answers->without.fitness + 0.05) << c.pair;
  }
}

// Under crops and outliers the half-turned twin of a right answer is often refined and then
// refused (it fits better, but not by the margins): seed 1's pairs 0-39 under a crop of 40% and
// under outliers of 40%. Where the start refined a twin and kept nothing, the answer and its
// confidence are the very ones without it, and some twins are refused so.
TEST(RegistrarHalfTurnStartTest, TwinsNotFittingBetterByTheMarginsAreRefused) {
  RegistrationOptions without;
  without.search_half_turn_start = false;
  const RegistrationOptions with;
  int refused = 0;
  for (DisturbanceKind disturbance : {DisturbanceKind::kCrop, DisturbanceKind::kUniformOutliers}) {
    for (uint64_t i = 0; i < 40; ++i) {
      absl::StatusOr<AnswersWithAndWithout> answers =
          testing_util::RegisterStudyPair(1, i, without, with, disturbance, 4);
      ASSERT_TRUE(answers.ok()) << answers.status();
      if (answers->with.start == "half_turn" || answers->with.starts == answers->without.starts) {
        continue;
      }
      ++refused;
      EXPECT_TRUE(answers->with.T_target_source.isApprox(answers->without.T_target_source, 0.0))
          << "pair " << i;
      EXPECT_EQ(answers->with.confidence, answers->without.confidence) << "pair " << i;
    }
  }
  std::printf("half-turned twins refined and refused: %d of 80 answers\n", refused);
  EXPECT_GE(refused, 1);
}

// Seed 1's clean pairs 0-39: every answer within (1 deg, 0.01) without the start stays within it;
// where it keeps nothing, the answer and its confidence are the very ones without it (most answers
// fit above 0.95 and are not searched at all).
TEST(RegistrarHalfTurnStartTest, AnswersAreKeptWhereTheHalfTurnKeepsNothing) {
  const int kept = testing_util::ExpectAnswersKeptWhereTheStepKeepsNothing(
      1, 40, &RegistrationOptions::search_half_turn_start, "half_turn");
  std::printf("the half-turn start kept %d of 40 answers\n", kept);
  EXPECT_EQ(kept, 0);
}

}  // namespace
}  // namespace rpsr::core
