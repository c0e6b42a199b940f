#include "core/synth/seeded_random.h"

#include <cmath>
#include <numeric>
#include <utility>

namespace rpsr::core {

uint64_t DeriveSeed(uint64_t seed, uint64_t stream) {
  uint64_t z = seed + 0x9E3779B97F4A7C15ULL * (stream + 1);
  z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ULL;
  z = (z ^ (z >> 27)) * 0x94D049BB133111EBULL;
  return z ^ (z >> 31);
}

uint64_t SeededRandom::UniformIndex(uint64_t count) {
  if (count <= 1) return 0;
  // Reject the top partial block of the 64-bit range so every residue is equally likely.
  const uint64_t limit = UINT64_MAX - (UINT64_MAX % count);
  uint64_t bits = engine_();
  while (bits >= limit) bits = engine_();
  return bits % count;
}

double SeededRandom::Normal(double mean, double sigma) {
  if (has_spare_normal_) {
    has_spare_normal_ = false;
    return mean + sigma * spare_normal_;
  }
  // 1 - UniformUnit() is in (0, 1], so the logarithm is finite.
  const double u1 = 1.0 - UniformUnit();
  const double u2 = UniformUnit();
  const double radius = std::sqrt(-2.0 * std::log(u1));
  const double angle = 2.0 * M_PI * u2;
  spare_normal_ = radius * std::sin(angle);
  has_spare_normal_ = true;
  return mean + sigma * radius * std::cos(angle);
}

Eigen::Vector3d SeededRandom::UnitVector() {
  while (true) {
    const Eigen::Vector3d v(Normal(0, 1), Normal(0, 1), Normal(0, 1));
    const double norm = v.norm();
    if (norm > 1e-12) return v / norm;
  }
}

std::vector<size_t> SeededRandom::DistinctIndices(size_t size, size_t count) {
  std::vector<size_t> order(size);
  std::iota(order.begin(), order.end(), size_t{0});
  if (count > size) count = size;
  for (size_t i = 0; i < count; ++i) {
    const size_t j = i + static_cast<size_t>(UniformIndex(size - i));
    std::swap(order[i], order[j]);
  }
  order.resize(count);
  return order;
}

}  // namespace rpsr::core
