// The pair manifest: the CSV that lists registration pairs on disk, written by `rpsr data` and
// read by the evaluation and benchmark drivers.
//
//   source,target,gt
//   clouds/000000_source.ply,clouds/000000_target.ply,0.9 -0.1 ... 0 0 0 1
//
// One pair a line after the header. `gt` is T_target_source (maps source points into the target
// frame) as its 16 entries in row-major order separated by single spaces
// (transform_convention.h); it may be empty when the ground truth is unknown. Paths inside the
// manifest's folder are stored relative to it, other paths absolute; relative paths are resolved
// against the manifest's folder on read, so a data set folder can be moved as a whole. Paths may
// not contain a comma, a double quote or a line break (there is no CSV quoting).
#ifndef RPSR_CORE_DATA_PAIR_MANIFEST_H_
#define RPSR_CORE_DATA_PAIR_MANIFEST_H_

#include <optional>
#include <string>
#include <vector>

#include "Eigen/Geometry"
#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "absl/strings/string_view.h"

namespace rpsr::core {

inline constexpr char kPairManifestHeader[] = "source,target,gt";

struct ManifestRow {
  std::string source;
  std::string target;
  // Maps source points into the target frame; nullopt when the ground truth is unknown.
  std::optional<Eigen::Isometry3d> T_target_source;
};

// Writes the header and one line per row to `path` (its folder must exist). Paths are written
// relative to the manifest's folder when they lie inside it (a relative path is first taken
// relative to the working directory), absolute otherwise; numbers in the shortest form that
// reads back exactly. InvalidArgument (naming the row, 1-based) for an empty path, a path with
// a comma, quote or line break, or a non-finite transform; Internal when the file cannot be
// written.
absl::Status WritePairManifest(const std::string& path, const std::vector<ManifestRow>& rows);

// Reads a manifest written by WritePairManifest (or by hand). The header line is optional; blank
// lines are skipped; a trailing '\r' is ignored. Relative paths come back joined to the
// manifest's folder. NotFound when the file cannot be opened; InvalidArgument naming the file
// and the 1-based line for a line without exactly three comma-separated fields, an empty source
// or target, a gt that is not 16 numbers, or a gt that is not a rigid transform
// (TransformFromRowMajor's checks).
absl::StatusOr<std::vector<ManifestRow>> ReadPairManifest(const std::string& path);

// The parser behind ReadPairManifest: `text` as the manifest's contents, `name` for errors, and
// relative paths joined to `folder` (left as they are when `folder` is empty).
absl::StatusOr<std::vector<ManifestRow>> ParsePairManifest(absl::string_view text,
                                                           absl::string_view name,
                                                           const std::string& folder);

}  // namespace rpsr::core

#endif  // RPSR_CORE_DATA_PAIR_MANIFEST_H_
