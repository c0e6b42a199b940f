// The sample pairs of client/examples/data (an object pair and two LiDAR scans with their
// truth), linked into the `rpsr` binary so that `rpsr demo` and `rpsr bench` work on a machine
// that has the binary and nothing else; or read from a folder of the same layout.
#ifndef RPSR_CLIENT_CLI_SAMPLE_PAIRS_H_
#define RPSR_CLIENT_CLI_SAMPLE_PAIRS_H_

#include <optional>
#include <string>

#include "Eigen/Geometry"
#include "absl/status/statusor.h"
#include "core/cloud/point_cloud.h"

namespace rpsr::client {

struct SamplePair {
  std::string source_name;  // e.g. "object/clouds/000000_source.ply" (embedded) or a path
  std::string target_name;
  core::PointCloud source;
  core::PointCloud target;
  std::optional<Eigen::Isometry3d> T_target_source;
};

// The first pair of <sample>/manifest.csv (sample: "object" or "lidar"). `data_folder` empty:
// the copy embedded in the binary; else the folder's files. NotFound naming what is missing.
absl::StatusOr<SamplePair> LoadSamplePair(const std::string& data_folder,
                                          const std::string& sample);

}  // namespace rpsr::client

#endif  // RPSR_CLIENT_CLI_SAMPLE_PAIRS_H_
