// RpsrNet's implementation state, shared by rpsr_net.cc and trainer.cc (private to core/net).
#ifndef RPSR_CORE_NET_RPSR_NET_IMPL_H_
#define RPSR_CORE_NET_RPSR_NET_IMPL_H_

#include <torch/torch.h>

#include <string>
#include <vector>

#include "absl/status/statusor.h"
#include "core/net/rpsr_modules.h"
#include "core/net/rpsr_net.h"

namespace rpsr::core {

struct RpsrNet::Impl {
  RpsrNetConfig config;
  net::RpsrNetwork network{nullptr};
  torch::Device device = torch::kCPU;
};

// What EncodeTarget keeps: one target's tokens and encodings, batch dimension 1.
class NetTargetEncoding {
 public:
  const RpsrNet::Impl* owner = nullptr;  // the network that made it
  const Octree* tree = nullptr;          // the tree it was made from
  torch::Tensor token_com;               // [1, T, 3]
  torch::Tensor token_empty;             // [1, T]
  net::EncodedTarget encoded;            // embedding [1, T, E], memory and self_attended [T, 1, E]
};

namespace net {

std::string ConfigToText(const RpsrNetConfig& config);
absl::StatusOr<RpsrNetConfig> ConfigFromText(absl::string_view text);

// The network's inputs of a batch of pairs for one pass: the targets (fixed over passes) and
// the sources moved by `estimates` and re-binned into their targets' cubes (cropped cubes when
// cube_half_length > 0, RpsrNetConfig::cube_half_length).
absl::StatusOr<PackedClouds> PackTargets(absl::Span<const NetPair> pairs, double cube_half_length);
absl::StatusOr<PackedClouds> PackMovedSources(absl::Span<const NetPair> pairs,
                                              const std::vector<Eigen::Isometry3d>& estimates,
                                              double cube_half_length);

// [B, 3, 3] and [B, 3] tensors -> isometries (double).
std::vector<Eigen::Isometry3d> ToIsometries(const torch::Tensor& rotation,
                                            const torch::Tensor& translation);

}  // namespace net
}  // namespace rpsr::core

#endif  // RPSR_CORE_NET_RPSR_NET_IMPL_H_
