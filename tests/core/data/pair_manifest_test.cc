#include "core/data/pair_manifest.h"

#include <unistd.h>

#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>

#include "core/data/transform_convention.h"
#include "gmock/gmock.h"
#include "gtest/gtest.h"

namespace rpsr::core {
namespace {

namespace fs = std::filesystem;
using ::testing::HasSubstr;

class PairManifestTest : public ::testing::Test {
 protected:
  void SetUp() override {
    const testing::TestInfo* info = testing::UnitTest::GetInstance()->current_test_info();
    dir_ = fs::temp_directory_path() /
           (std::string("rpsr_pair_manifest_") + info->name() + "_" + std::to_string(getpid()));
    fs::remove_all(dir_);
    fs::create_directories(dir_);
  }
  void TearDown() override { fs::remove_all(dir_); }

  std::string Path(const std::string& name) const { return (dir_ / name).string(); }

  std::string Write(const std::string& name, const std::string& text) const {
    std::ofstream(Path(name), std::ios::binary) << text;
    return Path(name);
  }

  std::string Read(const std::string& name) const {
    std::ifstream in(Path(name), std::ios::binary);
    std::ostringstream text;
    text << in.rdbuf();
    return text.str();
  }

  fs::path dir_;
};

Eigen::Isometry3d SomeTransform() {
  return MakeTransform(RotationFromEulerXyz(Eigen::Vector3d(0.3, -0.2, 0.71)),
                       Eigen::Vector3d(0.1, -0.45, 0.333333333333));
}

TEST_F(PairManifestTest, RoundTripIsExact) {
  std::vector<ManifestRow> rows(2);
  rows[0] = {Path("a_source.ply"), Path("a_target.ply"), SomeTransform()};
  rows[1] = {Path("b_source.ply"), Path("b_target.ply"), Eigen::Isometry3d::Identity()};
  ASSERT_TRUE(WritePairManifest(Path("manifest.csv"), rows).ok());

  absl::StatusOr<std::vector<ManifestRow>> read = ReadPairManifest(Path("manifest.csv"));
  ASSERT_TRUE(read.ok()) << read.status();
  ASSERT_EQ(read->size(), 2u);
  for (size_t i = 0; i < 2; ++i) {
    EXPECT_EQ(fs::path((*read)[i].source), fs::path(rows[i].source));
    EXPECT_EQ(fs::path((*read)[i].target), fs::path(rows[i].target));
    ASSERT_TRUE((*read)[i].T_target_source.has_value());
    // Shortest round-trip formatting: bit-exact.
    EXPECT_EQ((*read)[i].T_target_source->matrix(), rows[i].T_target_source->matrix());
  }
}

TEST_F(PairManifestTest, WritesHeaderAndRowMajorEntries) {
  const Eigen::Isometry3d T = MakeTransform(Eigen::Matrix3d::Identity(), Eigen::Vector3d(1, 2, 3));
  ASSERT_TRUE(WritePairManifest(Path("manifest.csv"), {{Path("s.bin"), Path("t.bin"), T}}).ok());
  EXPECT_EQ(Read("manifest.csv"),
            "source,target,gt\n"
            "s.bin,t.bin,1 0 0 1 0 1 0 2 0 0 1 3 0 0 0 1\n");
}

TEST_F(PairManifestTest, PathsInsideTheFolderAreRelativeOthersAbsolute) {
  fs::create_directories(dir_ / "clouds");
  const std::string outside = (dir_.parent_path() / "elsewhere" / "x.ply").string();
  ASSERT_TRUE(
      WritePairManifest(Path("manifest.csv"), {{Path("clouds/s.ply"), outside, std::nullopt}})
          .ok());
  EXPECT_EQ(Read("manifest.csv"), "source,target,gt\nclouds/s.ply," +
                                      fs::path(outside).lexically_normal().generic_string() +
                                      ",\n");

  // Moving the folder keeps the relative path valid.
  const fs::path moved = dir_ / "moved";
  fs::create_directories(moved);
  fs::copy_file(Path("manifest.csv"), moved / "manifest.csv");
  absl::StatusOr<std::vector<ManifestRow>> read =
      ReadPairManifest((moved / "manifest.csv").string());
  ASSERT_TRUE(read.ok()) << read.status();
  ASSERT_EQ(read->size(), 1u);
  EXPECT_EQ((*read)[0].source, (moved / "clouds" / "s.ply").generic_string());
  EXPECT_EQ((*read)[0].target, fs::path(outside).lexically_normal().generic_string());
}

TEST_F(PairManifestTest, RelativeManifestPathResolvesAgainstItsFolder) {
  absl::StatusOr<std::vector<ManifestRow>> read =
      ParsePairManifest("source,target,gt\nsub/../s.ply,t.ply,\n", "m.csv", "data/set");
  ASSERT_TRUE(read.ok()) << read.status();
  EXPECT_EQ((*read)[0].source, "data/set/s.ply");
  EXPECT_EQ((*read)[0].target, "data/set/t.ply");
  // An empty folder (a manifest in the working directory) leaves paths as they are.
  read = ParsePairManifest("s.ply,t.ply,", "m.csv", "");
  ASSERT_TRUE(read.ok()) << read.status();
  EXPECT_EQ((*read)[0].source, "s.ply");
}

TEST_F(PairManifestTest, MissingGroundTruthIsAccepted) {
  const std::string path =
      Write("m.csv", "source,target,gt\r\na.ply,b.ply,\r\n\r\nc.ply,d.ply,   \r\n");
  absl::StatusOr<std::vector<ManifestRow>> read = ReadPairManifest(path);
  ASSERT_TRUE(read.ok()) << read.status();
  ASSERT_EQ(read->size(), 2u);
  EXPECT_FALSE((*read)[0].T_target_source.has_value());
  EXPECT_FALSE((*read)[1].T_target_source.has_value());
  EXPECT_EQ((*read)[1].source, Path("c.ply"));
}

TEST_F(PairManifestTest, HeaderIsOptionalOnRead) {
  absl::StatusOr<std::vector<ManifestRow>> read =
      ParsePairManifest("a,b,1 0 0 0 0 1 0 0 0 0 1 0 0 0 0 1\n", "m.csv", "");
  ASSERT_TRUE(read.ok()) << read.status();
  ASSERT_EQ(read->size(), 1u);
  EXPECT_TRUE((*read)[0].T_target_source->isApprox(Eigen::Isometry3d::Identity()));
}

TEST_F(PairManifestTest, MalformedLinesNameFileAndLine) {
  struct Case {
    std::string line;
    std::string message;
  };
  const std::vector<Case> cases = {
      {"a.ply,b.ply", "expected 3 comma-separated fields"},
      {"a.ply,b.ply,1 0 0 0,extra", "expected 3 comma-separated fields"},
      {",b.ply,", "empty source"},
      {"a.ply, ,", "empty target"},
      {"a.ply,b.ply,1 0 0 0 0 1 0 0 0 0 1 0", "found 12"},
      {"a.ply,b.ply,1 0 0 0 0 1 0 0 0 0 1 0 0 0 0 x", "entry 16 'x' is not a number"},
      {"a.ply,b.ply,1 0 0 0 0 1 0 0 0 0 1 0 0 0 0 nan", "gt:"},
      {"a.ply,b.ply,2 0 0 0 0 1 0 0 0 0 1 0 0 0 0 1", "gt:"},   // not a rotation
      {"a.ply,b.ply,1 0 0 0 0 1 0 0 0 0 1 0 0 0 1 1", "gt:"},   // last row not 0 0 0 1
      {"a.ply,b.ply,-1 0 0 0 0 1 0 0 0 0 1 0 0 0 0 1", "gt:"},  // a reflection
  };
  for (const Case& c : cases) {
    const std::string path = Write("bad.csv", "source,target,gt\na,b,\n" + c.line + "\n");
    absl::StatusOr<std::vector<ManifestRow>> read = ReadPairManifest(path);
    ASSERT_FALSE(read.ok()) << c.line;
    EXPECT_EQ(read.status().code(), absl::StatusCode::kInvalidArgument) << c.line;
    EXPECT_THAT(read.status().message(), HasSubstr(path + ":3: ")) << c.line;
    EXPECT_THAT(read.status().message(), HasSubstr(c.message)) << c.line;
  }
}

TEST_F(PairManifestTest, MissingFileIsNotFound) {
  absl::StatusOr<std::vector<ManifestRow>> read = ReadPairManifest(Path("absent.csv"));
  EXPECT_EQ(read.status().code(), absl::StatusCode::kNotFound);
  EXPECT_THAT(read.status().message(), HasSubstr("absent.csv"));
}

TEST_F(PairManifestTest, WriteRejectsPathsTheFormatCannotStore) {
  absl::Status status =
      WritePairManifest(Path("m.csv"), {{Path("a,b.ply"), Path("c.ply"), std::nullopt}});
  EXPECT_EQ(status.code(), absl::StatusCode::kInvalidArgument);
  EXPECT_THAT(status.message(), HasSubstr("row 1"));
  status = WritePairManifest(Path("m.csv"), {{"", Path("c.ply"), std::nullopt}});
  EXPECT_EQ(status.code(), absl::StatusCode::kInvalidArgument);
}

TEST_F(PairManifestTest, WriteToMissingFolderFails) {
  const absl::Status status = WritePairManifest(Path("no/such/folder/m.csv"),
                                                {{Path("a.ply"), Path("b.ply"), std::nullopt}});
  EXPECT_FALSE(status.ok());
  EXPECT_THAT(status.message(), HasSubstr("no/such/folder/m.csv"));
}

}  // namespace
}  // namespace rpsr::core
