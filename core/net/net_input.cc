#include "core/net/net_input.h"

#include <algorithm>
#include <cmath>

#include "absl/strings/str_cat.h"

namespace rpsr::core {
namespace {

// Deepest cached level used as weighted points when re-binning a moved source: depth 7 keeps
// ~1 cm cells on objects and ~2 m on LiDAR scans, far below the network's depth 5.
constexpr int kMovedSourceDepth = 7;

void FillDepth(const Octree& tree, int depth, NetDepthInput& out) {
  const Octree::Level& level = tree.level(depth);
  const int n = static_cast<int>(level.size());
  out.num_nodes = n;
  out.position.resize(static_cast<size_t>(n) * kNetPositionFeatures);
  out.density.resize(static_cast<size_t>(n) * kNetDensityFeatures);
  const Eigen::Vector3d center = tree.center();
  const double r = tree.half_length();
  const double cell_half = r / static_cast<double>(1 << depth);
  double mean_inverse_count = 0.0;
  for (int i = 0; i < n; ++i) mean_inverse_count += 1.0 / level.count[i];
  mean_inverse_count /= std::max(n, 1);
  for (int i = 0; i < n; ++i) {
    const Eigen::Vector3d mu = level.center_of_mass[i].cast<double>();
    const Eigen::AlignedBox3f bounds = tree.CellBounds(depth, i);
    const Eigen::Vector3d cell_center = bounds.center().cast<double>();
    float* p = &out.position[static_cast<size_t>(i) * kNetPositionFeatures];
    for (int a = 0; a < 3; ++a) {
      p[a] = static_cast<float>((mu[a] - center[a]) / r);
      // Clamped: a point binned into a border cell from outside the cube lies outside its cell.
      p[3 + a] = static_cast<float>(std::clamp((mu[a] - cell_center[a]) / cell_half, -2.0, 2.0));
    }
    out.density[i] = static_cast<float>(std::log((1.0 / level.count[i]) / mean_inverse_count));
  }
  if (depth >= kNetTokenDepth + 1) {
    out.neighbors = level.neighbors;
  } else {
    out.neighbors.clear();
  }
  if (depth < kNetLeafDepth) {
    out.child_slots = tree.level(depth + 1).labels;
  } else {
    out.child_slots.clear();
  }
}

}  // namespace

absl::StatusOr<NetCloudInput> MakeNetInput(const Octree& tree) {
  if (tree.max_depth() < kNetLeafDepth || tree.neighbor_max_depth() < kNetLeafDepth) {
    return absl::FailedPreconditionError(
        absl::StrCat("the network needs trees of depth >= ", kNetLeafDepth,
                     " with neighbour tables to depth ", kNetLeafDepth, "; this tree has depth ",
                     tree.max_depth(), " and neighbour depth ", tree.neighbor_max_depth()));
  }
  NetCloudInput input;
  for (int d = kNetTokenDepth; d <= kNetLeafDepth; ++d) {
    FillDepth(tree, d, input.depths[d - kNetTokenDepth]);
  }
  const std::vector<int32_t> view = tree.DenseView(kNetTokenDepth);
  const Octree::Level& tokens = tree.level(kNetTokenDepth);
  input.token_com.fill(0.0f);
  input.token_weight.fill(0.0f);
  for (int slot = 0; slot < kNetTokens; ++slot) {
    const int32_t node = view[slot];
    input.token_node[slot] = node;
    if (node < 0) continue;
    for (int a = 0; a < 3; ++a) input.token_com[slot * 3 + a] = tokens.center_of_mass[node][a];
    input.token_weight[slot] =
        static_cast<float>(tokens.count[node]) / static_cast<float>(tree.num_points());
  }
  input.cube_center = tree.center();
  input.cube_half_length = tree.half_length();
  return input;
}

namespace {

// The nodes of `cloud` at depth min(max_depth, 7), moved by T and (when `crop`) kept only inside
// the cube, re-binned into the cube as weighted points.
absl::StatusOr<NetCloudInput> Rebinned(const Octree& cloud, const Eigen::Isometry3d& T,
                                       const Eigen::Vector3d& center, double half_length,
                                       bool crop) {
  const Octree::Level& level = cloud.level(std::min(cloud.max_depth(), kMovedSourceDepth));
  std::vector<Eigen::Vector3f> moved;
  std::vector<uint32_t> kept_counts;  // only when cropping; otherwise the level's own counts
  moved.reserve(level.size());
  const Eigen::Isometry3f Tf = T.cast<float>();
  const Eigen::Vector3f c = center.cast<float>();
  // Strictly inside, so that no kept point is clamped into a border cell.
  const float limit = static_cast<float>(half_length * (1.0 - 1e-6));
  for (size_t i = 0; i < level.size(); ++i) {
    const Eigen::Vector3f p = Tf * level.center_of_mass[i];
    if (crop && (p - c).cwiseAbs().maxCoeff() >= limit) continue;
    moved.push_back(p);
    if (crop) kept_counts.push_back(level.count[i]);
  }
  if (moved.empty()) {
    return absl::FailedPreconditionError(
        crop ? absl::StrCat("no point of the cloud lies within the network's cube (half-length ",
                            half_length, " around the target's centre of mass)")
             : std::string("the cloud's tree holds no nodes"));
  }
  BarnesHutTreeOptions options;
  options.max_depth = kNetLeafDepth;
  options.neighbor_max_depth = kNetLeafDepth;
  options.cube_center = {center.x(), center.y(), center.z()};
  options.cube_half_length = half_length;
  absl::StatusOr<Octree> rebinned = BuildWeightedBarnesHutTree<3>(
      absl::MakeConstSpan(moved), crop ? kept_counts : level.count, options);
  if (!rebinned.ok()) return rebinned.status();
  return MakeNetInput(*rebinned);
}

}  // namespace

absl::StatusOr<NetCloudInput> MakeMovedNetInput(const Octree& source, const Eigen::Isometry3d& T,
                                                const Octree& cube_of) {
  return Rebinned(source, T, cube_of.center(), cube_of.half_length(), /*crop=*/false);
}

NetCube CroppedNetCube(const Octree& target, double half_length) {
  NetCube cube;
  cube.center = target.level(0).center_of_mass[0].cast<double>();
  cube.half_length = half_length;
  return cube;
}

absl::StatusOr<NetCloudInput> MakeCroppedNetInput(const Octree& cloud, const Eigen::Isometry3d& T,
                                                  const NetCube& cube) {
  return Rebinned(cloud, T, cube.center, cube.half_length, /*crop=*/true);
}

}  // namespace rpsr::core
