// End to end: runs the built `rpsr data` and checks what it writes with the library readers.
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_split.h"
#include "core/data/kitti_odometry.h"
#include "core/data/pair_manifest.h"
#include "core/io/point_cloud_io.h"
#include "gmock/gmock.h"
#include "gtest/gtest.h"

namespace rpsr::client {
namespace {

namespace fs = std::filesystem;
using ::testing::HasSubstr;

class DataCommandTest : public ::testing::Test {
 protected:
  void SetUp() override {
    const testing::TestInfo* info = testing::UnitTest::GetInstance()->current_test_info();
    dir_ =
        fs::temp_directory_path() / absl::StrCat("rpsr_data_command_", info->name(), "_", getpid());
    fs::remove_all(dir_);
    fs::create_directories(dir_);
  }
  void TearDown() override { fs::remove_all(dir_); }

  // Runs `rpsr data <args>`; returns its exit code and keeps its stderr in stderr_.
  int RunData(const std::string& args) {
    const fs::path log = dir_ / "stderr.txt";
    const std::string command =
        absl::StrCat(RPSR_CLI_BINARY, " data ", args, " 2>", log.string(), " >/dev/null");
    const int status = std::system(command.c_str());
    std::ifstream in(log);
    std::ostringstream text;
    text << in.rdbuf();
    stderr_ = text.str();
    return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  }

  std::string Path(const std::string& name) const { return (dir_ / name).string(); }

  static std::string ReadText(const std::string& path) {
    std::ifstream in(path);
    std::ostringstream text;
    text << in.rdbuf();
    return text.str();
  }

  fs::path dir_;
  std::string stderr_;
};

TEST_F(DataCommandTest, ObjectPairsWithSamePointsMapSourceOntoTarget) {
  ASSERT_EQ(RunData(absl::StrCat("pairs --protocol objects --count 5 --same_points --seed 3 "
                                 "--num_points 256 --output ",
                                 Path("pairs"))),
            0)
      << stderr_;
  absl::StatusOr<std::vector<core::ManifestRow>> rows =
      core::ReadPairManifest(Path("pairs/manifest.csv"));
  ASSERT_TRUE(rows.ok()) << rows.status();
  ASSERT_EQ(rows->size(), 5u);
  for (const core::ManifestRow& row : *rows) {
    ASSERT_TRUE(row.T_target_source.has_value());
    absl::StatusOr<core::PointCloud> source = core::ReadPointCloud(row.source);
    absl::StatusOr<core::PointCloud> target = core::ReadPointCloud(row.target);
    ASSERT_TRUE(source.ok()) << source.status();
    ASSERT_TRUE(target.ok()) << target.status();
    ASSERT_EQ(source->size(), 256u);
    ASSERT_EQ(target->size(), 256u);
    double max_error = 0.0;
    for (size_t i = 0; i < source->size(); ++i) {
      const Eigen::Vector3d mapped = *row.T_target_source * source->points[i].cast<double>();
      max_error = std::max(max_error, (mapped - target->points[i].cast<double>()).norm());
    }
    EXPECT_LT(max_error, 1e-5) << row.source;  // float32 files
    EXPECT_FALSE(row.T_target_source->isApprox(Eigen::Isometry3d::Identity()));
  }
  // The manifest stores paths relative to its folder.
  EXPECT_THAT(ReadText(Path("pairs/manifest.csv")),
              HasSubstr("source,target,gt\nclouds/000000_source.ply,clouds/000000_target.ply,"));
  // One line of details a pair, after the header.
  const std::vector<std::string> details =
      absl::StrSplit(ReadText(Path("pairs/pairs.csv")), '\n', absl::SkipEmpty());
  EXPECT_EQ(details.size(), 6u);
}

TEST_F(DataCommandTest, SameSeedWritesTheSamePairs) {
  ASSERT_EQ(RunData(absl::StrCat("pairs --count 3 --disturbance crop --level 3 --seed 9 "
                                 "--num_points 128 --format xyz --output ",
                                 Path("a"))),
            0)
      << stderr_;
  ASSERT_EQ(RunData(absl::StrCat("pairs --count 3 --disturbance crop --level 3 --seed 9 "
                                 "--num_points 128 --format xyz --output ",
                                 Path("b"))),
            0)
      << stderr_;
  EXPECT_EQ(ReadText(Path("a/manifest.csv")), ReadText(Path("b/manifest.csv")));
  EXPECT_EQ(ReadText(Path("a/clouds/000002_source.xyz")),
            ReadText(Path("b/clouds/000002_source.xyz")));
  // Level 3 crop removes 30% of the source.
  absl::StatusOr<core::PointCloud> source =
      core::ReadPointCloud(Path("a/clouds/000000_source.xyz"));
  ASSERT_TRUE(source.ok()) << source.status();
  EXPECT_EQ(source->size(), 128u - 38u);
}

// --disturbance partial: both clouds lose 30% at level 3 (which chunk: object_pairs_test).
TEST_F(DataCommandTest, PartialViewsCropBothClouds) {
  ASSERT_EQ(RunData(absl::StrCat("pairs --count 2 --disturbance partial --level 3 --seed 9 "
                                 "--num_points 128 --format xyz --output ",
                                 Path("partial"))),
            0)
      << stderr_;
  for (const char* side : {"source", "target"}) {
    absl::StatusOr<core::PointCloud> cloud =
        core::ReadPointCloud(Path(absl::StrCat("partial/clouds/000001_", side, ".xyz")));
    ASSERT_TRUE(cloud.ok()) << cloud.status();
    EXPECT_EQ(cloud->size(), 128u - 38u) << side;
  }
  EXPECT_THAT(ReadText(Path("partial/pairs.csv")), HasSubstr(",partial_views,0.3,90,90,"));
}

TEST_F(DataCommandTest, ObjectsAreNormalisedAndListed) {
  ASSERT_EQ(RunData(absl::StrCat("objects --count 3 --split seen --num_points 200 --output ",
                                 Path("objects"))),
            0)
      << stderr_;
  const std::vector<std::string> lines =
      absl::StrSplit(ReadText(Path("objects/objects.csv")), '\n', absl::SkipEmpty());
  ASSERT_EQ(lines.size(), 4u);
  for (size_t i = 1; i < lines.size(); ++i) {
    const std::vector<std::string> fields = absl::StrSplit(lines[i], ',');
    ASSERT_EQ(fields.size(), 6u) << lines[i];
    EXPECT_EQ(fields[3], "seen");
    absl::StatusOr<core::PointCloud> cloud = core::ReadPointCloud(Path("objects/" + fields[0]));
    ASSERT_TRUE(cloud.ok()) << cloud.status();
    ASSERT_EQ(cloud->size(), 200u);
    for (const Eigen::Vector3f& p : cloud->points) {
      EXPECT_LE(p.cwiseAbs().maxCoeff(), 1.0f + 1e-6f);
    }
  }
}

TEST_F(DataCommandTest, SimulatedLidarSequenceGivesPairsWithItsGroundTruth) {
  ASSERT_EQ(RunData(absl::StrCat("lidar --frames 12 --seed 5 --output ", Path("kitti"))), 0)
      << stderr_;
  absl::StatusOr<core::KittiOdometrySequence> sequence =
      core::KittiOdometrySequence::Open(Path("kitti"), 0);
  ASSERT_TRUE(sequence.ok()) << sequence.status();
  ASSERT_EQ(sequence->frame_count(), 12);

  // 12 frames: the training block is frames 0..7, so sources 0, 1, 2.
  ASSERT_EQ(RunData(absl::StrCat("pairs --protocol lidar --kitti ", Path("kitti"),
                                 " --sequence 00 --split train --output ", Path("kept"))),
            0)
      << stderr_;
  absl::StatusOr<std::vector<core::ManifestRow>> rows =
      core::ReadPairManifest(Path("kept/manifest.csv"));
  ASSERT_TRUE(rows.ok()) << rows.status();
  ASSERT_EQ(rows->size(), 3u);
  for (int i = 0; i < 3; ++i) {
    const core::ManifestRow& row = (*rows)[i];
    EXPECT_EQ(fs::path(row.source).filename(), absl::StrCat("00_00000", i, ".bin"));
    EXPECT_EQ(fs::path(row.target).filename(), absl::StrCat("00_00000", i + 5, ".bin"));
    ASSERT_TRUE(row.T_target_source.has_value());
    EXPECT_TRUE(row.T_target_source->isApprox(sequence->T_target_source(i, i + 5), 1e-12));
    absl::StatusOr<core::PointCloud> written = core::ReadPointCloud(row.source);
    absl::StatusOr<core::PointCloud> scan = sequence->ReadScan(i);
    ASSERT_TRUE(written.ok()) << written.status();
    ASSERT_TRUE(scan.ok()) << scan.status();
    EXPECT_EQ(written->size(), scan->size());  // ground kept (K2-w)
  }

  // K1-w/o: the ground is gone, so the clouds are smaller.
  ASSERT_EQ(RunData(absl::StrCat("pairs --protocol lidar --kitti ", Path("kitti"),
                                 " --sequence 0 --split train --ground remove --max_pairs 1 "
                                 "--format ply --output ",
                                 Path("removed"))),
            0)
      << stderr_;
  rows = core::ReadPairManifest(Path("removed/manifest.csv"));
  ASSERT_TRUE(rows.ok()) << rows.status();
  ASSERT_EQ(rows->size(), 1u);
  const int frame = std::stoi(fs::path((*rows)[0].source).stem().string().substr(3));
  absl::StatusOr<core::PointCloud> without_ground = core::ReadPointCloud((*rows)[0].source);
  absl::StatusOr<core::PointCloud> scan = sequence->ReadScan(frame);
  ASSERT_TRUE(without_ground.ok()) << without_ground.status();
  ASSERT_TRUE(scan.ok()) << scan.status();
  EXPECT_GT(without_ground->size(), 0u);
  EXPECT_LT(without_ground->size(), scan->size());

  // The test block of 12 frames is too short: a flag problem, with advice.
  EXPECT_EQ(RunData(absl::StrCat("pairs --protocol lidar --kitti ", Path("kitti"),
                                 " --sequence 00 --output ", Path("test"))),
            2);
  EXPECT_THAT(stderr_, HasSubstr("--split"));
  // A sequence that is not there: reading fails, and the message lists those that are.
  EXPECT_EQ(RunData(absl::StrCat("pairs --protocol lidar --kitti ", Path("kitti"),
                                 " --sequence 07 --output ", Path("x"))),
            1);
  EXPECT_THAT(stderr_, HasSubstr("sequences under"));
}

// --sensor simulates the named scanner: a VLP-16's 16 beams span +-15 degrees, where an HDL-64E's
// reach down to -24.8 degrees, and it returns a fraction of the points.
TEST_F(DataCommandTest, SensorPresetsSimulateTheirBeams) {
  struct Scan {
    size_t points = 0;
    double lowest_deg = 90.0;
    double highest_deg = -90.0;
  };
  auto simulate = [&](const std::string& sensor) {
    Scan scan;
    const std::string out = Path(sensor);
    EXPECT_EQ(RunData(absl::StrCat("lidar --frames 1 --seed 5 --style urban --sensor ", sensor,
                                   " --output ", out)),
              0)
        << stderr_;
    absl::StatusOr<core::KittiOdometrySequence> sequence =
        core::KittiOdometrySequence::Open(out, 0);
    EXPECT_TRUE(sequence.ok()) << sequence.status();
    if (!sequence.ok()) return scan;
    absl::StatusOr<core::PointCloud> cloud = sequence->ReadScan(0);
    EXPECT_TRUE(cloud.ok()) << cloud.status();
    if (!cloud.ok()) return scan;
    scan.points = cloud->size();
    for (const Eigen::Vector3f& p : cloud->points) {
      const double elevation = std::atan2(p.z(), std::hypot(p.x(), p.y())) * 180.0 / M_PI;
      scan.lowest_deg = std::min(scan.lowest_deg, elevation);
      scan.highest_deg = std::max(scan.highest_deg, elevation);
    }
    return scan;
  };
  const Scan hdl64 = simulate("hdl64");
  const Scan vlp16 = simulate("vlp16");
  EXPECT_LT(hdl64.lowest_deg, -24.0);
  EXPECT_GT(vlp16.lowest_deg, -15.5);  // range noise moves a return a little off its beam
  EXPECT_LT(vlp16.lowest_deg, -14.5);
  EXPECT_LT(vlp16.points * 3, hdl64.points);
  EXPECT_EQ(RunData("lidar --sensor vlp32 --output " + Path("x")), 2);
  EXPECT_THAT(stderr_, HasSubstr("hdl64, hdl32 or vlp16"));
}

TEST_F(DataCommandTest, BadFlagsExitWithTwoAndSayWhatToFix) {
  EXPECT_EQ(RunData(""), 2);
  EXPECT_THAT(stderr_, HasSubstr("usage:"));
  EXPECT_EQ(RunData("shapes --output " + Path("x")), 2);
  EXPECT_THAT(stderr_, HasSubstr("unknown mode 'shapes'"));
  EXPECT_EQ(RunData("objects"), 2);
  EXPECT_THAT(stderr_, HasSubstr("--output"));
  EXPECT_EQ(RunData("objects --split m3 --output " + Path("x")), 2);
  EXPECT_THAT(stderr_, HasSubstr("m1, seen or unseen"));
  EXPECT_EQ(RunData("pairs --disturbance blur --output " + Path("x")), 2);
  EXPECT_THAT(stderr_, HasSubstr("none, noise, outliers, crop, jitter or partial"));
  EXPECT_EQ(RunData("pairs --level 7 --output " + Path("x")), 2);
  EXPECT_EQ(RunData("pairs --format las --output " + Path("x")), 2);
  EXPECT_EQ(RunData("pairs --protocol lidar --output " + Path("x")), 2);
  EXPECT_THAT(stderr_, HasSubstr("--kitti"));
  EXPECT_EQ(RunData("lidar --style city --output " + Path("x")), 2);
  EXPECT_EQ(RunData("objects --mesh_folder " + Path("none") + " --output " + Path("x")), 2);
}

TEST_F(DataCommandTest, OutputThatCannotBeCreatedExitsWithOne) {
  std::ofstream(Path("file")) << "not a folder";
  EXPECT_EQ(RunData("objects --count 1 --output " + Path("file")), 1);
  EXPECT_THAT(stderr_, HasSubstr("cannot create"));
}

}  // namespace
}  // namespace rpsr::client
