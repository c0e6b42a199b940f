#include "client/cli/sample_pairs.h"

#include <filesystem>

#include "absl/strings/str_cat.h"
#include "absl/strings/string_view.h"
#include "core/data/pair_manifest.h"
#include "core/io/file_bytes.h"
#include "core/io/ply.h"
#include "core/io/point_cloud_io.h"

namespace rpsr::client {
namespace embedded {

struct EmbeddedFile {
  const char* path;
  const char* begin;
  const char* end;
};
// embedded_samples_data.cc (generated); ends with a null path.
extern const EmbeddedFile kSampleFiles[];

}  // namespace embedded
namespace {

absl::StatusOr<absl::string_view> EmbeddedFile(const std::string& path) {
  for (const embedded::EmbeddedFile* file = embedded::kSampleFiles; file->path != nullptr; ++file) {
    if (path == file->path) {
      return absl::string_view(file->begin, static_cast<size_t>(file->end - file->begin));
    }
  }
  return absl::NotFoundError(absl::StrCat("no sample file ", path, " in this binary"));
}

absl::StatusOr<core::PointCloud> EmbeddedCloud(const std::string& path) {
  absl::StatusOr<absl::string_view> bytes = EmbeddedFile(path);
  if (!bytes.ok()) return bytes.status();
  absl::StatusOr<core::PlyContents> ply = core::ParsePly(*bytes, path);
  if (!ply.ok()) return ply.status();
  return std::move(ply->cloud);
}

}  // namespace

absl::StatusOr<SamplePair> LoadSamplePair(const std::string& data_folder,
                                          const std::string& sample) {
  SamplePair pair;
  if (data_folder.empty()) {
    const std::string manifest_name = sample + "/manifest.csv";
    absl::StatusOr<absl::string_view> manifest = EmbeddedFile(manifest_name);
    if (!manifest.ok()) return manifest.status();
    // Relative paths stay relative ("clouds/..."): they name embedded files under <sample>/.
    absl::StatusOr<std::vector<core::ManifestRow>> rows =
        core::ParsePairManifest(*manifest, manifest_name, "");
    if (!rows.ok()) return rows.status();
    if (rows->empty()) return absl::NotFoundError(absl::StrCat(manifest_name, " lists no pair"));
    pair.source_name = absl::StrCat(sample, "/", rows->front().source);
    pair.target_name = absl::StrCat(sample, "/", rows->front().target);
    pair.T_target_source = rows->front().T_target_source;
    absl::StatusOr<core::PointCloud> source = EmbeddedCloud(pair.source_name);
    if (!source.ok()) return source.status();
    absl::StatusOr<core::PointCloud> target = EmbeddedCloud(pair.target_name);
    if (!target.ok()) return target.status();
    pair.source = *std::move(source);
    pair.target = *std::move(target);
    return pair;
  }
  const std::string manifest_path =
      (std::filesystem::path(data_folder) / sample / "manifest.csv").string();
  absl::StatusOr<std::vector<core::ManifestRow>> rows = core::ReadPairManifest(manifest_path);
  if (!rows.ok()) return rows.status();
  if (rows->empty()) return absl::NotFoundError(absl::StrCat(manifest_path, " lists no pair"));
  pair.source_name = rows->front().source;
  pair.target_name = rows->front().target;
  pair.T_target_source = rows->front().T_target_source;
  absl::StatusOr<core::PointCloud> source = core::ReadPointCloud(pair.source_name);
  if (!source.ok()) return source.status();
  absl::StatusOr<core::PointCloud> target = core::ReadPointCloud(pair.target_name);
  if (!target.ok()) return target.status();
  pair.source = *std::move(source);
  pair.target = *std::move(target);
  return pair;
}

}  // namespace rpsr::client
