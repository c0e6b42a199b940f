#include "core/io/point_cloud_io.h"

#include <utility>

#include "absl/strings/ascii.h"
#include "absl/strings/str_cat.h"
#include "core/io/kitti_bin.h"
#include "core/io/off.h"
#include "core/io/pcd.h"
#include "core/io/ply.h"
#include "core/io/xyz_text.h"

namespace rpsr::core {
namespace {

constexpr char kCloudExtensions[] = ".ply .pcd .xyz .txt .csv .bin .off";
constexpr char kMeshExtensions[] = ".ply .off";

// The lower-cased extension of the file name in `path` with its dot (".ply"), or "".
std::string LowercaseExtension(const std::string& path) {
  const size_t slash = path.find_last_of('/');
  const size_t dot = path.find_last_of('.');
  if (dot == std::string::npos || (slash != std::string::npos && dot < slash)) return "";
  return absl::AsciiStrToLower(path.substr(dot));
}

absl::Status UnknownExtension(const std::string& path, const char* supported) {
  return absl::InvalidArgumentError(absl::StrCat(
      path, ": unknown file extension '", LowercaseExtension(path), "'; supported: ", supported));
}

}  // namespace

absl::StatusOr<PointCloud> ReadPointCloud(const std::string& path) {
  const std::string extension = LowercaseExtension(path);
  if (extension == ".ply") {
    absl::StatusOr<PlyContents> contents = ReadPly(path);
    if (!contents.ok()) return contents.status();
    return std::move(contents->cloud);
  }
  if (extension == ".pcd") return ReadPcd(path);
  if (extension == ".xyz" || extension == ".txt") {
    return ReadXyzText(path, XyzTextDelimiter::kWhitespace);
  }
  if (extension == ".csv") return ReadXyzText(path, XyzTextDelimiter::kComma);
  if (extension == ".bin") return ReadKittiBin(path);
  if (extension == ".off") {
    absl::StatusOr<TriangleMesh> mesh = ReadOff(path);
    if (!mesh.ok()) return mesh.status();
    PointCloud cloud;
    cloud.points = std::move(mesh->vertices);
    return cloud;
  }
  return UnknownExtension(path, kCloudExtensions);
}

absl::Status WritePointCloud(const std::string& path, const PointCloud& cloud) {
  const std::string extension = LowercaseExtension(path);
  if (extension == ".ply") return WritePly(path, cloud);
  if (extension == ".pcd") return WritePcd(path, cloud);
  if (extension == ".xyz" || extension == ".txt") {
    return WriteXyzText(path, cloud, XyzTextDelimiter::kWhitespace);
  }
  if (extension == ".csv") return WriteXyzText(path, cloud, XyzTextDelimiter::kComma);
  if (extension == ".bin") return WriteKittiBin(path, cloud);
  if (extension == ".off") {
    absl::Status valid = ValidatePointCloud(cloud);
    if (!valid.ok()) return absl::InvalidArgumentError(absl::StrCat(path, ": ", valid.message()));
    TriangleMesh mesh;
    mesh.vertices = cloud.points;
    return WriteOff(path, mesh);
  }
  return UnknownExtension(path, kCloudExtensions);
}

absl::StatusOr<TriangleMesh> ReadTriangleMesh(const std::string& path) {
  const std::string extension = LowercaseExtension(path);
  if (extension == ".ply") {
    absl::StatusOr<PlyContents> contents = ReadPly(path);
    if (!contents.ok()) return contents.status();
    if (!contents->has_faces) {
      return absl::InvalidArgumentError(
          absl::StrCat(path, ": no element 'face'; the file is a point cloud, not a mesh"));
    }
    return std::move(contents->mesh);
  }
  if (extension == ".off") return ReadOff(path);
  return UnknownExtension(path, kMeshExtensions);
}

}  // namespace rpsr::core
