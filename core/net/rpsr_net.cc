#include "core/net/rpsr_net.h"

#include <malloc.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <mutex>

#include "absl/strings/numbers.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "absl/strings/str_split.h"
#include "core/io/file_bytes.h"
#include "core/net/rpsr_net_impl.h"
#include "core/net/weights_file.h"

namespace rpsr::core {
namespace net {

std::string ConfigToText(const RpsrNetConfig& c) {
  return absl::StrCat(
      "conv_widths=", c.conv_widths[0], ",", c.conv_widths[1], ",", c.conv_widths[2],
      "\nembedding_width=", c.embedding_width, "\nattention_heads=", c.attention_heads,
      "\nfeedforward_width=", c.feedforward_width, "\npasses=", c.passes,
      // %.17g: the value survives the text round trip exactly (resuming compares it). Written
      // whenever not 0 (the default, left out so that older files stay as they were), so that
      // ConfigFromText rejects a negative or NaN value on its way through Create.
      c.cube_half_length != 0.0 ? absl::StrFormat("\ncube_half_length=%.17g", c.cube_half_length)
                                : "",
      "\n");
}

absl::StatusOr<RpsrNetConfig> ConfigFromText(absl::string_view text) {
  RpsrNetConfig c;
  for (absl::string_view line : absl::StrSplit(text, '\n', absl::SkipEmpty())) {
    std::pair<absl::string_view, absl::string_view> kv = absl::StrSplit(line, '=');
    auto parse = [&](int& out) -> absl::Status {
      if (!absl::SimpleAtoi(kv.second, &out) || out <= 0) {
        return absl::InvalidArgumentError(absl::StrCat("bad network config line '", line, "'"));
      }
      return absl::OkStatus();
    };
    absl::Status s;
    if (kv.first == "conv_widths") {
      std::vector<absl::string_view> parts = absl::StrSplit(kv.second, ',');
      if (parts.size() != 3) return absl::InvalidArgumentError("conv_widths needs 3 values");
      for (int i = 0; i < 3; ++i) {
        if (!absl::SimpleAtoi(parts[i], &c.conv_widths[i]) || c.conv_widths[i] <= 0) {
          return absl::InvalidArgumentError(absl::StrCat("bad conv_widths '", kv.second, "'"));
        }
      }
    } else if (kv.first == "embedding_width") {
      s = parse(c.embedding_width);
    } else if (kv.first == "attention_heads") {
      s = parse(c.attention_heads);
    } else if (kv.first == "feedforward_width") {
      s = parse(c.feedforward_width);
    } else if (kv.first == "passes") {
      s = parse(c.passes);
    } else if (kv.first == "cube_half_length") {
      if (!absl::SimpleAtod(kv.second, &c.cube_half_length) || !(c.cube_half_length > 0) ||
          !std::isfinite(c.cube_half_length)) {
        return absl::InvalidArgumentError(absl::StrCat("bad network config line '", line, "'"));
      }
    }  // Unknown keys are ignored: newer files may carry more.
    if (!s.ok()) return s;
  }
  if (c.embedding_width % c.attention_heads != 0) {
    return absl::InvalidArgumentError(absl::StrCat("embedding_width ", c.embedding_width,
                                                   " is not a multiple of attention_heads ",
                                                   c.attention_heads));
  }
  return c;
}

absl::StatusOr<PackedClouds> PackTargets(absl::Span<const NetPair> pairs, double cube_half_length) {
  std::vector<NetCloudInput> inputs;
  inputs.reserve(pairs.size());
  for (size_t b = 0; b < pairs.size(); ++b) {
    if (pairs[b].source == nullptr || pairs[b].target == nullptr) {
      return absl::InvalidArgumentError(absl::StrCat("pair ", b, " lacks a source or target tree"));
    }
    absl::StatusOr<NetCloudInput> input =
        cube_half_length > 0
            ? MakeCroppedNetInput(*pairs[b].target, Eigen::Isometry3d::Identity(),
                                  CroppedNetCube(*pairs[b].target, cube_half_length))
            : MakeNetInput(*pairs[b].target);
    if (!input.ok()) return input.status();
    inputs.push_back(*std::move(input));
  }
  std::vector<const NetCloudInput*> pointers;
  for (const NetCloudInput& in : inputs) pointers.push_back(&in);
  return PackClouds(pointers);
}

absl::StatusOr<PackedClouds> PackMovedSources(absl::Span<const NetPair> pairs,
                                              const std::vector<Eigen::Isometry3d>& estimates,
                                              double cube_half_length) {
  std::vector<NetCloudInput> inputs;
  inputs.reserve(pairs.size());
  for (size_t b = 0; b < pairs.size(); ++b) {
    absl::StatusOr<NetCloudInput> input =
        cube_half_length > 0
            ? MakeCroppedNetInput(*pairs[b].source, estimates[b],
                                  CroppedNetCube(*pairs[b].target, cube_half_length))
            : MakeMovedNetInput(*pairs[b].source, estimates[b], *pairs[b].target);
    if (!input.ok()) return input.status();
    inputs.push_back(*std::move(input));
  }
  std::vector<const NetCloudInput*> pointers;
  for (const NetCloudInput& in : inputs) pointers.push_back(&in);
  return PackClouds(pointers);
}

std::vector<Eigen::Isometry3d> ToIsometries(const torch::Tensor& rotation,
                                            const torch::Tensor& translation) {
  torch::Tensor R = rotation.detach().to(torch::kCPU, torch::kFloat64).contiguous();
  torch::Tensor t = translation.detach().to(torch::kCPU, torch::kFloat64).contiguous();
  std::vector<Eigen::Isometry3d> out(R.size(0), Eigen::Isometry3d::Identity());
  for (int64_t b = 0; b < R.size(0); ++b) {
    out[b].linear() = Eigen::Map<const Eigen::Matrix<double, 3, 3, Eigen::RowMajor>>(
        R.data_ptr<double>() + b * 9);
    out[b].translation() = Eigen::Map<const Eigen::Vector3d>(t.data_ptr<double>() + b * 3);
  }
  return out;
}

}  // namespace net

void SetNetThreads(int threads) { torch::set_num_threads(std::max(threads, 1)); }

namespace {
// A batched forward pass allocates and frees tensors of tens of MB (the gathered 27-neighbour
// matrices of 16 objects). Above glibc's dynamic mmap threshold each is a fresh mmap whose pages
// fault in and are zeroed again on every call: at batch 16 that cost ~30% of the pass here
// (rpsr_net_bench, 487 -> 345 ms of CPU). Keeping such blocks in the heap makes batching pay
// instead of cost. Process-wide, so done once, when the first network is made.
void KeepLargeBuffersInHeap() {
  static std::once_flag once;
  std::call_once(once, [] {
    mallopt(M_MMAP_THRESHOLD, 256 << 20);
    mallopt(M_TRIM_THRESHOLD, 1 << 30);
  });
}
}  // namespace

RpsrNet::RpsrNet(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) { KeepLargeBuffersInHeap(); }
RpsrNet::~RpsrNet() = default;

absl::StatusOr<std::unique_ptr<RpsrNet>> RpsrNet::Create(const RpsrNetConfig& config,
                                                         uint64_t seed) {
  absl::StatusOr<RpsrNetConfig> checked = net::ConfigFromText(net::ConfigToText(config));
  if (!checked.ok()) return checked.status();
  try {
    torch::manual_seed(seed);
    auto impl = std::make_unique<Impl>();
    impl->config = *checked;
    impl->network = net::RpsrNetwork(*checked);
    impl->network->eval();
    return std::unique_ptr<RpsrNet>(new RpsrNet(std::move(impl)));
  } catch (const c10::Error& e) {
    return absl::InternalError(
        absl::StrCat("creating the network failed: ", e.what_without_backtrace()));
  }
}

absl::StatusOr<std::unique_ptr<RpsrNet>> RpsrNet::LoadFromBytes(absl::string_view bytes,
                                                                absl::string_view name) {
  try {
    absl::StatusOr<net::NamedTensors> weights = net::ParseWeights(bytes, name);
    if (!weights.ok()) return weights.status();
    absl::StatusOr<RpsrNetConfig> config = net::ConfigFromText(weights->config_text);
    if (!config.ok()) {
      return absl::InvalidArgumentError(absl::StrCat(name, ": ", config.status().message()));
    }
    absl::StatusOr<std::unique_ptr<RpsrNet>> net = Create(*config, 0);
    if (!net.ok()) return net.status();
    if (absl::Status s = net::LoadTensorsInto(*weights, *(*net)->impl_->network); !s.ok()) {
      return absl::InvalidArgumentError(absl::StrCat(name, ": ", s.message()));
    }
    return net;
  } catch (const c10::Error& e) {
    return absl::InternalError(
        absl::StrCat(name, ": loading failed: ", e.what_without_backtrace()));
  }
}

absl::StatusOr<std::unique_ptr<RpsrNet>> RpsrNet::Load(const std::string& path) {
  absl::StatusOr<std::string> bytes = ReadFileBytes(path, size_t{1} << 30);
  if (!bytes.ok()) return bytes.status();
  return LoadFromBytes(*bytes, path);
}

absl::Status RpsrNet::Save(const std::string& path) const {
  try {
    return WriteFileBytes(path, net::SerializeWeights(net::CollectTensors(
                                    *impl_->network, net::ConfigToText(impl_->config))));
  } catch (const c10::Error& e) {
    return absl::InternalError(absl::StrCat(path, ": saving failed: ", e.what_without_backtrace()));
  }
}

const RpsrNetConfig& RpsrNet::config() const { return impl_->config; }

int64_t RpsrNet::NumParameters() const {
  int64_t n = 0;
  for (const torch::Tensor& p : impl_->network->parameters()) n += p.numel();
  return n;
}

absl::StatusOr<std::shared_ptr<const NetTargetEncoding>> RpsrNet::EncodeTarget(
    const Octree& target) const {
  try {
    torch::InferenceMode inference;
    const NetPair pair{&target, &target};
    absl::StatusOr<net::PackedClouds> packed =
        net::PackTargets(absl::MakeConstSpan(&pair, 1), impl_->config.cube_half_length);
    if (!packed.ok()) return packed.status();
    const net::PackedClouds on_device = packed->To(impl_->device);
    auto encoding = std::make_shared<NetTargetEncoding>();
    encoding->owner = impl_.get();
    encoding->tree = &target;
    encoding->token_com = on_device.token_com;
    encoding->token_empty = on_device.token_empty;
    encoding->encoded = impl_->network->EncodeTarget(on_device);
    return std::shared_ptr<const NetTargetEncoding>(std::move(encoding));
  } catch (const c10::Error& e) {
    return absl::InternalError(
        absl::StrCat("network target encoding failed: ", e.what_without_backtrace()));
  }
}

size_t RpsrNet::EncodingBytes(const NetTargetEncoding& encoding) {
  size_t bytes = sizeof(NetTargetEncoding);
  for (const torch::Tensor* t :
       {&encoding.token_com, &encoding.token_empty, &encoding.encoded.embedding,
        &encoding.encoded.memory, &encoding.encoded.self_attended}) {
    if (t->defined()) bytes += static_cast<size_t>(t->nbytes());
  }
  return bytes;
}

namespace {

// What every pair of a batch must be: both trees given, and a given target encoding made by this
// network from this target.
absl::Status ValidatePairs(const RpsrNet::Impl& impl, absl::Span<const NetPair> pairs) {
  for (size_t b = 0; b < pairs.size(); ++b) {
    if (pairs[b].source == nullptr || pairs[b].target == nullptr) {
      return absl::InvalidArgumentError(absl::StrCat("pair ", b, " lacks a source or target tree"));
    }
    const NetTargetEncoding* given = pairs[b].target_encoding;
    if (given != nullptr && (given->owner != &impl || given->tree != pairs[b].target)) {
      return absl::InvalidArgumentError(
          absl::StrCat("pair ", b, ": its target encoding was made ",
                       given->owner != &impl ? "by another network" : "from another tree"));
    }
  }
  return absl::OkStatus();
}

// The batch's target side: packed and encoded here for the pairs without a NetTargetEncoding,
// concatenated along the batch dimension with the given ones for the others, in pair order.
absl::Status TargetSide(RpsrNet::Impl& impl, absl::Span<const NetPair> pairs,
                        net::PackedClouds& target, net::EncodedTarget& encoded) {
  std::vector<NetPair> missing;
  std::vector<size_t> missing_index(pairs.size(), pairs.size());
  for (size_t b = 0; b < pairs.size(); ++b) {
    const NetTargetEncoding* given = pairs[b].target_encoding;
    if (given == nullptr) {
      missing_index[b] = missing.size();
      missing.push_back(pairs[b]);
    }
  }
  if (missing.size() == pairs.size()) {  // the common case: one batched encoding
    absl::StatusOr<net::PackedClouds> packed =
        net::PackTargets(pairs, impl.config.cube_half_length);
    if (!packed.ok()) return packed.status();
    target = packed->To(impl.device);
    encoded = impl.network->EncodeTarget(target);
    return absl::OkStatus();
  }
  net::PackedClouds fresh;
  net::EncodedTarget fresh_encoded;
  if (!missing.empty()) {
    absl::StatusOr<net::PackedClouds> packed =
        net::PackTargets(missing, impl.config.cube_half_length);
    if (!packed.ok()) return packed.status();
    fresh = packed->To(impl.device);
    fresh_encoded = impl.network->EncodeTarget(fresh);
  }
  std::vector<torch::Tensor> com, empty, embedding, memory, self_attended;
  for (size_t b = 0; b < pairs.size(); ++b) {
    if (const NetTargetEncoding* given = pairs[b].target_encoding) {
      com.push_back(given->token_com);
      empty.push_back(given->token_empty);
      embedding.push_back(given->encoded.embedding);
      memory.push_back(given->encoded.memory);
      self_attended.push_back(given->encoded.self_attended);
    } else {
      const int64_t m = static_cast<int64_t>(missing_index[b]);
      com.push_back(fresh.token_com.narrow(0, m, 1));
      empty.push_back(fresh.token_empty.narrow(0, m, 1));
      embedding.push_back(fresh_encoded.embedding.narrow(0, m, 1));
      memory.push_back(fresh_encoded.memory.narrow(1, m, 1));
      self_attended.push_back(fresh_encoded.self_attended.narrow(1, m, 1));
    }
  }
  // Pass reads only the target's tokens (centres of mass and emptiness) besides the encodings.
  target = net::PackedClouds{};
  target.batch = static_cast<int64_t>(pairs.size());
  target.token_com = torch::cat(com, 0);
  target.token_empty = torch::cat(empty, 0);
  encoded.embedding = torch::cat(embedding, 0);
  encoded.memory = torch::cat(memory, 1);
  encoded.self_attended = torch::cat(self_attended, 1);
  return absl::OkStatus();
}

}  // namespace

absl::StatusOr<std::vector<NetEstimate>> RpsrNet::Estimate(absl::Span<const NetPair> pairs,
                                                           int passes) const {
  if (pairs.empty()) return std::vector<NetEstimate>{};
  if (passes <= 0) passes = impl_->config.passes;
  if (absl::Status valid = ValidatePairs(*impl_, pairs); !valid.ok()) return valid;
  if (pairs.size() > 1 && impl_->device.is_cpu()) {
    // On CPU a batch is its pairs one at a time. Over a whole batch's rows, OpenBLAS's AVX2
    // kernels (Haswell, Zen) block a pair's rows otherwise than alone, so its scores changed in
    // their last bits with what shared its batch and an ill-conditioned SVD made degrees of it;
    // and a batch saved little here (1.1-1.3x: the network's time is arithmetic that grows with
    // the nodes). GPU builds keep whole batches.
    std::vector<NetEstimate> results;
    results.reserve(pairs.size());
    for (size_t b = 0; b < pairs.size(); ++b) {
      absl::StatusOr<std::vector<NetEstimate>> one = Estimate({&pairs[b], 1}, passes);
      if (!one.ok()) {
        return absl::Status(one.status().code(),
                            absl::StrCat("pair ", b, ": ", one.status().message()));
      }
      results.push_back(std::move(one->front()));
    }
    return results;
  }
  try {
    torch::InferenceMode inference;
    net::RpsrNetwork& network = impl_->network;
    net::PackedClouds target;
    net::EncodedTarget encoded_target;
    absl::Status target_side = TargetSide(*impl_, pairs, target, encoded_target);
    if (!target_side.ok()) return target_side;

    std::vector<NetEstimate> results(pairs.size());
    std::vector<Eigen::Isometry3d> estimates;
    for (const NetPair& pair : pairs) estimates.push_back(pair.initial);
    torch::Tensor scores;
    torch::Tensor source_empty;
    for (int pass = 0; pass < passes; ++pass) {
      absl::StatusOr<net::PackedClouds> sources =
          net::PackMovedSources(pairs, estimates, impl_->config.cube_half_length);
      if (!sources.ok()) return sources.status();
      const net::PackedClouds source = sources->To(impl_->device);
      net::PassOutput out = network->Pass(source, target, encoded_target);
      const std::vector<Eigen::Isometry3d> steps = net::ToIsometries(out.rotation, out.translation);
      for (size_t b = 0; b < pairs.size(); ++b) {
        estimates[b] = steps[b] * estimates[b];
        results[b].per_pass.push_back(estimates[b]);
      }
      scores = out.scores;
      source_empty = source.token_empty;
    }
    // Mean peak score over the non-empty source tokens of the last pass.
    torch::Tensor peak = std::get<0>(scores.max(-1)).to(torch::kCPU);
    torch::Tensor valid = (~source_empty).to(torch::kCPU).to(torch::kFloat32);
    torch::Tensor mean_peak = (peak * valid).sum(1) / valid.sum(1).clamp_min(1.0);
    for (size_t b = 0; b < pairs.size(); ++b) {
      results[b].T_target_source = estimates[b];
      results[b].score_peak = mean_peak[b].item<double>();
    }
    return results;
  } catch (const c10::Error& e) {
    return absl::InternalError(
        absl::StrCat("network forward pass failed: ", e.what_without_backtrace()));
  }
}

}  // namespace rpsr::core
