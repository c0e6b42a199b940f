// libFuzzer target for ParsePcd: any input either parses into a finite cloud that survives a
// write-and-read round trip, or gives InvalidArgument (Unimplemented for binary_compressed)
// naming the input. Built and run by run_fuzzer.sh.
#include <cstddef>
#include <cstdint>
#include <cstdlib>

#include "absl/strings/match.h"
#include "absl/strings/string_view.h"
#include "core/io/pcd.h"

namespace {

void Check(bool condition) {
  if (!condition) std::abort();
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const absl::string_view bytes(reinterpret_cast<const char*>(data), size);
  absl::StatusOr<rpsr::core::PointCloud> cloud = rpsr::core::ParsePcd(bytes, "fuzz.pcd");
  if (!cloud.ok()) {
    Check(cloud.status().code() == absl::StatusCode::kInvalidArgument ||
          cloud.status().code() == absl::StatusCode::kUnimplemented);
    Check(absl::StartsWith(cloud.status().message(), "fuzz.pcd: "));
    return 0;
  }
  Check(cloud->intensities.empty() || cloud->intensities.size() == cloud->points.size());
  for (const Eigen::Vector3f& p : cloud->points) Check(p.allFinite());
  for (const rpsr::core::PcdFormat format :
       {rpsr::core::PcdFormat::kAscii, rpsr::core::PcdFormat::kBinary}) {
    absl::StatusOr<std::string> written = rpsr::core::SerializePcd(*cloud, format);
    Check(written.ok());
    absl::StatusOr<rpsr::core::PointCloud> reread = rpsr::core::ParsePcd(*written, "rewritten.pcd");
    Check(reread.ok() && reread->points == cloud->points);
  }
  return 0;
}
