#include "core/net/weights_file.h"

#include <bit>
#include <cstring>
#include <map>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_join.h"

namespace rpsr::core::net {

static_assert(std::endian::native == std::endian::little,
              "the weights format is little-endian; a big-endian host needs byte swapping here");

namespace {

constexpr char kMagic[8] = {'R', 'P', 'S', 'R', 'W', '0', '0', '1'};
constexpr uint64_t kMaxElements = uint64_t{1} << 31;

template <typename T>
void Put(std::string& out, T value) {
  out.append(reinterpret_cast<const char*>(&value), sizeof(T));
}

class Reader {
 public:
  Reader(absl::string_view bytes, absl::string_view name) : bytes_(bytes), name_(name) {}

  template <typename T>
  absl::Status Get(T& value, absl::string_view what) {
    if (bytes_.size() - pos_ < sizeof(T)) return Truncated(what);
    std::memcpy(&value, bytes_.data() + pos_, sizeof(T));
    pos_ += sizeof(T);
    return absl::OkStatus();
  }
  absl::Status GetBytes(size_t n, absl::string_view what, absl::string_view& out) {
    if (bytes_.size() - pos_ < n) return Truncated(what);
    out = bytes_.substr(pos_, n);
    pos_ += n;
    return absl::OkStatus();
  }
  bool AtEnd() const { return pos_ == bytes_.size(); }
  size_t pos() const { return pos_; }

 private:
  absl::Status Truncated(absl::string_view what) const {
    return absl::InvalidArgumentError(absl::StrCat(name_, ": truncated at byte ", pos_,
                                                   " while reading ", what,
                                                   "; the weights file is incomplete"));
  }
  absl::string_view bytes_;
  absl::string_view name_;
  size_t pos_ = 0;
};

std::map<std::string, torch::Tensor> NamedSlots(torch::nn::Module& module) {
  std::map<std::string, torch::Tensor> slots;
  for (const auto& item : module.named_parameters(/*recurse=*/true))
    slots[item.key()] = item.value();
  for (const auto& item : module.named_buffers(/*recurse=*/true)) slots[item.key()] = item.value();
  return slots;
}

}  // namespace

NamedTensors CollectTensors(const torch::nn::Module& module, std::string config_text) {
  NamedTensors out;
  out.config_text = std::move(config_text);
  for (const auto& item : module.named_parameters(true)) {
    out.tensors.emplace_back(item.key(), item.value().detach().to(torch::kCPU).contiguous());
  }
  for (const auto& item : module.named_buffers(true)) {
    out.tensors.emplace_back(item.key(), item.value().detach().to(torch::kCPU).contiguous());
  }
  return out;
}

std::string SerializeWeights(const NamedTensors& weights) {
  std::string out(kMagic, sizeof(kMagic));
  Put<uint32_t>(out, static_cast<uint32_t>(weights.config_text.size()));
  out += weights.config_text;
  Put<uint32_t>(out, static_cast<uint32_t>(weights.tensors.size()));
  for (const auto& [name, tensor] : weights.tensors) {
    Put<uint32_t>(out, static_cast<uint32_t>(name.size()));
    out += name;
    const bool is_int = tensor.scalar_type() == torch::kInt64;
    torch::Tensor values = is_int ? tensor.contiguous() : tensor.to(torch::kFloat32).contiguous();
    Put<uint8_t>(out, is_int ? 1 : 0);
    Put<uint32_t>(out, static_cast<uint32_t>(values.dim()));
    for (int64_t s : values.sizes()) Put<int64_t>(out, s);
    out.append(static_cast<const char*>(values.data_ptr()), values.numel() * values.element_size());
  }
  return out;
}

absl::StatusOr<NamedTensors> ParseWeights(absl::string_view bytes, absl::string_view name) {
  Reader reader(bytes, name);
  absl::string_view magic;
  if (absl::Status s = reader.GetBytes(sizeof(kMagic), "the magic", magic); !s.ok()) return s;
  if (magic != absl::string_view(kMagic, sizeof(kMagic))) {
    return absl::InvalidArgumentError(
        absl::StrCat(name, ": not an rpsr weights file (expected magic RPSRW001)"));
  }
  NamedTensors out;
  uint32_t config_size = 0;
  absl::string_view config;
  if (absl::Status s = reader.Get(config_size, "the config length"); !s.ok()) return s;
  if (absl::Status s = reader.GetBytes(config_size, "the config", config); !s.ok()) return s;
  out.config_text = std::string(config);
  uint32_t count = 0;
  if (absl::Status s = reader.Get(count, "the tensor count"); !s.ok()) return s;
  for (uint32_t i = 0; i < count; ++i) {
    uint32_t name_size = 0;
    absl::string_view tensor_name;
    uint8_t dtype = 0;
    uint32_t rank = 0;
    if (absl::Status s = reader.Get(name_size, "a tensor name length"); !s.ok()) return s;
    if (absl::Status s = reader.GetBytes(name_size, "a tensor name", tensor_name); !s.ok())
      return s;
    if (absl::Status s = reader.Get(dtype, "a dtype"); !s.ok()) return s;
    if (absl::Status s = reader.Get(rank, "a rank"); !s.ok()) return s;
    if (dtype > 1 || rank > 8) {
      return absl::InvalidArgumentError(absl::StrCat(name, ": tensor '", tensor_name,
                                                     "' has dtype ", dtype, " and rank ", rank,
                                                     "; the file is corrupt"));
    }
    std::vector<int64_t> sizes(rank);
    uint64_t elements = 1;
    for (uint32_t r = 0; r < rank; ++r) {
      if (absl::Status s = reader.Get(sizes[r], "a tensor size"); !s.ok()) return s;
      if (sizes[r] < 0 || static_cast<uint64_t>(sizes[r]) > kMaxElements) {
        return absl::InvalidArgumentError(
            absl::StrCat(name, ": tensor '", tensor_name, "' has a bad size ", sizes[r]));
      }
      elements *= static_cast<uint64_t>(sizes[r]);
      if (elements > kMaxElements) {
        return absl::InvalidArgumentError(
            absl::StrCat(name, ": tensor '", tensor_name, "' is implausibly large"));
      }
    }
    const size_t element_size = dtype == 1 ? 8 : 4;
    absl::string_view data;
    if (absl::Status s = reader.GetBytes(elements * element_size,
                                         absl::StrCat("the values of '", tensor_name, "'"), data);
        !s.ok()) {
      return s;
    }
    torch::Tensor tensor = torch::empty(
        sizes, torch::TensorOptions().dtype(dtype == 1 ? torch::kInt64 : torch::kFloat32));
    std::memcpy(tensor.data_ptr(), data.data(), data.size());
    out.tensors.emplace_back(std::string(tensor_name), tensor);
  }
  if (!reader.AtEnd()) {
    return absl::InvalidArgumentError(absl::StrCat(name, ": ", bytes.size() - reader.pos(),
                                                   " unexpected bytes after the last tensor"));
  }
  return out;
}

absl::Status LoadTensorsInto(const NamedTensors& weights, torch::nn::Module& module) {
  std::map<std::string, const torch::Tensor*> given;
  for (const auto& [name, tensor] : weights.tensors) given[name] = &tensor;
  torch::NoGradGuard no_grad;
  for (auto& [name, slot] : NamedSlots(module)) {
    auto it = given.find(name);
    if (it == given.end()) {
      return absl::InvalidArgumentError(
          absl::StrCat("weights lack tensor '", name, "' that the network needs"));
    }
    if (it->second->sizes() != slot.sizes()) {
      return absl::InvalidArgumentError(absl::StrCat(
          "weights tensor '", name, "' has shape [", absl::StrJoin(it->second->sizes(), ","),
          "] but the network expects [", absl::StrJoin(slot.sizes(), ","), "]"));
    }
    slot.copy_(it->second->to(slot.device(), slot.scalar_type()));
  }
  return absl::OkStatus();
}

}  // namespace rpsr::core::net
