#include "core/data/training_pairs.h"

#include <map>
#include <memory>
#include <mutex>

#include "absl/strings/str_cat.h"
#include "core/data/semantic_labels.h"
#include "core/synth/lidar_sequence.h"

namespace rpsr::core {
namespace {

// SplitMix64: decorrelates (stream, index) into a seed.
uint64_t MixSeed(uint64_t stream, uint64_t index) {
  uint64_t z = stream * 0x9e3779b97f4a7c15ull + index + 0x632be59bd9b4e5ull;
  z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ull;
  z = (z ^ (z >> 27)) * 0x94d049bb133111ebull;
  return z ^ (z >> 31);
}

double UnitFromSeed(uint64_t seed) { return (MixSeed(seed, 7) >> 11) * (1.0 / 9007199254740992.0); }

// Simulated sequences are costly to set up (scene generation and indexing); a few are kept.
class SequenceCache {
 public:
  absl::StatusOr<std::shared_ptr<const LidarSequenceSimulator>> Get(const LidarSequenceOptions& o) {
    std::lock_guard<std::mutex> lock(mutex_);
    auto it = cache_.find(o.seed);
    if (it != cache_.end()) return it->second;
    absl::StatusOr<LidarSequenceSimulator> simulator = LidarSequenceSimulator::Create(o);
    if (!simulator.ok()) return simulator.status();
    if (cache_.size() >= kCapacity) cache_.erase(cache_.begin());
    auto shared = std::make_shared<const LidarSequenceSimulator>(*std::move(simulator));
    cache_[o.seed] = shared;
    return shared;
  }

 private:
  static constexpr size_t kCapacity = 8;
  std::mutex mutex_;
  std::map<uint64_t, std::shared_ptr<const LidarSequenceSimulator>> cache_;
};

absl::StatusOr<PointCloud> WithoutGround(const LidarScan& scan) {
  std::vector<uint32_t> labels(scan.labels.begin(), scan.labels.end());
  return RemoveGroundPoints(scan.cloud, labels, "simulated labels");
}

}  // namespace

RegistrationPairGenerator MakeObjectPairStream(const ObjectStreamOptions& options) {
  return [options](uint64_t index) -> absl::StatusOr<RegistrationPair> {
    const uint64_t seed = MixSeed(options.stream_seed, index);
    PairOptions pair_options = options.pair;
    pair_options.random_disturbance = UnitFromSeed(seed) < options.disturbed_fraction;
    pair_options.disturbance = DisturbanceKind::kNone;
    absl::StatusOr<ObjectPair> pair = MakeObjectPair(pair_options, seed);
    if (!pair.ok()) return pair.status();
    return RegistrationPair{std::move(pair->source), std::move(pair->target),
                            pair->T_target_source};
  };
}

RegistrationPairGenerator MakeLidarPairStream(const LidarStreamOptions& options) {
  auto cache = std::make_shared<SequenceCache>();
  return [options, cache](uint64_t index) -> absl::StatusOr<RegistrationPair> {
    const uint64_t sequence = index / std::max(options.pairs_per_sequence, 1);
    LidarSequenceOptions sequence_options;
    sequence_options.seed = MixSeed(options.stream_seed, sequence);
    sequence_options.style = static_cast<StreetStyle>(sequence % 4);
    sequence_options.frame_count = options.frames_per_sequence;
    sequence_options.thread_count = 1;
    absl::StatusOr<std::shared_ptr<const LidarSequenceSimulator>> simulator =
        cache->Get(sequence_options);
    if (!simulator.ok()) return simulator.status();
    const uint64_t pair_seed = MixSeed(sequence_options.seed, index);
    const int frames = options.frames_per_sequence - options.frame_offset;
    if (frames < 1) {
      return absl::InvalidArgumentError("frames_per_sequence must exceed frame_offset");
    }
    const int source_frame = static_cast<int>(MixSeed(pair_seed, 1) % frames);
    const int target_frame = source_frame + options.frame_offset;
    const LidarScan source = (*simulator)->SimulateFrame(source_frame);
    const LidarScan target = (*simulator)->SimulateFrame(target_frame);
    const auto& poses = (*simulator)->T_world_lidar();
    RegistrationPair pair;
    pair.T_target_source = poses[target_frame].inverse() * poses[source_frame];
    if (UnitFromSeed(pair_seed) < options.ground_removed_fraction) {
      absl::StatusOr<PointCloud> s = WithoutGround(source);
      absl::StatusOr<PointCloud> t = WithoutGround(target);
      if (!s.ok() || !t.ok()) return s.ok() ? t.status() : s.status();
      pair.source = *std::move(s);
      pair.target = *std::move(t);
    } else {
      pair.source = source.cloud;
      pair.target = target.cloud;
    }
    return pair;
  };
}

}  // namespace rpsr::core
