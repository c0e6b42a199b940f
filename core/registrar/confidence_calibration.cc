#include "core/registrar/confidence_calibration.h"

#include <algorithm>
#include <atomic>
#include <cmath>
#include <limits>
#include <mutex>
#include <numeric>
#include <thread>
#include <utility>

#include "Eigen/Cholesky"
#include "Eigen/Core"
#include "absl/status/status.h"
#include "absl/strings/str_cat.h"
#include "core/data/disturbances.h"
#include "core/data/registration_metrics.h"
#include "core/data/training_pairs.h"
#include "core/synth/seeded_random.h"

namespace rpsr::core {
namespace {

const char* SplitName(ObjectSplit split) {
  switch (split) {
    case ObjectSplit::kM1All:
      return "m1";
    case ObjectSplit::kM2Seen:
      return "seen";
    case ObjectSplit::kM2Unseen:
      return "unseen";
  }
  return "?";
}

// The kinds of unrelated pairs (CalibrationSetOptions::unrelated_pairs_per_kind).
enum class Unrelated { kNo, kVolumes, kObjects, kScans };

// One pair to generate: an object pair (split, disturbance, level, index), a LiDAR pair (frame
// offset, index) or an unrelated pair (kind, index).
struct WorkItem {
  bool lidar = false;
  Unrelated unrelated = Unrelated::kNo;
  std::string setting;
  uint64_t seed = 0;
  PairOptions object;
  int offset_slot = 0;
  uint64_t lidar_index = 0;
};

double Sigmoid(double z) {
  if (z >= 0) return 1.0 / (1.0 + std::exp(-z));
  const double e = std::exp(z);
  return e / (1.0 + e);
}

// Uniform points in a box of random proportions (edges 0.5-2), at a random place near the origin.
PointCloud RandomVolume(size_t n, uint64_t seed) {
  SeededRandom random(seed);
  auto unit = [&random] { return random.Uniform(-0.5, 0.5); };
  const Eigen::Vector3d size(random.Uniform(0.5, 2.0), random.Uniform(0.5, 2.0),
                             random.Uniform(0.5, 2.0));
  const Eigen::Vector3d center(0.3 * unit(), 0.3 * unit(), 0.3 * unit());
  PointCloud cloud;
  cloud.points.reserve(n);
  for (size_t i = 0; i < n; ++i) {
    const double x = unit();
    const double y = unit();
    const double z = unit();
    cloud.points.push_back((center + Eigen::Vector3d(x, y, z).cwiseProduct(size)).cast<float>());
  }
  return cloud;
}

// A pair with nothing in common (WorkItem::unrelated); its T_target_source is meaningless.
absl::StatusOr<RegistrationPair> UnrelatedPair(
    const WorkItem& item, const std::vector<RegistrationPairGenerator>& lidar_streams) {
  RegistrationPair pair;
  switch (item.unrelated) {
    case Unrelated::kVolumes:
      pair.source = RandomVolume(item.object.num_points, DeriveSeed(item.seed, 1));
      pair.target = RandomVolume(item.object.num_points, DeriveSeed(item.seed, 2));
      return pair;
    case Unrelated::kObjects: {
      absl::StatusOr<ObjectPair> a = MakeObjectPair(item.object, DeriveSeed(item.seed, 1));
      if (!a.ok()) return a.status();
      // The target from the first later seed whose object is of another family.
      for (uint64_t k = 2; k < 64; ++k) {
        absl::StatusOr<ObjectPair> b = MakeObjectPair(item.object, DeriveSeed(item.seed, k));
        if (!b.ok()) return b.status();
        if (b->family_index == a->family_index) continue;
        pair.source = std::move(a->source);
        pair.target = std::move(b->target);
        return pair;
      }
      return absl::InternalError("no object of another family in 62 draws");
    }
    case Unrelated::kScans: {
      // Pairs 8 apart in a stream come from different sequences (8 pairs a sequence), each
      // sequence a street of another style or seed.
      const RegistrationPairGenerator& stream = lidar_streams.front();
      absl::StatusOr<RegistrationPair> a = stream(item.lidar_index * 2);
      absl::StatusOr<RegistrationPair> b = stream(item.lidar_index * 2 + 8);
      if (!a.ok()) return a.status();
      if (!b.ok()) return b.status();
      pair.source = std::move(a->source);
      pair.target = std::move(b->target);
      return pair;
    }
    case Unrelated::kNo:
      break;
  }
  return absl::InternalError("not an unrelated pair");
}

}  // namespace

bool CalibrationSample::success() const {
  return rotation_error_deg <= 1.0 && translation_error_rel <= 0.01;
}

bool CalibrationSample::failure() const {
  return rotation_error_deg > 5.0 || translation_error_rel > 0.05;
}

RegistrationPairGenerator CalibrationLidarPairs(uint64_t pair_seed, int frame_offset) {
  LidarStreamOptions stream;
  stream.frame_offset = frame_offset;
  stream.pairs_per_sequence = 8;  // four sequences (one per street style) per 32 pairs
  stream.stream_seed = DeriveSeed(pair_seed, 1000 + static_cast<uint64_t>(frame_offset));
  return MakeLidarPairStream(stream);
}

absl::StatusOr<std::vector<CalibrationSample>> CollectCalibrationSamples(
    const Registrar& registrar, const CalibrationSetOptions& options) {
  if (options.modes.empty()) return absl::InvalidArgumentError("no registration mode to sample");
  std::vector<WorkItem> items;
  std::vector<std::pair<DisturbanceKind, int>> settings = {{DisturbanceKind::kNone, 0}};
  for (DisturbanceKind kind : {DisturbanceKind::kGaussianNoise, DisturbanceKind::kUniformOutliers,
                               DisturbanceKind::kCrop, DisturbanceKind::kJitter}) {
    for (int level = 0; level < kNumDisturbanceLevels; ++level) settings.push_back({kind, level});
  }
  // Appended after the paper's 21 so that their pairs (seeded by their index) stay the same.
  if (options.partial_views) {
    for (int level = 0; level < kNumDisturbanceLevels; ++level) {
      settings.push_back({DisturbanceKind::kPartialViews, level});
    }
  }
  for (ObjectSplit split : options.object_splits) {
    for (size_t k = 0; k < settings.size(); ++k) {
      const auto [kind, level] = settings[k];
      absl::StatusOr<double> magnitude = DisturbanceMagnitudeAtLevel(kind, level);
      if (!magnitude.ok()) return magnitude.status();
      const std::string name = absl::StrCat(
          SplitName(split), "/",
          kind == DisturbanceKind::kNone ? std::string("clean")
                                         : absl::StrCat(DisturbanceName(kind), "@", *magnitude));
      const uint64_t setting_seed =
          DeriveSeed(options.seed, static_cast<uint64_t>(split) * 64 + static_cast<uint64_t>(k));
      for (int i = 0; i < options.object_pairs_per_setting; ++i) {
        WorkItem item;
        item.setting = name;
        item.seed = DeriveSeed(setting_seed, static_cast<uint64_t>(i));
        item.object.split = split;
        item.object.num_points = i % 2 == 0 ? 1024 : 2048;
        item.object.disturbance = kind;
        item.object.disturbance_level = level;
        items.push_back(item);
      }
    }
  }
  std::vector<RegistrationPairGenerator> lidar_streams;
  for (size_t o = 0; o < options.lidar_frame_offsets.size(); ++o) {
    const int frame_offset = options.lidar_frame_offsets[o];
    lidar_streams.push_back(CalibrationLidarPairs(options.seed, frame_offset));
    for (int i = 0; i < options.lidar_pairs_per_offset; ++i) {
      WorkItem item;
      item.lidar = true;
      item.setting = absl::StrCat("lidar+", frame_offset);
      item.offset_slot = static_cast<int>(o);
      item.lidar_index = static_cast<uint64_t>(i);
      items.push_back(item);
    }
  }

  for (int i = 0; i < options.unrelated_pairs_per_kind; ++i) {
    for (Unrelated kind : {Unrelated::kVolumes, Unrelated::kObjects, Unrelated::kScans}) {
      if (kind == Unrelated::kScans && lidar_streams.empty()) continue;
      WorkItem item;
      item.unrelated = kind;
      item.lidar = kind == Unrelated::kScans;
      item.setting = kind == Unrelated::kVolumes   ? "unrelated/volumes"
                     : kind == Unrelated::kObjects ? "unrelated/objects"
                                                   : "unrelated/scans";
      item.seed = DeriveSeed(options.seed, 5000 + static_cast<uint64_t>(i));
      item.object.split = ObjectSplit::kM1All;
      item.object.num_points = i % 2 == 0 ? 1024 : 2048;
      item.lidar_index = static_cast<uint64_t>(i);
      items.push_back(item);
    }
  }

  std::vector<std::vector<CalibrationSample>> per_item(items.size());
  std::vector<absl::Status> errors(items.size());
  std::atomic<size_t> next{0};
  std::atomic<int> done{0};
  std::mutex progress_mutex;
  auto work = [&] {
    for (size_t i = next++; i < items.size(); i = next++) {
      const WorkItem& item = items[i];
      RegistrationPair pair;
      BarnesHutTreeOptions tree_options;
      if (item.unrelated != Unrelated::kNo) {
        absl::StatusOr<RegistrationPair> p = UnrelatedPair(item, lidar_streams);
        if (!p.ok()) {
          errors[i] = p.status();
          continue;
        }
        pair = *std::move(p);
        tree_options.max_depth = item.lidar ? options.lidar_tree_depth : options.object_tree_depth;
      } else if (item.lidar) {
        absl::StatusOr<RegistrationPair> p = lidar_streams[item.offset_slot](item.lidar_index);
        if (!p.ok()) {
          errors[i] = p.status();
          continue;
        }
        pair = *std::move(p);
        tree_options.max_depth = options.lidar_tree_depth;
      } else {
        absl::StatusOr<ObjectPair> p = MakeObjectPair(item.object, item.seed);
        if (!p.ok()) {
          errors[i] = p.status();
          continue;
        }
        pair = {std::move(p->source), std::move(p->target), p->T_target_source};
        tree_options.max_depth = options.object_tree_depth;
      }
      absl::StatusOr<Octree> source = BuildOctree(pair.source, tree_options);
      absl::StatusOr<Octree> target = BuildOctree(pair.target, tree_options);
      if (!source.ok() || !target.ok()) {
        errors[i] = source.ok() ? target.status() : source.status();
        continue;
      }
      std::vector<RegistrationRequest> requests;
      for (RegistrationMode mode : options.modes) {
        RegistrationRequest r{&*source, &*target, {}};
        r.options.mode = mode;
        requests.push_back(r);
      }
      std::vector<absl::StatusOr<RegistrationResult>> results = registrar.RegisterBatch(requests);
      const double extent = std::max(ConfidenceExtent(*target), 1e-12);
      for (size_t m = 0; m < results.size(); ++m) {
        if (!results[m].ok()) {
          errors[i] = results[m].status();
          break;
        }
        const RegistrationResult& r = *results[m];
        CalibrationSample s;
        s.protocol = item.unrelated != Unrelated::kNo ? "unrelated"
                     : item.lidar                     ? "lidar"
                                                      : "objects";
        s.setting = item.setting;
        s.mode = r.mode;
        s.valid = r.valid;
        s.num_degenerate = r.num_degenerate;
        s.failure_reason = r.failure_reason;
        s.confidence = r.confidence;
        s.features = r.confidence_features;
        if (s.features.empty()) s.features.assign(kNumConfidenceFeatures, 0.0);
        const PairError e = ErrorOf(r.T_target_source, pair.T_target_source);
        s.rotation_error_deg = e.rotation_deg;
        s.translation_error_rel = e.translation / extent;
        if (item.unrelated != Unrelated::kNo) {  // no pose is right
          s.rotation_error_deg = 180.0;
          s.translation_error_rel = 1.0;
        }
        per_item[i].push_back(std::move(s));
      }
      const int d = ++done;
      if (options.progress) {
        std::lock_guard<std::mutex> lock(progress_mutex);
        options.progress(d, static_cast<int>(items.size()));
      }
    }
  };
  std::vector<std::thread> threads;
  for (int t = 1; t < std::max(1, options.threads); ++t) threads.emplace_back(work);
  work();
  for (std::thread& t : threads) t.join();
  std::vector<CalibrationSample> samples;
  for (size_t i = 0; i < items.size(); ++i) {
    if (!errors[i].ok()) {
      return absl::Status(errors[i].code(),
                          absl::StrCat(items[i].setting, ": ", errors[i].message()));
    }
    for (CalibrationSample& s : per_item[i]) samples.push_back(std::move(s));
  }
  return samples;
}

absl::StatusOr<ConfidenceModel> FitConfidenceModel(const std::vector<CalibrationSample>& samples,
                                                   const ConfidenceFitOptions& options) {
  std::vector<const CalibrationSample*> used;
  int positives = 0;
  for (const CalibrationSample& s : samples) {
    if (!s.valid || s.features.size() != static_cast<size_t>(kNumConfidenceFeatures)) continue;
    used.push_back(&s);
    positives += s.success();
  }
  const int n = static_cast<int>(used.size());
  if (positives == 0 || positives == n) {
    return absl::InvalidArgumentError(
        absl::StrCat("fitting the confidence needs valid samples of both outcomes (", n, " valid, ",
                     positives, " within 1 degree and 1% of the extent)"));
  }
  const int d = kNumConfidenceFeatures;
  // Standardise; constant features (e.g. one mode only) are left out.
  Eigen::VectorXd mean = Eigen::VectorXd::Zero(d), scale = Eigen::VectorXd::Ones(d);
  for (const CalibrationSample* s : used) {
    for (int j = 0; j < d; ++j) mean[j] += s->features[j];
  }
  mean /= n;
  Eigen::VectorXd var = Eigen::VectorXd::Zero(d);
  for (const CalibrationSample* s : used) {
    for (int j = 0; j < d; ++j) var[j] += std::pow(s->features[j] - mean[j], 2);
  }
  std::vector<int> active;
  for (int j = 0; j < d; ++j) {
    scale[j] = std::sqrt(var[j] / n);
    if (scale[j] > 1e-9) active.push_back(j);
  }
  const int k = static_cast<int>(active.size()) + 1;  // + bias
  Eigen::MatrixXd X(n, k);
  Eigen::VectorXd y(n);
  for (int i = 0; i < n; ++i) {
    X(i, 0) = 1.0;
    for (int a = 0; a < k - 1; ++a) {
      const int j = active[a];
      X(i, a + 1) = (used[i]->features[j] - mean[j]) / scale[j];
    }
    y[i] = used[i]->success() ? 1.0 : 0.0;
  }
  Eigen::VectorXd w = Eigen::VectorXd::Zero(k);
  const double lambda = options.l2 * n;
  for (int it = 0; it < options.max_newton_iterations; ++it) {
    Eigen::VectorXd p(n);
    for (int i = 0; i < n; ++i) p[i] = Sigmoid(X.row(i).dot(w));
    Eigen::VectorXd g = X.transpose() * (p - y);
    Eigen::MatrixXd H = Eigen::MatrixXd::Zero(k, k);
    for (int i = 0; i < n; ++i) {
      H.noalias() += std::max(p[i] * (1 - p[i]), 1e-12) * X.row(i).transpose() * X.row(i);
    }
    for (int a = 1; a < k; ++a) {  // the bias is not penalised
      g[a] += lambda * w[a];
      H(a, a) += lambda;
    }
    const Eigen::VectorXd step = H.ldlt().solve(g);
    if (!step.allFinite()) break;
    w -= step;
    if (step.norm() < 1e-9 * (1 + w.norm())) break;
  }
  ConfidenceModel model;
  model.bias = w[0];
  for (int a = 0; a < k - 1; ++a) {
    const int j = active[a];
    model.features.push_back({j, mean[j], scale[j], w[a + 1]});
  }
  model.degenerate_cap = options.degenerate_cap;
  if (options.isotonic) {
    // Pool adjacent violators on (raw probability, outcome), sorted by probability.
    std::vector<std::pair<double, double>> points;
    for (const CalibrationSample* s : used) {
      points.push_back({model.RawProbability(s->features), s->success() ? 1.0 : 0.0});
    }
    std::sort(points.begin(), points.end());
    struct Block {
      double x_sum, y_sum, count;
    };
    std::vector<Block> blocks;
    for (const auto& [x, yv] : points) {
      blocks.push_back({x, yv, 1.0});
      while (blocks.size() >= 2 &&
             blocks[blocks.size() - 2].y_sum / blocks[blocks.size() - 2].count >=
                 blocks.back().y_sum / blocks.back().count) {
        Block b = blocks.back();
        blocks.pop_back();
        blocks.back().x_sum += b.x_sum;
        blocks.back().y_sum += b.y_sum;
        blocks.back().count += b.count;
      }
    }
    for (const Block& b : blocks) {
      model.isotonic_x.push_back(b.x_sum / b.count);
      model.isotonic_y.push_back(b.y_sum / b.count);
    }
    // The top block is often pure (all successes): a probability of exactly 1 claims more than a
    // finite sample shows, so it takes the Jeffreys estimate (k + 1/2) / (n + 1) instead, kept
    // strictly above its neighbour (the map stays increasing, so the logistic output's ranking
    // survives). The bottom block keeps its rate: a 0 there ties with the invalid results.
    const size_t m = model.isotonic_y.size();
    if (m >= 2) {
      const Block& last = blocks.back();
      std::vector<double>& y = model.isotonic_y;
      y.back() = std::max((last.y_sum + 0.5) / (last.count + 1.0), 0.5 * (y.back() + y[m - 2]));
    }
    if (model.isotonic_x.size() < 2) {
      model.isotonic_x.clear();
      model.isotonic_y.clear();
    }
  }
  return model;
}

ReliabilityReport MeasureReliability(const std::vector<CalibrationSample>& samples,
                                     const std::vector<double>& confidences, int num_bins) {
  ReliabilityReport report;
  report.count = static_cast<int>(samples.size());
  num_bins = std::max(1, num_bins);
  report.bins.resize(num_bins);
  for (int b = 0; b < num_bins; ++b) {
    report.bins[b].lower = static_cast<double>(b) / num_bins;
    report.bins[b].upper = static_cast<double>(b + 1) / num_bins;
  }
  std::vector<double> success_scores, failure_scores;
  for (size_t i = 0; i < samples.size(); ++i) {
    const double c = std::clamp(confidences[i], 0.0, 1.0);
    const double y = samples[i].success() ? 1.0 : 0.0;
    report.successes += samples[i].success();
    report.failures += samples[i].failure();
    report.mean_confidence += c;
    report.success_rate += y;
    report.brier += (c - y) * (c - y);
    const int b = std::min(num_bins - 1, static_cast<int>(c * num_bins));
    ReliabilityBin& bin = report.bins[b];
    ++bin.count;
    bin.mean_confidence += c;
    bin.success_rate += y;
    if (samples[i].success()) success_scores.push_back(c);
    if (samples[i].failure()) failure_scores.push_back(c);
  }
  if (report.count == 0) return report;
  report.mean_confidence /= report.count;
  report.success_rate /= report.count;
  report.brier /= report.count;
  for (ReliabilityBin& bin : report.bins) {
    if (bin.count == 0) continue;
    bin.mean_confidence /= bin.count;
    bin.success_rate /= bin.count;
    report.ece += static_cast<double>(bin.count) / report.count *
                  std::abs(bin.success_rate - bin.mean_confidence);
  }
  if (success_scores.empty() || failure_scores.empty()) {
    report.auroc = std::numeric_limits<double>::quiet_NaN();
  } else {
    // Mann-Whitney U through ranks of the merged scores (ties get their mean rank).
    std::vector<std::pair<double, int>> all;
    for (double s : success_scores) all.push_back({s, 1});
    for (double s : failure_scores) all.push_back({s, 0});
    std::sort(all.begin(), all.end());
    double rank_sum = 0.0;
    for (size_t i = 0; i < all.size();) {
      size_t j = i;
      while (j < all.size() && all[j].first == all[i].first) ++j;
      const double mean_rank = 0.5 * static_cast<double>(i + 1 + j);  // ranks i+1 .. j
      for (size_t t = i; t < j; ++t) {
        if (all[t].second == 1) rank_sum += mean_rank;
      }
      i = j;
    }
    const double ns = static_cast<double>(success_scores.size());
    const double nf = static_cast<double>(failure_scores.size());
    report.auroc = (rank_sum - ns * (ns + 1) / 2.0) / (ns * nf);
  }
  return report;
}

}  // namespace rpsr::core
