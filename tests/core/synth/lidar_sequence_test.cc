#include "core/synth/lidar_sequence.h"

#include <atomic>
#include <map>
#include <mutex>

#include "gmock/gmock.h"
#include "gtest/gtest.h"

namespace rpsr::core {
namespace {

using ::testing::HasSubstr;

LidarSequenceSimulator MakeSequence(const LidarSequenceOptions& options) {
  absl::StatusOr<LidarSequenceSimulator> sequence = LidarSequenceSimulator::Create(options);
  EXPECT_TRUE(sequence.ok()) << sequence.status();
  return *std::move(sequence);
}

TEST(LidarSequenceTest, UrbanScanHasKittiLikePointCount) {
  LidarSequenceOptions options;
  options.frame_count = 40;
  const LidarSequenceSimulator sequence = MakeSequence(options);
  for (int frame : {0, 20, 39}) {
    const LidarScan scan = sequence.SimulateFrame(frame);
    EXPECT_GE(scan.cloud.size(), 100000u) << "frame " << frame;
    EXPECT_LE(scan.cloud.size(), 130000u) << "frame " << frame;
    // A street scene: ground, facades and cars are all there.
    std::map<uint16_t, int> counts;
    for (uint16_t label : scan.labels) ++counts[label];
    EXPECT_GT(counts[semantic_kitti::kRoad], 10000);
    EXPECT_GT(counts[semantic_kitti::kBuilding], 5000);
    EXPECT_GT(counts[semantic_kitti::kCar], 1000);
  }
}

TEST(LidarSequenceTest, DriveMovesFiveToFifteenMetresASecondAtSensorHeight) {
  LidarSequenceOptions options;
  options.style = StreetStyle::kSuburban;  // bumpy ground
  options.frame_count = 100;
  const LidarSequenceSimulator sequence = MakeSequence(options);
  ASSERT_EQ(sequence.frame_count(), 100);
  ASSERT_EQ(sequence.timestamps_s().size(), 100u);
  EXPECT_DOUBLE_EQ(sequence.timestamps_s()[10], 1.0);
  const auto& poses = sequence.T_world_lidar();
  for (int i = 1; i < 100; ++i) {
    const double step = (poses[i].translation() - poses[i - 1].translation()).norm();
    EXPECT_GE(step, 0.5 - 1e-3) << "frame " << i;
    EXPECT_LE(step, 1.5 + 1e-3) << "frame " << i;
    // Heading changes smoothly (at most ~6 degrees a frame even in tight turns).
    const Eigen::AngleAxisd turn(poses[i - 1].linear().transpose() * poses[i].linear());
    EXPECT_LT(turn.angle(), 0.1) << "frame " << i;
  }
  for (const Eigen::Isometry3d& pose : poses) {
    const Eigen::Vector3d p = pose.translation();
    const double ground =
        sequence.scene().ground.HeightAt(static_cast<float>(p.x()), static_cast<float>(p.y()));
    EXPECT_NEAR(p.z() - ground, options.sensor_height_m, 0.01);
    EXPECT_TRUE(pose.linear().isUnitary(1e-9));
    EXPECT_GT(pose.linear().determinant(), 0.0);
  }
}

TEST(LidarSequenceTest, ResultsDoNotDependOnThreadCount) {
  LidarSequenceOptions options;
  options.frame_count = 6;
  options.style = StreetStyle::kParkingLot;
  auto collect = [&](int threads) {
    options.thread_count = threads;
    const LidarSequenceSimulator sequence = MakeSequence(options);
    std::vector<std::vector<Eigen::Vector3f>> frames(options.frame_count);
    std::mutex mutex;
    absl::Status status = sequence.SimulateAllFrames([&](int frame, LidarScan scan) {
      std::lock_guard<std::mutex> lock(mutex);
      frames[frame] = std::move(scan.cloud.points);
      return absl::OkStatus();
    });
    EXPECT_TRUE(status.ok()) << status;
    return frames;
  };
  const auto one = collect(1);
  const auto two = collect(2);
  for (int i = 0; i < options.frame_count; ++i) {
    EXPECT_FALSE(one[i].empty());
    EXPECT_EQ(one[i], two[i]) << "frame " << i;
  }
  EXPECT_NE(one[0], one[1]);
}

TEST(LidarSequenceTest, SinkErrorStopsTheRun) {
  LidarSequenceOptions options;
  options.frame_count = 20;
  options.sensor.azimuth_steps = 100;
  const LidarSequenceSimulator sequence = MakeSequence(options);
  std::atomic<int> calls{0};
  absl::Status status = sequence.SimulateAllFrames([&](int frame, LidarScan) {
    ++calls;
    return frame == 3 ? absl::DataLossError("disk full") : absl::OkStatus();
  });
  EXPECT_EQ(status.code(), absl::StatusCode::kDataLoss);
  EXPECT_LT(calls.load(), 20);
}

TEST(LidarSequenceTest, RejectsBadOptions) {
  LidarSequenceOptions options;
  options.frame_count = 0;
  EXPECT_THAT(LidarSequenceSimulator::Create(options).status().message(), HasSubstr("frame_count"));
  options = {};
  options.min_speed_mps = 20;
  options.max_speed_mps = 10;
  EXPECT_EQ(LidarSequenceSimulator::Create(options).status().code(),
            absl::StatusCode::kInvalidArgument);
  options = {};
  options.sensor.beam_count = 1000;
  EXPECT_EQ(LidarSequenceSimulator::Create(options).status().code(),
            absl::StatusCode::kInvalidArgument);
}

}  // namespace
}  // namespace rpsr::core
