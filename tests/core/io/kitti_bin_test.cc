#include "core/io/kitti_bin.h"

#include <cstring>
#include <limits>
#include <string>

#include "core/io/file_bytes.h"
#include "gmock/gmock.h"
#include "gtest/gtest.h"
#include "tests/core/io/status_expectations.h"

namespace rpsr::core {
namespace {

TEST(KittiBinTest, RoundTripsWithReflectance) {
  PointCloud cloud;
  cloud.points = {{1.5f, -2, 3}, {0, 0, -1e-3f}};
  cloud.intensities = {0.25f, 1};
  const std::string path = testing::TempDir() + "/scan.bin";
  ASSERT_TRUE(WriteKittiBin(path, cloud).ok());
  absl::StatusOr<PointCloud> read = ReadKittiBin(path);
  ASSERT_TRUE(read.ok()) << read.status();
  EXPECT_EQ(read->points, cloud.points);
  EXPECT_EQ(read->intensities, cloud.intensities);
}

TEST(KittiBinTest, MissingReflectanceIsWrittenAsZero) {
  PointCloud cloud;
  cloud.points = {{1, 2, 3}};
  const std::string path = testing::TempDir() + "/no_reflectance.bin";
  ASSERT_TRUE(WriteKittiBin(path, cloud).ok());
  absl::StatusOr<std::string> bytes = ReadFileBytes(path);
  ASSERT_TRUE(bytes.ok());
  ASSERT_EQ(bytes->size(), 16u);
  float record[4];
  std::memcpy(record, bytes->data(), 16);
  EXPECT_EQ(record[0], 1);
  EXPECT_EQ(record[2], 3);
  EXPECT_EQ(record[3], 0);
}

TEST(KittiBinTest, EmptyBytesAreAnEmptyScan) {
  absl::StatusOr<PointCloud> parsed = ParseKittiBin("", "empty.bin");
  ASSERT_TRUE(parsed.ok());
  EXPECT_TRUE(parsed->empty());
}

TEST(KittiBinTest, TruncatedRecordNamesFileAndSize) {
  ExpectInvalid(ParseKittiBin(std::string(20, '\0'), "cut.bin"), "cut.bin",
                {"20 bytes", "16-byte"});
}

TEST(KittiBinTest, NonFiniteCoordinateNamesRecordAndOffset) {
  float records[8] = {0, 0, 0, 0, 1, std::numeric_limits<float>::infinity(), 0, 0};
  ExpectInvalid(ParseKittiBin(std::string(reinterpret_cast<const char*>(records), 32), "inf.bin"),
                "inf.bin", {"record 1", "byte offset 16"});
}

TEST(KittiBinTest, WriterRejectsMismatchedIntensities) {
  PointCloud cloud;
  cloud.points = {{1, 2, 3}, {4, 5, 6}};
  cloud.intensities = {1};
  ExpectInvalid(WriteKittiBin(testing::TempDir() + "/bad.bin", cloud),
                testing::TempDir() + "/bad.bin", {"2 points but 1 intensities"});
}

TEST(KittiBinTest, MissingFileIsNotFound) {
  ExpectError(ReadKittiBin(testing::TempDir() + "/absent.bin"), absl::StatusCode::kNotFound,
              {"absent.bin"});
}

}  // namespace
}  // namespace rpsr::core
