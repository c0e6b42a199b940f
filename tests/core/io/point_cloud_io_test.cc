#include "core/io/point_cloud_io.h"

#include <string>

#include "core/io/file_bytes.h"
#include "core/io/off.h"
#include "core/io/ply.h"
#include "gmock/gmock.h"
#include "gtest/gtest.h"
#include "tests/core/io/status_expectations.h"

namespace rpsr::core {
namespace {

PointCloud SmallCloud() {
  PointCloud cloud;
  cloud.points = {{0.1f, -2.5f, 3e7f}, {-1e-20f, 0, 42}, {1, 2, 3}};
  return cloud;
}

TriangleMesh Square() {
  TriangleMesh mesh;
  mesh.vertices = {{0, 0, 0}, {1, 0, 0}, {1, 1, 0}, {0, 1, 0}};
  mesh.triangles = {{0, 1, 2}, {0, 2, 3}};
  return mesh;
}

TEST(PointCloudIoTest, EveryExtensionRoundTrips) {
  for (const char* extension :
       {".ply", ".pcd", ".xyz", ".txt", ".csv", ".bin", ".off", ".PLY", ".Pcd"}) {
    const std::string path = testing::TempDir() + "/cloud" + extension;
    ASSERT_TRUE(WritePointCloud(path, SmallCloud()).ok()) << path;
    absl::StatusOr<PointCloud> read = ReadPointCloud(path);
    ASSERT_TRUE(read.ok()) << read.status();
    EXPECT_EQ(read->points, SmallCloud().points) << path;
  }
}

TEST(PointCloudIoTest, IntensitiesSurviveFormatsThatHoldThem) {
  PointCloud cloud = SmallCloud();
  cloud.intensities = {1, 2, 3};
  for (const char* extension : {".ply", ".pcd", ".bin"}) {
    const std::string path = testing::TempDir() + "/intensity" + extension;
    ASSERT_TRUE(WritePointCloud(path, cloud).ok());
    absl::StatusOr<PointCloud> read = ReadPointCloud(path);
    ASSERT_TRUE(read.ok()) << read.status();
    EXPECT_EQ(read->intensities, cloud.intensities) << path;
  }
}

TEST(PointCloudIoTest, MeshFilesReadAsMeshesAndAsClouds) {
  const std::string ply = testing::TempDir() + "/square.ply";
  const std::string off = testing::TempDir() + "/square.off";
  ASSERT_TRUE(WritePly(ply, Square(), PlyFormat::kAscii).ok());
  ASSERT_TRUE(WriteOff(off, Square()).ok());
  for (const std::string& path : {ply, off}) {
    absl::StatusOr<TriangleMesh> mesh = ReadTriangleMesh(path);
    ASSERT_TRUE(mesh.ok()) << mesh.status();
    EXPECT_EQ(mesh->vertices, Square().vertices);
    EXPECT_EQ(mesh->triangles, Square().triangles);
    absl::StatusOr<PointCloud> cloud = ReadPointCloud(path);
    ASSERT_TRUE(cloud.ok()) << cloud.status();
    EXPECT_EQ(cloud->points, Square().vertices);
  }
}

TEST(PointCloudIoTest, PlyWithoutFacesIsNotAMesh) {
  const std::string path = testing::TempDir() + "/points_only.ply";
  ASSERT_TRUE(WritePointCloud(path, SmallCloud()).ok());
  ExpectInvalid(ReadTriangleMesh(path), path, {"no element 'face'"});
}

TEST(PointCloudIoTest, UnknownExtensionsListTheSupportedOnes) {
  ExpectInvalid(ReadPointCloud("/tmp/cloud.las"), "/tmp/cloud.las",
                {"'.las'", ".ply .pcd .xyz .txt .csv .bin .off"});
  ExpectInvalid(ReadPointCloud("/tmp/dir.ply/cloud"), "/tmp/dir.ply/cloud", {"''"});
  ExpectInvalid(WritePointCloud("/tmp/cloud.obj", SmallCloud()), "/tmp/cloud.obj",
                {"'.obj'", ".ply .pcd"});
  ExpectInvalid(ReadTriangleMesh("/tmp/cloud.pcd"), "/tmp/cloud.pcd", {"'.pcd'", ".ply .off"});
}

TEST(PointCloudIoTest, MissingFileIsNotFound) {
  ExpectError(ReadPointCloud(testing::TempDir() + "/absent.pcd"), absl::StatusCode::kNotFound,
              {"absent.pcd"});
  ExpectError(ReadTriangleMesh(testing::TempDir() + "/absent.off"), absl::StatusCode::kNotFound,
              {"absent.off"});
}

TEST(PointCloudIoTest, MalformedContentNamesTheFile) {
  const std::string path = testing::TempDir() + "/broken.pcd";
  ASSERT_TRUE(WriteFileBytes(path, "FIELDS x y\n").ok());
  ExpectInvalid(ReadPointCloud(path), path, {"DATA"});
}

}  // namespace
}  // namespace rpsr::core
