#include "core/data/kitti_odometry.h"

#include <filesystem>
#include <random>

#include "absl/strings/str_cat.h"
#include "core/data/semantic_labels.h"
#include "core/data/simulated_kitti.h"
#include "core/io/file_bytes.h"
#include "core/synth/seeded_random.h"
#include "gmock/gmock.h"
#include "gtest/gtest.h"

namespace rpsr::core {
namespace {

namespace fs = std::filesystem;
using ::testing::AllOf;
using ::testing::HasSubstr;

std::string FreshDirectory(const std::string& name) {
  const fs::path dir = fs::path(::testing::TempDir()) / absl::StrCat("kitti_odometry_test_", name);
  fs::remove_all(dir);
  fs::create_directories(dir);
  return dir.string();
}

Eigen::Isometry3d RandomPose(SeededRandom& random) {
  Eigen::Isometry3d pose = Eigen::Isometry3d::Identity();
  const Eigen::Vector3d axis = random.UnitVector();
  pose.linear() = Eigen::AngleAxisd(random.Uniform(-M_PI, M_PI), axis).toRotationMatrix();
  pose.translation() =
      Eigen::Vector3d(random.Uniform(-100, 100), random.Uniform(-100, 100), random.Uniform(-5, 5));
  return pose;
}

struct TinySequence {
  std::string root;
  std::vector<PointCloud> clouds;
  std::vector<std::vector<uint32_t>> labels;
  std::vector<Eigen::Isometry3d> T_world_lidar;
  std::vector<double> times;
};

// Writes a 3-frame sequence 04 of small random clouds with labels.
TinySequence WriteTinySequence(const std::string& name) {
  TinySequence tiny;
  tiny.root = FreshDirectory(name);
  SeededRandom random(9);
  absl::StatusOr<KittiSequenceWriter> writer =
      KittiSequenceWriter::Create(tiny.root, 4, KittiLikeCameraFromLidar());
  EXPECT_TRUE(writer.ok()) << writer.status();
  for (int frame = 0; frame < 3; ++frame) {
    PointCloud cloud;
    std::vector<uint32_t> labels;
    for (int i = 0; i < 50 + 10 * frame; ++i) {
      cloud.points.emplace_back(random.Uniform(-50, 50), random.Uniform(-50, 50),
                                random.Uniform(-2, 5));
      cloud.intensities.push_back(static_cast<float>(random.Uniform(0, 1)));
      labels.push_back(MakeSemanticKittiLabel(i % 2 ? semantic_kitti::kRoad : semantic_kitti::kCar,
                                              static_cast<uint16_t>(i)));
    }
    EXPECT_TRUE(writer->WriteFrame(frame, cloud, &labels).ok());
    tiny.clouds.push_back(cloud);
    tiny.labels.push_back(labels);
    tiny.T_world_lidar.push_back(RandomPose(random));
    tiny.times.push_back(0.1 * frame);
  }
  EXPECT_TRUE(writer->WritePoses(tiny.T_world_lidar, tiny.times).ok());
  return tiny;
}

TEST(KittiPosesTest, FormatThenParseIsExact) {
  SeededRandom random(1);
  std::vector<Eigen::Isometry3d> poses;
  for (int i = 0; i < 20; ++i) poses.push_back(RandomPose(random));
  absl::StatusOr<std::vector<Eigen::Isometry3d>> parsed =
      ParseKittiPoses(FormatKittiPoses(poses), "poses.txt");
  ASSERT_TRUE(parsed.ok()) << parsed.status();
  ASSERT_EQ(parsed->size(), poses.size());
  for (size_t i = 0; i < poses.size(); ++i) {
    EXPECT_EQ(parsed->at(i).matrix(), poses[i].matrix()) << "pose " << i;
  }
}

TEST(KittiPosesTest, CameraLidarConversionRoundTrips) {
  SeededRandom random(2);
  std::vector<Eigen::Isometry3d> lidar;
  for (int i = 0; i < 20; ++i) lidar.push_back(RandomPose(random));
  const Eigen::Isometry3d tr = KittiLikeCameraFromLidar();
  EXPECT_TRUE(tr.linear().isUnitary(1e-14));
  const std::vector<Eigen::Isometry3d> camera = CameraPosesFromLidarPoses(lidar, tr);
  const std::vector<Eigen::Isometry3d> back = LidarPosesFromCameraPoses(camera, tr);
  for (size_t i = 0; i < lidar.size(); ++i) {
    EXPECT_TRUE(back[i].matrix().isApprox(lidar[i].matrix(), 1e-13)) << "pose " << i;
    // P_i = Tr * T * Tr^-1: a camera-frame point maps like the LiDAR pose maps LiDAR points.
    const Eigen::Vector3d p_lidar(1.5, -2.0, 0.3);
    EXPECT_TRUE((tr * (lidar[i] * p_lidar)).isApprox(camera[i] * (tr * p_lidar), 1e-12));
  }
}

TEST(KittiPosesTest, MalformedLinesNameFileAndLine) {
  const std::string good = "1 0 0 0 0 1 0 0 0 0 1 0\n";
  absl::Status status = ParseKittiPoses(good + "1 0 0 0 0 1 0 0 0 0 1\n", "seq/poses.txt").status();
  EXPECT_EQ(status.code(), absl::StatusCode::kInvalidArgument);
  EXPECT_THAT(status.message(), AllOf(HasSubstr("seq/poses.txt line 2"), HasSubstr("expected 12"),
                                      HasSubstr("found 11")));
  status = ParseKittiPoses(good + good + "1 0 0 x 0 1 0 0 0 0 1 0\n", "p.txt").status();
  EXPECT_THAT(status.message(), AllOf(HasSubstr("p.txt line 3"), HasSubstr("'x'")));
  status = ParseKittiPoses(good + "\n" + good, "p.txt").status();
  EXPECT_THAT(status.message(), AllOf(HasSubstr("line 2"), HasSubstr("blank")));
  status = ParseKittiPoses("1 0 0 nan 0 1 0 0 0 0 1 0\n", "p.txt").status();
  EXPECT_THAT(status.message(), HasSubstr("not finite"));
  // CRLF and trailing blank lines are fine.
  absl::StatusOr<std::vector<Eigen::Isometry3d>> poses =
      ParseKittiPoses("1 0 0 0 0 1 0 0 0 0 1 0\r\n1 0 0 5 0 1 0 0 0 0 1 0\r\n\n\n", "p.txt");
  ASSERT_TRUE(poses.ok()) << poses.status();
  EXPECT_EQ(poses->size(), 2u);
  EXPECT_EQ(poses->at(1).translation(), Eigen::Vector3d(5, 0, 0));
}

TEST(KittiCalibTest, ReadsTrAndRejectsMissingOrShortTr) {
  absl::StatusOr<Eigen::Isometry3d> tr =
      ParseKittiCalibTr(FormatKittiCalib(KittiLikeCameraFromLidar()), "calib.txt");
  ASSERT_TRUE(tr.ok()) << tr.status();
  EXPECT_EQ(tr->matrix(), KittiLikeCameraFromLidar().matrix());
  tr = ParseKittiCalibTr("Tr_velo_to_cam: 0 -1 0 0 0 0 -1 0 1 0 0 0.5\n", "calib_velo_to_cam.txt");
  ASSERT_TRUE(tr.ok()) << tr.status();
  EXPECT_EQ(tr->translation(), Eigen::Vector3d(0, 0, 0.5));
  EXPECT_THAT(ParseKittiCalibTr("P0: 1 2 3\n", "seq/calib.txt").status().message(),
              AllOf(HasSubstr("seq/calib.txt"), HasSubstr("no 'Tr:'")));
  EXPECT_THAT(ParseKittiCalibTr("P0: 1\nTr: 1 2 3\n", "calib.txt").status().message(),
              AllOf(HasSubstr("calib.txt line 2"), HasSubstr("found 3")));
}

TEST(KittiOdometrySequenceTest, RoundTripsScansLabelsPosesCalibAndTimes) {
  const TinySequence tiny = WriteTinySequence("round_trip");
  absl::StatusOr<KittiOdometrySequence> sequence = KittiOdometrySequence::Open(tiny.root, 4);
  ASSERT_TRUE(sequence.ok()) << sequence.status();
  EXPECT_EQ(sequence->directory(), tiny.root + "/sequences/04");
  ASSERT_EQ(sequence->frame_count(), 3);
  EXPECT_TRUE(sequence->has_labels());
  EXPECT_EQ(sequence->T_camera_lidar().matrix(), KittiLikeCameraFromLidar().matrix());
  EXPECT_EQ(sequence->timestamps_s(), tiny.times);
  // poses.txt is relative to the first frame: its first camera pose is the identity.
  EXPECT_TRUE(sequence->T_world_camera()[0].matrix().isIdentity(1e-15));
  for (int frame = 0; frame < 3; ++frame) {
    const Eigen::Isometry3d expected = tiny.T_world_lidar[0].inverse() * tiny.T_world_lidar[frame];
    EXPECT_TRUE(sequence->T_world_lidar()[frame].matrix().isApprox(expected.matrix(), 1e-12))
        << "frame " << frame;
    absl::StatusOr<LabeledScan> scan = sequence->ReadLabeledScan(frame);
    ASSERT_TRUE(scan.ok()) << scan.status();
    EXPECT_EQ(scan->cloud.points, tiny.clouds[frame].points);
    EXPECT_EQ(scan->cloud.intensities, tiny.clouds[frame].intensities);
    EXPECT_EQ(scan->labels, tiny.labels[frame]);
  }
  const Eigen::Isometry3d T_2_0 = sequence->T_target_source(0, 2);
  const Eigen::Isometry3d expected = tiny.T_world_lidar[2].inverse() * tiny.T_world_lidar[0];
  EXPECT_TRUE(T_2_0.matrix().isApprox(expected.matrix(), 1e-12));
  EXPECT_EQ(sequence->ReadScan(3).status().code(), absl::StatusCode::kOutOfRange);
}

TEST(KittiOdometrySequenceTest, FallsBackToKittisPosesFolder) {
  const TinySequence tiny = WriteTinySequence("fallback");
  const std::string seq_dir = tiny.root + "/sequences/04";
  fs::create_directories(tiny.root + "/poses");
  fs::rename(seq_dir + "/poses.txt", tiny.root + "/poses/04.txt");
  absl::StatusOr<KittiOdometrySequence> sequence = KittiOdometrySequence::Open(tiny.root, 4);
  ASSERT_TRUE(sequence.ok()) << sequence.status();
  EXPECT_EQ(sequence->frame_count(), 3);
}

TEST(KittiOdometrySequenceTest, MalformedSequencesGiveStatusesNamingTheFile) {
  {
    const TinySequence tiny = WriteTinySequence("no_poses");
    fs::remove(tiny.root + "/sequences/04/poses.txt");
    absl::Status status = KittiOdometrySequence::Open(tiny.root, 4).status();
    EXPECT_EQ(status.code(), absl::StatusCode::kNotFound);
    EXPECT_THAT(status.message(),
                AllOf(HasSubstr("sequences/04/poses.txt"), HasSubstr("poses/04.txt")));
  }
  {
    const TinySequence tiny = WriteTinySequence("short_pose");
    const std::string path = tiny.root + "/sequences/04/poses.txt";
    ASSERT_TRUE(WriteFileBytes(path,
                               "1 0 0 0 0 1 0 0 0 0 1 0\n1 0 0 0 0 1 0 0 0 0 1\n"
                               "1 0 0 0 0 1 0 0 0 0 1 0\n")
                    .ok());
    absl::Status status = KittiOdometrySequence::Open(tiny.root, 4).status();
    EXPECT_EQ(status.code(), absl::StatusCode::kInvalidArgument);
    EXPECT_THAT(status.message(), AllOf(HasSubstr(path + " line 2"), HasSubstr("found 11")));
  }
  {
    const TinySequence tiny = WriteTinySequence("label_count");
    const std::string label_path = tiny.root + "/sequences/04/labels/000001.label";
    ASSERT_TRUE(WriteSemanticKittiLabels(label_path, {1, 2, 3}).ok());
    absl::StatusOr<KittiOdometrySequence> sequence = KittiOdometrySequence::Open(tiny.root, 4);
    ASSERT_TRUE(sequence.ok()) << sequence.status();
    absl::Status status = sequence->ReadLabeledScan(1).status();
    EXPECT_EQ(status.code(), absl::StatusCode::kInvalidArgument);
    EXPECT_THAT(status.message(),
                AllOf(HasSubstr(label_path), HasSubstr("3 labels"), HasSubstr("60 points")));
    EXPECT_TRUE(sequence->ReadLabeledScan(0).ok());
  }
  {
    const TinySequence tiny = WriteTinySequence("missing_scan");
    fs::remove(tiny.root + "/sequences/04/velodyne/000002.bin");
    absl::Status status = KittiOdometrySequence::Open(tiny.root, 4).status();
    EXPECT_EQ(status.code(), absl::StatusCode::kFailedPrecondition);
    EXPECT_THAT(status.message(), AllOf(HasSubstr("3 poses"), HasSubstr("2 .bin scans")));
  }
  {
    const TinySequence tiny = WriteTinySequence("no_calib");
    fs::remove(tiny.root + "/sequences/04/calib.txt");
    absl::Status status = KittiOdometrySequence::Open(tiny.root, 4).status();
    EXPECT_EQ(status.code(), absl::StatusCode::kNotFound);
    EXPECT_THAT(status.message(), HasSubstr("calib.txt"));
  }
  {
    const TinySequence tiny = WriteTinySequence("times");
    const std::string path = tiny.root + "/sequences/04/times.txt";
    ASSERT_TRUE(WriteFileBytes(path, "0.0\n0.1\n").ok());
    EXPECT_THAT(KittiOdometrySequence::Open(tiny.root, 4).status().message(),
                AllOf(HasSubstr(path), HasSubstr("2 timestamps")));
  }
  {
    const TinySequence tiny = WriteTinySequence("no_labels");
    fs::remove_all(tiny.root + "/sequences/04/labels");
    absl::StatusOr<KittiOdometrySequence> sequence = KittiOdometrySequence::Open(tiny.root, 4);
    ASSERT_TRUE(sequence.ok()) << sequence.status();
    EXPECT_FALSE(sequence->has_labels());
    EXPECT_EQ(sequence->ReadLabeledScan(0).status().code(), absl::StatusCode::kFailedPrecondition);
  }
}

// Mean distance from (a subsample of) `source` mapped by T to the nearest point of `target`,
// each distance capped at 1 m (parts of one scan that the other does not see).
double MeanCappedNearestDistance(const PointCloud& source, const PointCloud& target,
                                 const Eigen::Isometry3d& T) {
  const Eigen::Isometry3f Tf = T.cast<float>();
  double sum = 0.0;
  int count = 0;
  for (size_t i = 0; i < source.size(); i += source.size() / 400) {
    const Eigen::Vector3f p = Tf * source.points[i];
    float best = 1.0f;
    for (const Eigen::Vector3f& q : target.points) best = std::min(best, (p - q).squaredNorm());
    sum += std::sqrt(std::min(best, 1.0f));
    ++count;
  }
  return sum / count;
}

// The convention end to end: simulate a drive, write it, read it back, and check that
// T_target_source carries scan i onto scan i + 5's geometry (and that neither the identity nor
// the inverse does).
TEST(KittiOdometrySequenceTest, GroundTruthMapsSimulatedSourceOntoTarget) {
  const std::string root = FreshDirectory("simulated");
  LidarSequenceOptions options;
  options.frame_count = 8;
  options.seed = 5;
  absl::StatusOr<SimulatedKittiSummary> summary = WriteSimulatedKittiSequence(root, 0, options);
  ASSERT_TRUE(summary.ok()) << summary.status();
  EXPECT_EQ(summary->frame_count, 8);
  EXPECT_GE(summary->min_points_per_scan, 100000u);
  EXPECT_LE(summary->max_points_per_scan, 130000u);

  absl::StatusOr<KittiOdometrySequence> sequence = KittiOdometrySequence::Open(root, 0);
  ASSERT_TRUE(sequence.ok()) << sequence.status();
  ASSERT_EQ(sequence->frame_count(), 8);
  EXPECT_TRUE(sequence->T_world_lidar()[0].matrix().isIdentity(1e-12));

  // The reader's LiDAR poses are the simulated ones, relative to the first frame.
  absl::StatusOr<LidarSequenceSimulator> simulator = LidarSequenceSimulator::Create(options);
  ASSERT_TRUE(simulator.ok());
  for (int i = 0; i < 8; ++i) {
    const Eigen::Isometry3d expected =
        simulator->T_world_lidar()[0].inverse() * simulator->T_world_lidar()[i];
    EXPECT_TRUE(sequence->T_world_lidar()[i].matrix().isApprox(expected.matrix(), 1e-12));
  }

  absl::StatusOr<LabeledScan> source = sequence->ReadLabeledScan(0);
  absl::StatusOr<LabeledScan> target = sequence->ReadLabeledScan(5);
  ASSERT_TRUE(source.ok() && target.ok());
  const Eigen::Isometry3d T_target_source = sequence->T_target_source(0, 5);
  EXPECT_GT(T_target_source.translation().norm(), 2.0);  // the car moved 2.5-7.5 m
  // Off the ground, where a wrong transform shows most.
  absl::StatusOr<PointCloud> source_objects =
      RemoveGroundPoints(source->cloud, source->labels, "source");
  absl::StatusOr<PointCloud> target_objects =
      RemoveGroundPoints(target->cloud, target->labels, "target");
  ASSERT_TRUE(source_objects.ok() && target_objects.ok());
  const double with_truth =
      MeanCappedNearestDistance(*source_objects, *target_objects, T_target_source);
  const double with_identity =
      MeanCappedNearestDistance(*source_objects, *target_objects, Eigen::Isometry3d::Identity());
  const double with_inverse =
      MeanCappedNearestDistance(*source_objects, *target_objects, T_target_source.inverse());
  EXPECT_LT(with_truth, 0.12);
  EXPECT_GT(with_identity, 3 * with_truth);
  EXPECT_GT(with_inverse, 3 * with_truth);
}

}  // namespace
}  // namespace rpsr::core
