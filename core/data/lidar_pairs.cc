#include "core/data/lidar_pairs.h"

#include <algorithm>
#include <cmath>

#include "absl/strings/str_cat.h"
#include "core/data/semantic_labels.h"
#include "core/synth/seeded_random.h"

namespace rpsr::core {

const char* LidarSplitName(LidarSplit split) {
  switch (split) {
    case LidarSplit::kTrain:
      return "train";
    case LidarSplit::kTest:
      return "test";
    case LidarSplit::kValidation:
      return "validation";
  }
  return "unknown";
}

FrameRange SplitFrameRange(int frame_count, LidarSplit split, const LidarPairOptions& options) {
  const int train_end = static_cast<int>(std::floor(options.train_fraction * frame_count));
  const int test_end = std::min(
      frame_count,
      static_cast<int>(std::floor((options.train_fraction + options.test_fraction) * frame_count)));
  switch (split) {
    case LidarSplit::kTrain:
      return {0, train_end};
    case LidarSplit::kTest:
      return {train_end, test_end};
    case LidarSplit::kValidation:
      return {test_end, frame_count};
  }
  return {0, 0};
}

absl::StatusOr<std::vector<LidarPairIndex>> SelectLidarPairs(int sequence, int frame_count,
                                                             LidarSplit split,
                                                             const LidarPairOptions& options) {
  if (options.frame_offset < 1) {
    return absl::InvalidArgumentError(absl::StrCat(
        "SelectLidarPairs: frame_offset must be positive, got ", options.frame_offset));
  }
  if (options.split_gap_frames < 0) {
    return absl::InvalidArgumentError(absl::StrCat(
        "SelectLidarPairs: split_gap_frames must be non-negative, got ", options.split_gap_frames));
  }
  if (!(options.train_fraction >= 0.0 && options.test_fraction >= 0.0 &&
        options.train_fraction + options.test_fraction <= 1.0)) {
    return absl::InvalidArgumentError(
        absl::StrCat("SelectLidarPairs: need fractions in [0, 1] summing to at most 1, got train ",
                     options.train_fraction, " and test ", options.test_fraction));
  }
  const FrameRange block = SplitFrameRange(std::max(frame_count, 0), split, options);
  const int first = block.begin + (block.begin > 0 ? options.split_gap_frames : 0);
  std::vector<LidarPairIndex> pairs;
  for (int source = first; source + options.frame_offset < block.end; ++source) {
    pairs.push_back({sequence, source, source + options.frame_offset});
  }
  if (options.max_pairs > 0 && pairs.size() > options.max_pairs) {
    SeededRandom random(
        DeriveSeed(options.seed, static_cast<uint64_t>(sequence) * 3 + static_cast<int>(split)));
    std::vector<size_t> chosen = random.DistinctIndices(pairs.size(), options.max_pairs);
    std::sort(chosen.begin(), chosen.end());
    std::vector<LidarPairIndex> subset;
    subset.reserve(chosen.size());
    for (size_t i : chosen) subset.push_back(pairs[i]);
    pairs = std::move(subset);
  }
  return pairs;
}

absl::StatusOr<LidarPair> LoadLidarPair(const KittiOdometrySequence& sequence,
                                        const LidarPairIndex& index, GroundHandling ground) {
  if (index.sequence != sequence.sequence()) {
    return absl::InvalidArgumentError(
        absl::StrCat("LoadLidarPair: pair of sequence ", index.sequence, " given sequence ",
                     sequence.sequence(), " (", sequence.directory(), ")"));
  }
  for (int frame : {index.source_frame, index.target_frame}) {
    if (frame < 0 || frame >= sequence.frame_count()) {
      return absl::OutOfRangeError(absl::StrCat(sequence.directory(), ": frame ", frame,
                                                " is outside [0, ", sequence.frame_count(), ")"));
    }
  }
  auto read = [&](int frame) -> absl::StatusOr<PointCloud> {
    if (ground == GroundHandling::kKeep) return sequence.ReadScan(frame);
    absl::StatusOr<LabeledScan> scan = sequence.ReadLabeledScan(frame);
    if (!scan.ok()) return scan.status();
    return RemoveGroundPoints(scan->cloud, scan->labels,
                              KittiLabelPath(sequence.directory(), frame));
  };
  LidarPair pair;
  pair.index = index;
  absl::StatusOr<PointCloud> source = read(index.source_frame);
  if (!source.ok()) return source.status();
  absl::StatusOr<PointCloud> target = read(index.target_frame);
  if (!target.ok()) return target.status();
  pair.source = *std::move(source);
  pair.target = *std::move(target);
  pair.T_target_source = sequence.T_target_source(index.source_frame, index.target_frame);
  return pair;
}

}  // namespace rpsr::core
