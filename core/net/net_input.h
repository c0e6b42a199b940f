// What RPSRNet reads of one cloud, prepared from its Barnes-Hut tree without LibTorch.
//
// Choices (the paper is silent on them; reasons given here, measured in the eval tables):
// - Both clouds of a pair are binned in the SAME cube, the target's. The target's cached tree is
//   used as it is; the source's deepest cached nodes (centres of mass weighted by their counts)
//   are moved by the current estimate and re-binned into the target's cube at every pass (the
//   paper's Sec. 3.3 "re-encoding"). Shared cells make the depth-2 tokens of the two clouds
//   describe the same regions of space, so token centres of mass converge as the alignment does,
//   and a target's encoding can be computed once per tree.
// - Position features per node (6): the centre of mass in the cube's unit frame, (mu - c) / r,
//   and its offset inside its own cell in cell half-lengths, (mu - cell centre) / cell half, which
//   is translation- and scale-free local shape.
// - Density feature per node (1): log(K * inverse_density) = log((1/n) / mean_l(1/n_l)) over the
//   K nodes of the depth: the paper's normalised inverse density made independent of K, so that
//   a 1,024-point object and a 120k-point scan give features of the same range.
#ifndef RPSR_CORE_NET_NET_INPUT_H_
#define RPSR_CORE_NET_NET_INPUT_H_

#include <array>
#include <cstdint>
#include <vector>

#include "Eigen/Core"
#include "Eigen/Geometry"
#include "absl/status/statusor.h"
#include "core/tree/bh_tree.h"

namespace rpsr::core {

// Depths the network reads: tree convolutions at 5, 4, 3 and the Tree-to-Voxel tokens at 2.
inline constexpr int kNetTokenDepth = 2;
inline constexpr int kNetLeafDepth = 5;
inline constexpr int kNetDepths = kNetLeafDepth - kNetTokenDepth + 1;  // 2, 3, 4, 5
inline constexpr int kNetTokens = 64;                                  // 4^3 cells at depth 2
inline constexpr int kNetPositionFeatures = 6;
inline constexpr int kNetDensityFeatures = 1;

struct NetDepthInput {
  int num_nodes = 0;
  std::vector<float> position;       // num_nodes x kNetPositionFeatures
  std::vector<float> density;        // num_nodes x kNetDensityFeatures
  std::vector<int32_t> neighbors;    // num_nodes x 27, -1 = empty (depths 3..5 only)
  std::vector<int32_t> child_slots;  // num_nodes x 8: children at depth + 1, -1 = empty
};

struct NetCloudInput {
  std::array<NetDepthInput, kNetDepths> depths;  // [0] = depth 2 ... [3] = depth 5
  std::array<int32_t, kNetTokens> token_node;    // node of depth 2 per token slot, -1 = empty
  std::array<float, kNetTokens * 3>
      token_com;                               // centre of mass per token (frame below), 0 if empty
  std::array<float, kNetTokens> token_weight;  // fraction of the cloud's points in the token
  Eigen::Vector3d cube_center = Eigen::Vector3d::Zero();
  double cube_half_length = 1.0;
};

// The input of a tree as it is (the target's). Requires tree.max_depth() >= 5 and
// tree.neighbor_max_depth() >= 5 (the defaults); FailedPrecondition otherwise.
absl::StatusOr<NetCloudInput> MakeNetInput(const Octree& tree);

// The input of `source` moved by T (p -> T p) and re-binned into `cube_of`'s cube, from the
// source's nodes at depth min(max_depth, 7) weighted by their counts. Token centres of mass are
// in the moved frame (the target's frame for T = current estimate of T_target_source).
absl::StatusOr<NetCloudInput> MakeMovedNetInput(const Octree& source, const Eigen::Isometry3d& T,
                                                const Octree& cube_of);

// A cropped cube for both clouds of a pair (RpsrNetConfig::cube_half_length > 0): centred on the
// target's centre of mass, which on a LiDAR scan lies near the sensor because the points are
// densest there, with a fixed half-length in the clouds' units. Why: a scan's own cube is ~240 m
// wide, its 64 depth-2 tokens are 60 m cells and a street fills one or two layers of them, too
// coarse for motions of a few metres; a 40 m half-length gives 20 m tokens and 2.5 m cells at
// depth 5, and drops the sparse far points.
struct NetCube {
  Eigen::Vector3d center = Eigen::Vector3d::Zero();
  double half_length = 1.0;
};
NetCube CroppedNetCube(const Octree& target, double half_length);

// `cloud` moved by T, from its nodes at depth min(max_depth, 7) weighted by their counts, keeping
// only those inside `cube`, re-binned into it. FailedPrecondition when none is inside.
absl::StatusOr<NetCloudInput> MakeCroppedNetInput(const Octree& cloud, const Eigen::Isometry3d& T,
                                                  const NetCube& cube);

}  // namespace rpsr::core

#endif  // RPSR_CORE_NET_NET_INPUT_H_
