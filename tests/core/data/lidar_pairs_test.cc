#include "core/data/lidar_pairs.h"

#include <filesystem>

#include "absl/strings/str_cat.h"
#include "core/data/semantic_labels.h"
#include "core/data/simulated_kitti.h"
#include "gmock/gmock.h"
#include "gtest/gtest.h"

namespace rpsr::core {
namespace {

namespace fs = std::filesystem;

std::vector<LidarPairIndex> Select(int frames, LidarSplit split, const LidarPairOptions& options) {
  absl::StatusOr<std::vector<LidarPairIndex>> pairs = SelectLidarPairs(3, frames, split, options);
  EXPECT_TRUE(pairs.ok()) << pairs.status();
  return *std::move(pairs);
}

TEST(LidarPairsTest, SplitsAreContiguousSeventyTwentyTenBlocks) {
  const LidarPairOptions options;
  const FrameRange train = SplitFrameRange(1101, LidarSplit::kTrain, options);
  const FrameRange test = SplitFrameRange(1101, LidarSplit::kTest, options);
  const FrameRange validation = SplitFrameRange(1101, LidarSplit::kValidation, options);
  EXPECT_EQ(train.begin, 0);
  EXPECT_EQ(train.end, 770);
  EXPECT_EQ(test.begin, 770);
  EXPECT_EQ(test.end, 990);
  EXPECT_EQ(validation.begin, 990);
  EXPECT_EQ(validation.end, 1101);
}

TEST(LidarPairsTest, PairsStayInsideTheirBlockAwayFromOtherSplits) {
  const LidarPairOptions options;
  const std::vector<LidarPairIndex> train = Select(1101, LidarSplit::kTrain, options);
  const std::vector<LidarPairIndex> test = Select(1101, LidarSplit::kTest, options);
  const std::vector<LidarPairIndex> validation = Select(1101, LidarSplit::kValidation, options);
  ASSERT_EQ(train.size(), 770u - 5u);  // sources 0..764
  ASSERT_EQ(test.size(), 220u - 10u - 5u);
  ASSERT_EQ(validation.size(), 111u - 10u - 5u);
  EXPECT_EQ(train.front().source_frame, 0);
  EXPECT_EQ(train.back().target_frame, 769);
  EXPECT_EQ(test.front().source_frame, 780);
  EXPECT_EQ(test.back().target_frame, 989);
  EXPECT_EQ(validation.front().source_frame, 1000);
  EXPECT_EQ(validation.back().target_frame, 1100);
  for (const auto* split : {&train, &test, &validation}) {
    for (const LidarPairIndex& pair : *split) {
      EXPECT_EQ(pair.sequence, 3);
      EXPECT_EQ(pair.target_frame, pair.source_frame + 5);
    }
  }
  // Every test frame is more than 10 frames from every training frame.
  EXPECT_GT(test.front().source_frame - train.back().target_frame, 10);
}

TEST(LidarPairsTest, SeededSubsetIsDeterministicSortedAndSeedDependent) {
  LidarPairOptions options;
  options.max_pairs = 50;
  const std::vector<LidarPairIndex> a = Select(4541, LidarSplit::kTrain, options);
  const std::vector<LidarPairIndex> b = Select(4541, LidarSplit::kTrain, options);
  options.seed = 2;
  const std::vector<LidarPairIndex> c = Select(4541, LidarSplit::kTrain, options);
  ASSERT_EQ(a.size(), 50u);
  bool same_as_c = true;
  for (size_t i = 0; i < a.size(); ++i) {
    EXPECT_EQ(a[i].source_frame, b[i].source_frame);
    if (i > 0) {
      EXPECT_LT(a[i - 1].source_frame, a[i].source_frame);
    }
    same_as_c = same_as_c && a[i].source_frame == c[i].source_frame;
  }
  EXPECT_FALSE(same_as_c);
}

TEST(LidarPairsTest, ShortSequencesAndBadOptions) {
  EXPECT_TRUE(Select(10, LidarSplit::kTest, {}).empty());
  EXPECT_TRUE(Select(0, LidarSplit::kTrain, {}).empty());
  LidarPairOptions options;
  options.frame_offset = 0;
  EXPECT_EQ(SelectLidarPairs(0, 100, LidarSplit::kTrain, options).status().code(),
            absl::StatusCode::kInvalidArgument);
  options = {};
  options.train_fraction = 0.9;
  options.test_fraction = 0.2;
  EXPECT_EQ(SelectLidarPairs(0, 100, LidarSplit::kTrain, options).status().code(),
            absl::StatusCode::kInvalidArgument);
}

TEST(LidarPairsTest, LoadsSimulatedPairsWithAndWithoutGround) {
  const std::string root = (fs::path(::testing::TempDir()) / "lidar_pairs_test_sim").string();
  fs::remove_all(root);
  LidarSequenceOptions options;
  options.frame_count = 7;
  options.style = StreetStyle::kSuburban;
  options.sensor.azimuth_steps = 500;  // small scans: the test is about bookkeeping
  ASSERT_TRUE(WriteSimulatedKittiSequence(root, 2, options).ok());
  absl::StatusOr<KittiOdometrySequence> sequence = KittiOdometrySequence::Open(root, 2);
  ASSERT_TRUE(sequence.ok()) << sequence.status();

  const LidarPairIndex index{2, 1, 6};
  absl::StatusOr<LidarPair> with_ground = LoadLidarPair(*sequence, index, GroundHandling::kKeep);
  absl::StatusOr<LidarPair> without = LoadLidarPair(*sequence, index, GroundHandling::kRemove);
  ASSERT_TRUE(with_ground.ok()) << with_ground.status();
  ASSERT_TRUE(without.ok()) << without.status();
  absl::StatusOr<LabeledScan> source = sequence->ReadLabeledScan(1);
  ASSERT_TRUE(source.ok());
  size_t non_ground = 0;
  for (uint32_t label : source->labels) non_ground += !IsGroundClass(SemanticClassOf(label));
  EXPECT_EQ(with_ground->source.size(), source->cloud.size());
  EXPECT_EQ(without->source.size(), non_ground);
  EXPECT_LT(without->source.size(), with_ground->source.size() / 2);  // ground is most of a scan
  EXPECT_GT(without->target.size(), 0u);
  EXPECT_TRUE(without->T_target_source.isApprox(sequence->T_target_source(1, 6)));
  EXPECT_EQ(without->index.target_frame, 6);

  EXPECT_EQ(LoadLidarPair(*sequence, {3, 1, 6}, GroundHandling::kKeep).status().code(),
            absl::StatusCode::kInvalidArgument);
  EXPECT_EQ(LoadLidarPair(*sequence, {2, 3, 8}, GroundHandling::kKeep).status().code(),
            absl::StatusCode::kOutOfRange);
  fs::remove_all(root + "/sequences/02/labels");
  absl::StatusOr<KittiOdometrySequence> unlabeled = KittiOdometrySequence::Open(root, 2);
  ASSERT_TRUE(unlabeled.ok());
  EXPECT_EQ(LoadLidarPair(*unlabeled, index, GroundHandling::kRemove).status().code(),
            absl::StatusCode::kFailedPrecondition);
  EXPECT_TRUE(LoadLidarPair(*unlabeled, index, GroundHandling::kKeep).ok());
}

}  // namespace
}  // namespace rpsr::core
