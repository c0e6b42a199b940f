// The shipped object model: written by a CUDA LibTorch 2.11 build on a GPU machine, it must load
// in this (Debian 1.13) LibTorch, register better than doing nothing, and give the same answers
// batched and one by one (with trained weights the SVD is well-conditioned, unlike at random
// initialisation, see rpsr_net_test.cc).
#include <algorithm>
#include <string>
#include <vector>

#include "core/data/object_pairs.h"
#include "core/data/transform_convention.h"
#include "core/net/rpsr_net.h"
#include "gtest/gtest.h"

namespace rpsr::core {
namespace {

const std::string kModel = std::string(RPSR_SOURCE_DIR) + "/core/models/objects/model.rpsrw";

double RotationErrorDeg(const Eigen::Isometry3d& a, const Eigen::Isometry3d& b) {
  return RotationErrorRad(a.linear(), b.linear()) * 180.0 / M_PI;
}

// Trees of `count` unseen-class object pairs, seeds first_seed on (source, target, source, ...),
// and their true motions.
struct UnseenPairs {
  std::vector<Octree> trees;
  std::vector<Eigen::Isometry3d> truths;
};
UnseenPairs MakeUnseenPairs(uint64_t first_seed, int count) {
  PairOptions options;
  options.split = ObjectSplit::kM2Unseen;
  UnseenPairs out;
  out.trees.reserve(2 * count);
  for (int i = 0; i < count; ++i) {
    auto pair = MakeObjectPair(options, first_seed + i);
    EXPECT_TRUE(pair.ok()) << pair.status();
    if (!pair.ok()) break;
    auto source = BuildOctree(pair->source);
    auto target = BuildOctree(pair->target);
    EXPECT_TRUE(source.ok() && target.ok());
    if (!source.ok() || !target.ok()) break;
    out.trees.push_back(*std::move(source));
    out.trees.push_back(*std::move(target));
    out.truths.push_back(pair->T_target_source);
  }
  return out;
}

// Targets encoded once (RpsrNet::EncodeTarget) mixed in one batch with fresh ones: the same
// estimates as the plain batch, to every bit (on CPU a batch runs its pairs one at a time, see
// below).
TEST(ShippedObjectModelTest, EncodedTargetsInAMixedBatchGiveTheSameEstimates) {
  auto net = RpsrNet::Load(kModel);
  ASSERT_TRUE(net.ok()) << net.status();
  const int kPairs = 4;
  const UnseenPairs made = MakeUnseenPairs(9100, kPairs);
  ASSERT_EQ(made.trees.size(), 2u * kPairs);
  const std::vector<Octree>& trees = made.trees;
  auto first_target = (*net)->EncodeTarget(trees[1]);
  auto third_target = (*net)->EncodeTarget(trees[5]);
  ASSERT_TRUE(first_target.ok() && third_target.ok());
  std::vector<NetPair> plain, mixed;
  for (int i = 0; i < kPairs; ++i) plain.push_back({&trees[2 * i], &trees[2 * i + 1]});
  mixed = plain;
  mixed[0].target_encoding = first_target->get();
  mixed[2].target_encoding = third_target->get();
  auto a = (*net)->Estimate(plain, 2);
  auto b = (*net)->Estimate(mixed, 2);
  ASSERT_TRUE(a.ok() && b.ok()) << a.status() << b.status();
  for (int i = 0; i < kPairs; ++i) {
    EXPECT_EQ((*a)[i].T_target_source.matrix(), (*b)[i].T_target_source.matrix()) << "pair " << i;
    EXPECT_EQ((*a)[i].score_peak, (*b)[i].score_peak) << "pair " << i;
  }
  // All encoded: the same again.
  auto second_target = (*net)->EncodeTarget(trees[3]);
  auto fourth_target = (*net)->EncodeTarget(trees[7]);
  ASSERT_TRUE(second_target.ok() && fourth_target.ok());
  mixed[1].target_encoding = second_target->get();
  mixed[3].target_encoding = fourth_target->get();
  auto c = (*net)->Estimate(mixed, 2);
  ASSERT_TRUE(c.ok()) << c.status();
  for (int i = 0; i < kPairs; ++i) {
    EXPECT_EQ((*a)[i].T_target_source.matrix(), (*c)[i].T_target_source.matrix()) << "pair " << i;
  }
}

TEST(ShippedObjectModelTest, LoadsAndBeatsIdentityOnUnseenClasses) {
  auto net = RpsrNet::Load(kModel);
  ASSERT_TRUE(net.ok()) << net.status();
  const int kPairs = 24;
  const UnseenPairs made = MakeUnseenPairs(9000, kPairs);
  ASSERT_EQ(made.trees.size(), 2u * kPairs);
  const std::vector<Octree>& trees = made.trees;
  const std::vector<Eigen::Isometry3d>& truths = made.truths;
  std::vector<NetPair> pairs;
  for (int i = 0; i < kPairs; ++i) pairs.push_back({&trees[2 * i], &trees[2 * i + 1]});
  auto estimates = (*net)->Estimate(pairs);
  ASSERT_TRUE(estimates.ok()) << estimates.status();
  std::vector<double> net_errors, identity_errors;
  for (int i = 0; i < kPairs; ++i) {
    net_errors.push_back(RotationErrorDeg((*estimates)[i].T_target_source, truths[i]));
    identity_errors.push_back(RotationErrorDeg(Eigen::Isometry3d::Identity(), truths[i]));
  }
  std::sort(net_errors.begin(), net_errors.end());
  std::sort(identity_errors.begin(), identity_errors.end());
  const double net_median = net_errors[kPairs / 2];
  const double identity_median = identity_errors[kPairs / 2];
  RecordProperty("net_median_deg", std::to_string(net_median));
  EXPECT_LT(net_median, 0.5 * identity_median)
      << "median rotation error " << net_median << " deg vs " << identity_median
      << " deg for the identity";

  // Batched = one by one, now on the rotation itself, to every bit: on CPU Estimate runs a
  // batch's pairs one at a time, so no BLAS kernel can block a pair's rows otherwise in a batch
  // (with OpenBLAS's AVX2 kernels a whole-batch GEMM did, and moved answers in their last bits;
  // a batching bug moves degrees).
  auto one_pass = (*net)->Estimate(pairs, 1);
  ASSERT_TRUE(one_pass.ok());
  for (int i = 0; i < 4; ++i) {
    auto single = (*net)->Estimate({&pairs[i], 1}, 1);
    ASSERT_TRUE(single.ok());
    EXPECT_EQ((*single)[0].T_target_source.matrix(), (*one_pass)[i].T_target_source.matrix())
        << "pair " << i;
    auto single_all = (*net)->Estimate({&pairs[i], 1});
    ASSERT_TRUE(single_all.ok());
    EXPECT_EQ((*single_all)[0].T_target_source.matrix(), (*estimates)[i].T_target_source.matrix())
        << "pair " << i;
    EXPECT_EQ((*single_all)[0].score_peak, (*estimates)[i].score_peak) << "pair " << i;
  }
}

}  // namespace
}  // namespace rpsr::core
