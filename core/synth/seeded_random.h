// The one random-number source of core/synth and core/data: a seeded std::mt19937_64 with our own
// mappings to uniform and normal variates. std:: distributions are implementation-defined
// (libstdc++ and libc++ give different numbers for the same engine state), so every generator and
// pair protocol draws through this class; the same seed then gives the same objects, poses and
// disturbances on every standard library. Normal variates use Box-Muller through std::log,
// std::sqrt and std::cos: identical wherever the C math library rounds them identically (glibc on
// x86-64 and aarch64 does); the integer and uniform streams are bit-exact everywhere.
#ifndef RPSR_CORE_SYNTH_SEEDED_RANDOM_H_
#define RPSR_CORE_SYNTH_SEEDED_RANDOM_H_

#include <cstddef>
#include <cstdint>
#include <random>
#include <vector>

#include "Eigen/Core"

namespace rpsr::core {

// Mixes `seed` and `stream` into a new, well-spread seed (SplitMix64 finaliser). Lets one
// user-facing seed feed several independent streams (shape, pose, sampling, disturbance), so that
// changing how many numbers one stage draws never shifts the numbers of another.
uint64_t DeriveSeed(uint64_t seed, uint64_t stream);

class SeededRandom {
 public:
  explicit SeededRandom(uint64_t seed) : engine_(seed) {}

  // 64 raw bits from the engine.
  uint64_t NextBits() { return engine_(); }

  // Uniform in [0, 1), 53 random bits.
  double UniformUnit() { return static_cast<double>(engine_() >> 11) * (1.0 / 9007199254740992.0); }

  // Uniform in [low, high).
  double Uniform(double low, double high) { return low + (high - low) * UniformUnit(); }

  // Uniform integer in [0, count); count must be positive. Uses rejection, so no modulo bias.
  uint64_t UniformIndex(uint64_t count);

  // Uniform integer in [low, high] (both inclusive).
  int UniformInt(int low, int high) {
    return low + static_cast<int>(UniformIndex(static_cast<uint64_t>(high - low) + 1));
  }

  // True with probability `p`.
  bool Bernoulli(double p) { return UniformUnit() < p; }

  // Normal variate N(mean, sigma^2) (Box-Muller; the second variate of each pair is kept for the
  // next call).
  double Normal(double mean, double sigma);

  // Uniformly distributed unit vector (normalised 3D standard normal).
  Eigen::Vector3d UnitVector();

  // `count` distinct indices drawn uniformly from [0, size), in draw order (partial Fisher-Yates);
  // count must not exceed size.
  std::vector<size_t> DistinctIndices(size_t size, size_t count);

 private:
  std::mt19937_64 engine_;
  bool has_spare_normal_ = false;
  double spare_normal_ = 0.0;
};

}  // namespace rpsr::core

#endif  // RPSR_CORE_SYNTH_SEEDED_RANDOM_H_
