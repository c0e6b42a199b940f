// The move to the middle of the far-count valley along the weakest direction
// (core/refine/far_valley.h): unseen helix springs turned along their screw by a few degrees come
// back to within two of the truth; true poses are left alone; a nearly unconstrained direction (a
// blob's) is not searched.
#include "core/refine/far_valley.h"

#include <cmath>
#include <cstdio>
#include <optional>

#include "core/data/registration_metrics.h"
#include "core/refine/cell_index.h"
#include "core/refine/symmetry_starts.h"
#include "core/refine/weak_direction_start.h"
#include "core/synth/shape_families.h"
#include "gtest/gtest.h"
#include "tests/core/refine/refinement_test_util.h"

namespace rpsr::core {
namespace {

constexpr int kDepth = 6;

std::string FamilyOf(const testing_util::StudyPairAtTruth& pair) {
  return ShapeFamilies()[static_cast<size_t>(pair.pair.family_index)].name;
}

// Clean unseen springs (`rpsr eval --protocol objects --split unseen --count 100 --seed S`) whose
// answers ended 4.7-7.5 degrees off along the screw: seed 14's pair 23, seed 13's pair 92, seed
// 5's pair 6. Each refined from its truth, then turned along its weakest direction (the refined
// information's) by 2 cells one depth above the finest either way (9-12 degrees): each comes back
// within 2 degrees.
TEST(FarValleyTest, BringsSpringsTurnedAlongTheirScrewBack) {
  struct Case {
    uint64_t seed;
    uint64_t pair;
  };
  for (const Case& c : {Case{14, 23}, Case{13, 92}, Case{5, 6}}) {
    const testing_util::StudyPairAtTruth spring =
        testing_util::CleanStudyPairAtTruth(c.seed, c.pair, kDepth);
    ASSERT_EQ(FamilyOf(spring), "helix_spring");
    TreeRefinementResult at_truth = spring.at_truth;
    at_truth.T_target_source = spring.pair.T_target_source;
    const int depth = SymmetryDepth(spring.source, spring.target);
    const double edge = CellEdge(spring.target, depth);
    for (double cells : {2.0, -2.0}) {
      TreeRefinementResult turned = at_truth;
      turned.T_target_source = StepAlongWeakestDirection(at_truth, cells * edge);
      const double before =
          ErrorOf(turned.T_target_source, spring.pair.T_target_source).rotation_deg;
      const std::optional<FarValleyMove> moved =
          FarValleyAlongWeakestDirection(spring.source, spring.target, turned, depth);
      ASSERT_TRUE(moved.has_value()) << c.seed << "/" << c.pair << " " << cells;
      const double after =
          ErrorOf(moved->T_target_source, spring.pair.T_target_source).rotation_deg;
      std::printf(
          "spring %d/%d turned %.1f cells (%.2f deg): valley %.2f cells, least %.4f, moved "
          "%.2f cells, left %.2f deg\n",
          static_cast<int>(c.seed), static_cast<int>(c.pair), cells, before, moved->valley_cells,
          moved->least_fraction, moved->move_cells, after);
      EXPECT_LT(moved->move_cells * cells, 0.0) << cells;  // back towards the truth
      EXPECT_LT(after, 2.0) << c.seed << "/" << c.pair << " " << cells;
    }
  }
}

// At the truth the valley's middle lies within a cell of it (the estimate's own spread), so nothing
// moves: springs, and seed 1's first 24 clean pairs (whichever of them the eigenvalue gate admits).
TEST(FarValleyTest, LeavesTruePosesAlone) {
  int searched = 0;
  for (uint64_t i = 0; i < 24; ++i) {
    const testing_util::StudyPairAtTruth pair = testing_util::CleanStudyPairAtTruth(1, i, kDepth);
    TreeRefinementResult at_truth = pair.at_truth;
    at_truth.T_target_source = pair.pair.T_target_source;
    if (at_truth.normalized_eigenvalues[0] >= FarValleyOptions{}.min_weakest_eigenvalue) {
      ++searched;
    }
    EXPECT_FALSE(FarValleyAlongWeakestDirection(pair.source, pair.target, at_truth,
                                                SymmetryDepth(pair.source, pair.target))
                     .has_value())
        << "pair " << i << " (" << FamilyOf(pair) << ")";
  }
  std::printf("%d of 24 true poses inside the eigenvalue gate\n", searched);
  EXPECT_GE(searched, 6);
  for (const auto& [seed, i] : {std::pair<uint64_t, uint64_t>{14, 23}, {13, 92}, {5, 6}}) {
    const testing_util::StudyPairAtTruth spring =
        testing_util::CleanStudyPairAtTruth(seed, i, kDepth);
    TreeRefinementResult at_truth = spring.at_truth;
    at_truth.T_target_source = spring.pair.T_target_source;
    EXPECT_FALSE(FarValleyAlongWeakestDirection(spring.source, spring.target, at_truth,
                                                SymmetryDepth(spring.source, spring.target))
                     .has_value())
        << seed << "/" << i;
  }
}

TEST(FarValleyTest, DoesNotSearchANearlyUnconstrainedDirection) {
  // Seed 1's clean pair 1, a smooth blob (normalised weakest eigenvalue ~0.02).
  const testing_util::StudyPairAtTruth blob = testing_util::CleanStudyPairAtTruth(1, 1, kDepth);
  ASSERT_EQ(FamilyOf(blob), "blob");
  ASSERT_LT(blob.at_truth.normalized_eigenvalues[0], FarValleyOptions{}.min_weakest_eigenvalue);
  const int depth = SymmetryDepth(blob.source, blob.target);
  TreeRefinementResult turned = blob.at_truth;
  turned.T_target_source =
      StepAlongWeakestDirection(blob.at_truth, 2.0 * CellEdge(blob.target, depth));
  EXPECT_FALSE(FarValleyAlongWeakestDirection(blob.source, blob.target, turned, depth).has_value());
  // Nor a depth either tree lacks.
  EXPECT_FALSE(
      FarValleyAlongWeakestDirection(blob.source, blob.target, turned, kDepth + 1).has_value());
}

}  // namespace
}  // namespace rpsr::core
