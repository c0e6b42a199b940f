// The portable weights file of RPSRNet (".rpsrw"), readable by any LibTorch version.
//
// Why not torch::save: its archive format changes between LibTorch releases, and a file written
// by a GPU machine's newer LibTorch may not load in Debian's 1.13. This format is plain:
//   bytes 0..7   magic "RPSRW001"
//   u32          length of the config text, then the text ("key=value" lines, see rpsr_net.h)
//   u32          number of tensors, then for each:
//                u32 name length, name (e.g. "encoder.position_branch.conv0.linear.weight"),
//                u8 dtype (0 = float32, 1 = int64), u32 rank, rank x i64 sizes,
//                the values, little-endian, row-major.
// Readers check every length against the bytes present.
#ifndef RPSR_CORE_NET_WEIGHTS_FILE_H_
#define RPSR_CORE_NET_WEIGHTS_FILE_H_

#include <torch/torch.h>

#include <string>
#include <utility>
#include <vector>

#include "absl/status/statusor.h"
#include "absl/strings/string_view.h"

namespace rpsr::core::net {

struct NamedTensors {
  std::string config_text;
  std::vector<std::pair<std::string, torch::Tensor>> tensors;
};

// Parameters and buffers of `module` (on any device), by their dotted names.
NamedTensors CollectTensors(const torch::nn::Module& module, std::string config_text);

std::string SerializeWeights(const NamedTensors& weights);
absl::StatusOr<NamedTensors> ParseWeights(absl::string_view bytes, absl::string_view name);

// Copies tensors into `module`'s parameters and buffers of the same names; every name of the
// module must be present with the same shape (InvalidArgument naming the first mismatch).
absl::Status LoadTensorsInto(const NamedTensors& weights, torch::nn::Module& module);

}  // namespace rpsr::core::net

#endif  // RPSR_CORE_NET_WEIGHTS_FILE_H_
