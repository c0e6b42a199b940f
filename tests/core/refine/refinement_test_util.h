// What the refinement's tests share beyond geometry: trees built as the refinement reads them,
// and the comparison of two results that must be the same bit for bit.
#ifndef RPSR_TESTS_CORE_REFINE_REFINEMENT_TEST_UTIL_H_
#define RPSR_TESTS_CORE_REFINE_REFINEMENT_TEST_UTIL_H_

#include <string>
#include <utility>

#include "core/cloud/point_cloud.h"
#include "core/refine/tree_refinement.h"
#include "core/tree/bh_tree.h"
#include "gtest/gtest.h"

namespace rpsr::core::testing_util {

// A tree to `max_depth` without the network's neighbour tables (the refinement reads none).
inline Octree RefinementTree(const PointCloud& cloud, int max_depth) {
  BarnesHutTreeOptions options;
  options.max_depth = max_depth;
  options.neighbor_max_depth = 2;
  auto tree = BuildOctree(cloud, options);
  EXPECT_TRUE(tree.ok()) << tree.status();
  return *std::move(tree);
}

// Two refinements that only shared or prepared work differently: every reported number equal.
inline void ExpectSameRefinement(const TreeRefinementResult& a, const TreeRefinementResult& b,
                                 const std::string& what) {
  EXPECT_EQ(a.T_target_source.matrix(), b.T_target_source.matrix()) << what;
  EXPECT_EQ(a.iterations, b.iterations) << what;
  EXPECT_EQ(a.fitness, b.fitness) << what;
  EXPECT_EQ(a.inlier_rmse, b.inlier_rmse) << what;
  EXPECT_EQ(a.information, b.information) << what;
  EXPECT_EQ(a.valid, b.valid) << what;
}

}  // namespace rpsr::core::testing_util

#endif  // RPSR_TESTS_CORE_REFINE_REFINEMENT_TEST_UTIL_H_
