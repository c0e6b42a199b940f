// libFuzzer target for ParsePly: any input either parses into a consistent cloud / mesh that
// survives a write-and-read round trip, or gives InvalidArgument naming the input. Built and run
// by run_fuzzer.sh.
#include <algorithm>
#include <bit>
#include <cstddef>
#include <cstdint>
#include <cstdlib>

#include "absl/strings/match.h"
#include "absl/strings/string_view.h"
#include "core/io/ply.h"

namespace {

void Check(bool condition) {
  if (!condition) std::abort();
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using rpsr::core::PlyContents;
  const absl::string_view bytes(reinterpret_cast<const char*>(data), size);
  absl::StatusOr<PlyContents> contents = rpsr::core::ParsePly(bytes, "fuzz.ply");
  if (!contents.ok()) {
    Check(contents.status().code() == absl::StatusCode::kInvalidArgument);
    Check(absl::StartsWith(contents.status().message(), "fuzz.ply: "));
    return 0;
  }
  const rpsr::core::PointCloud& cloud = contents->cloud;
  Check(cloud.intensities.empty() || cloud.intensities.size() == cloud.points.size());
  for (const Eigen::Vector3f& p : cloud.points) Check(p.allFinite());
  if (contents->has_faces) {
    Check(contents->mesh.vertices.size() == cloud.points.size());
    for (const Eigen::Vector3i& t : contents->mesh.triangles) {
      Check((t.array() >= 0).all() && (t.array() < static_cast<int>(cloud.size())).all());
    }
  } else {
    Check(contents->mesh.vertices.empty() && contents->mesh.triangles.empty());
  }
  absl::StatusOr<std::string> written = rpsr::core::SerializePly(
      cloud, rpsr::core::PlyFormat::kBinaryBigEndian, rpsr::core::PlyCoordinateType::kFloat32);
  Check(written.ok());
  absl::StatusOr<PlyContents> reread = rpsr::core::ParsePly(*written, "rewritten.ply");
  // Intensities are stored as read, NaN included: compare their bits.
  Check(reread.ok() && reread->cloud.points == cloud.points &&
        std::equal(cloud.intensities.begin(), cloud.intensities.end(),
                   reread->cloud.intensities.begin(), reread->cloud.intensities.end(),
                   [](float a, float b) {
                     return std::bit_cast<uint32_t>(a) == std::bit_cast<uint32_t>(b);
                   }));
  return 0;
}
