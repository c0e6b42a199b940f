#include "core/synth/mesh_folder.h"

#include <algorithm>
#include <cctype>
#include <filesystem>
#include <system_error>

#include "absl/strings/str_cat.h"
#include "core/io/point_cloud_io.h"
#include "core/synth/object_normalization.h"

namespace rpsr::core {
namespace {

bool HasMeshExtension(const std::filesystem::path& path) {
  std::string extension = path.extension().string();
  std::transform(extension.begin(), extension.end(), extension.begin(),
                 [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
  return extension == ".off" || extension == ".ply";
}

template <typename Iterator>
absl::Status CollectMeshFiles(Iterator it, std::vector<std::string>& paths) {
  std::error_code error;
  for (; it != Iterator(); it.increment(error)) {
    if (error) break;
    std::error_code type_error;
    if (it->is_regular_file(type_error) && HasMeshExtension(it->path())) {
      paths.push_back(it->path().string());
    }
  }
  if (error) {
    return absl::InternalError(absl::StrCat("listing mesh files: ", error.message()));
  }
  return absl::OkStatus();
}

}  // namespace

absl::StatusOr<std::vector<std::string>> ListMeshFiles(const std::string& folder, bool recursive) {
  std::error_code error;
  if (!std::filesystem::is_directory(folder, error)) {
    return absl::NotFoundError(absl::StrCat("mesh folder ", folder, " is not a directory"));
  }
  std::vector<std::string> paths;
  absl::Status status;
  if (recursive) {
    status = CollectMeshFiles(std::filesystem::recursive_directory_iterator(folder, error), paths);
  } else {
    status = CollectMeshFiles(std::filesystem::directory_iterator(folder, error), paths);
  }
  if (error) {
    return absl::InternalError(absl::StrCat("cannot list ", folder, ": ", error.message()));
  }
  if (!status.ok()) return status;
  std::sort(paths.begin(), paths.end());
  return paths;
}

absl::StatusOr<TriangleMesh> ReadNormalizedMesh(const std::string& path) {
  absl::StatusOr<TriangleMesh> mesh = ReadTriangleMesh(path);
  if (!mesh.ok()) return mesh.status();
  absl::StatusOr<TriangleMesh> normalized = NormalizedIntoUnitCube(*mesh);
  if (!normalized.ok()) {
    return absl::Status(normalized.status().code(),
                        absl::StrCat(path, ": ", normalized.status().message()));
  }
  return normalized;
}

}  // namespace rpsr::core
