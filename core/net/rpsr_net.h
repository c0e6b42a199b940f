// RPSRNet (paper Sec. 3): from the Barnes-Hut trees of a source and a target cloud to the rigid
// motion T_target_source, over several passes. LibTorch stays behind this header (pimpl).
//
// Architecture and the choices the paper leaves open (details in rpsr_modules.h, net_input.h):
// - HFE: position (HPFE) and density (HDFE) branches of tree convolutions at depths 5, 4, 3 with
//   widths conv_widths (the paper's Eq. 4 gives 2^(10-d): 32, 64, 128) and max-pooling to
//   parents; Hadamard fusion at depth 2; Tree-to-Voxel (64 tokens, empty ones zero and masked);
//   a linear layer to `embedding_width`.
// - DCP-v2 Transformer (one encoder and one decoder block, shared both ways, pre-norm); scores
//   softmax(F_src F_tgt^T / sqrt(E)) over non-empty target tokens; soft correspondences =
//   scores x target token centres of mass; weighted Procrustes with weights = the source
//   tokens' point fractions.
// - Passes: pass k moves the source by the estimate so far, re-bins it into the target's cube
//   and estimates the remaining motion; the estimates compose. Between passes the estimate is
//   treated as a constant (no gradient through the re-binning, which is discrete).
// - embedding_width defaults to 128, not the paper's 512: on one CPU core the Transformer's cost
//   grows with E^2 and 512 alone costs ~25 ms a pass (DEPS.md); the eval tables report the trade.
#ifndef RPSR_CORE_NET_RPSR_NET_H_
#define RPSR_CORE_NET_RPSR_NET_H_

#include <array>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "Eigen/Geometry"
#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "absl/types/span.h"
#include "core/tree/bh_tree.h"

namespace rpsr::core {

struct RpsrNetConfig {
  std::array<int, 3> conv_widths = {32, 64, 128};  // tree convolutions at depths 5, 4, 3
  int embedding_width = 128;                       // E, token width after Tree-to-Voxel
  int attention_heads = 4;
  int feedforward_width = 256;
  int passes = 3;  // default number of passes at inference
  // 0: each pair is binned in its target tree's own cube. > 0: in a cube of this half-length (the
  // clouds' units) around the target's centre of mass, points outside dropped (net_input.h:
  // CroppedNetCube; meant for scene-scale clouds).
  double cube_half_length = 0.0;
};

// A target's part of the network's work, computed once (RpsrNet::EncodeTarget) and reused by
// every Estimate against that target: its tree convolutions, its tokens, and the Transformer
// steps that read only the target. With net+refine's two passes that is about a third of an
// object pair's network time, which a client registering many sources against one reference
// (a model scan, a map) pays once. Opaque (LibTorch stays inside core/net), immutable, safe to
// share across threads; valid only with the RpsrNet that made it and for the tree it was made
// from (Estimate checks both).
class NetTargetEncoding;

// One pair to register. Trees must have depth >= 5 with neighbour tables to depth 5 (the
// BarnesHutTreeOptions defaults). `initial` is a starting guess of T_target_source.
// `target_encoding` (optional): EncodeTarget(*target) of the same network.
struct NetPair {
  const Octree* source = nullptr;
  const Octree* target = nullptr;
  Eigen::Isometry3d initial = Eigen::Isometry3d::Identity();
  const NetTargetEncoding* target_encoding = nullptr;
};

struct NetEstimate {
  Eigen::Isometry3d T_target_source = Eigen::Isometry3d::Identity();
  std::vector<Eigen::Isometry3d> per_pass;  // the estimate after each pass
  // Mean over source tokens of the largest score (how peaked the soft correspondences are), of
  // the last pass: an input for the confidence model, not a probability itself.
  double score_peak = 0.0;
};

class RpsrNet {
 public:
  // A network with freshly initialised weights (seeded), for training.
  static absl::StatusOr<std::unique_ptr<RpsrNet>> Create(const RpsrNetConfig& config,
                                                         uint64_t seed);
  // Loads weights written by Save (any LibTorch version: see weights_file.h).
  static absl::StatusOr<std::unique_ptr<RpsrNet>> Load(const std::string& path);
  static absl::StatusOr<std::unique_ptr<RpsrNet>> LoadFromBytes(absl::string_view bytes,
                                                                absl::string_view name);

  ~RpsrNet();
  RpsrNet(const RpsrNet&) = delete;
  RpsrNet& operator=(const RpsrNet&) = delete;

  absl::Status Save(const std::string& path) const;
  const RpsrNetConfig& config() const;
  // Number of trainable scalars.
  int64_t NumParameters() const;

  // Registers every pair (inference mode, thread-safe): on a GPU in one batched forward pass per
  // pass, on CPU one pair at a time, since CPU BLAS kernels may block a batch's rows otherwise
  // than one pair's. passes <= 0 uses config().passes. Results equal those of the pairs one at a
  // time, bit for bit on CPU.
  absl::StatusOr<std::vector<NetEstimate>> Estimate(absl::Span<const NetPair> pairs,
                                                    int passes = 0) const;

  // The target's part of Estimate, for reuse across calls (see NetTargetEncoding). Estimates
  // with it equal those without (the same operators on the same rows; the tests compare them).
  absl::StatusOr<std::shared_ptr<const NetTargetEncoding>> EncodeTarget(const Octree& target) const;
  // Memory an encoding holds (its tensors), for a caller's budget.
  static size_t EncodingBytes(const NetTargetEncoding& encoding);

  // For the trainer (core/net/trainer.cc), which lives beside the implementation.
  struct Impl;
  Impl& impl() { return *impl_; }

 private:
  explicit RpsrNet(std::unique_ptr<Impl> impl);
  std::unique_ptr<Impl> impl_;
};

// Sets LibTorch's intra-op threads for the process (DEPS.md: the default was 1 here; prefer one
// thread per worker and OMP_WAIT_POLICY=PASSIVE when other threads are busy).
void SetNetThreads(int threads);

}  // namespace rpsr::core

#endif  // RPSR_CORE_NET_RPSR_NET_H_
