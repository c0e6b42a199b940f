// Refinement on the trees (issue 5): milliseconds per refinement, trees given (building them is
// bh_tree_bench's business), and the accuracy the refinement reaches.
//
//   build/tests/bench/tree_refinement_bench --benchmark_counters_tabular=true
//
// Speed: BM_RefineLidar/depth:D refines a simulated 120k-point urban pair five frames apart
// (0.5 s of driving, a few metres) from the identity with trees cached to depth D;
// BM_RefineSparseLidar/depth:D the same on a simulated VLP-16 drive (the line rule chosen on);
// BM_RefineObject/points:N refines an object pair from the truth perturbed by 10 degrees and
// 0.07; BM_LineShapedFraction/depth:D is the line rule's choice on one of those trees;
// BM_MeanNodeDistance/lidar:L the registrar's closeness of two starts' answers;
// BM_FarNodeFractions/lidar:L the confidence's turn contrast (the answer and six 45-degree turns,
// 512 nodes one depth above the finest); BM_BestWeakDirectionStart the registrar's
// weak-direction start on 16 unseen object answers. Accuracy
// (one pass each, counters): BM_ObjectAccuracy/from_truth_deg:A starts 40
// asymmetric object pairs at the truth rotated by A degrees about a random axis and shifted by
// 0.07; BM_ObjectBasin/max_angle_deg:A starts them at the identity with the paper's protocol
// (Euler angles each up to A degrees, translations up to 0.5); BM_LidarAccuracy refines pairs
// i -> i+5 of a simulated drive from the identity. Success = rotation < 1 deg and translation
// < 0.01 (objects) or < 0.3 m (LiDAR).
#include <cmath>
#include <cstdlib>
#include <random>
#include <string>
#include <vector>

#include "benchmark/benchmark.h"
#include "core/data/object_pairs.h"
#include "core/data/registration_metrics.h"
#include "core/data/transform_convention.h"
#include "core/refine/node_closeness.h"
#include "core/refine/symmetry_starts.h"
#include "core/refine/tree_refinement.h"
#include "core/refine/weak_direction_start.h"
#include "core/synth/lidar_sequence.h"
#include "core/synth/lidar_simulator.h"
#include "core/synth/shape_families.h"
#include "tests/bench/bench_clouds.h"

namespace rpsr::core {
namespace {

constexpr double kDeg = M_PI / 180.0;

Octree TreeOf(const PointCloud& cloud, int max_depth) {
  BarnesHutTreeOptions options;
  options.max_depth = max_depth;
  options.neighbor_max_depth = 5;  // what the service caches for the network
  auto tree = BuildOctree(cloud, options);
  if (!tree.ok()) std::abort();
  return *std::move(tree);
}

using bench::Thinned;

// A 40-frame simulated urban drive (seed 1) seen by `sensor`.
const LidarSequenceSimulator* NewDrive(const LidarSensorOptions& sensor) {
  LidarSequenceOptions options;
  options.frame_count = 40;
  options.seed = 1;
  options.sensor = sensor;
  auto created = LidarSequenceSimulator::Create(options);
  if (!created.ok()) std::abort();
  return new LidarSequenceSimulator(*std::move(created));
}

const LidarSequenceSimulator& Drive() {
  static const LidarSequenceSimulator* simulator = [] {
    LidarSensorOptions sensor;
    sensor.azimuth_steps = 2400;  // ~140k points, thinned to 120k
    return NewDrive(sensor);
  }();
  return *simulator;
}

Eigen::Isometry3d TruthOf(const LidarSequenceSimulator& drive, int target_frame, int source_frame) {
  return drive.T_world_lidar()[target_frame].inverse() * drive.T_world_lidar()[source_frame];
}

Eigen::Isometry3d TruthOf(int target_frame, int source_frame) {
  return TruthOf(Drive(), target_frame, source_frame);
}

void ReportResult(benchmark::State& state, const TreeRefinementResult& result,
                  const Eigen::Isometry3d& truth) {
  const PairError error = ErrorOf(result.T_target_source, truth);
  state.counters["rot_err_deg"] = error.rotation_deg;
  state.counters["trans_err"] = error.translation;
  state.counters["valid"] = result.valid;
  state.counters["fitness"] = result.fitness;
  state.counters["inlier_rmse"] = result.inlier_rmse;
  state.counters["iterations"] = result.iterations;
  for (const DepthStage& stage : result.stages) {
    state.counters["ms_d" + std::to_string(stage.depth)] = 1e3 * stage.seconds;
    state.counters["it_d" + std::to_string(stage.depth)] = stage.iterations;
    state.counters["prep_ms_d" + std::to_string(stage.depth)] = 1e3 * stage.prepare_seconds;
  }
}

void BM_RefineLidar(benchmark::State& state) {
  const int depth = static_cast<int>(state.range(0));
  const Octree target = TreeOf(Thinned(Drive().SimulateFrame(10).cloud, 120'000), depth);
  const Octree source = TreeOf(Thinned(Drive().SimulateFrame(15).cloud, 120'000), depth);
  TreeRefinementResult last;
  for (auto _ : state) {
    auto result = RefineOnTrees(source, target, Eigen::Isometry3d::Identity());
    if (!result.ok()) std::abort();
    last = *std::move(result);
  }
  ReportResult(state, last, TruthOf(10, 15));
}
BENCHMARK(BM_RefineLidar)->ArgName("depth")->Arg(8)->Arg(9)->Arg(10)->Unit(benchmark::kMillisecond);

// A sparse scanner's pair (simulated VLP-16, urban, frames 10 -> 15, every point: ~28k), where
// the line rule is chosen on and most of the finest nodes are ring arcs whose normals come from
// their ancestors' planes (ShapeAt).
const LidarSequenceSimulator& SparseDrive() {
  static const LidarSequenceSimulator* simulator = NewDrive(*LidarSensorPreset("vlp16"));
  return *simulator;
}

void BM_RefineSparseLidar(benchmark::State& state) {
  const int depth = static_cast<int>(state.range(0));
  const Octree target = TreeOf(SparseDrive().SimulateFrame(10).cloud, depth);
  const Octree source = TreeOf(SparseDrive().SimulateFrame(15).cloud, depth);
  TreeRefinementResult last;
  for (auto _ : state) {
    auto result = RefineOnTrees(source, target, Eigen::Isometry3d::Identity());
    if (!result.ok()) std::abort();
    last = *std::move(result);
  }
  const Eigen::Isometry3d truth = TruthOf(SparseDrive(), 10, 15);
  ReportResult(state, last, truth);
  state.counters["line_rule"] = last.line_normals_from_planes;
  state.counters["points"] = static_cast<double>(source.num_points());
}
BENCHMARK(BM_RefineSparseLidar)->ArgName("depth")->Arg(9)->Unit(benchmark::kMillisecond);

// What choosing the line rule costs a tree (TreeRefinementOptions::line_normals_from_planes left
// unset: LineShapedFraction, once per tree of a pair), against BM_RefineLidar's refinement.
void BM_LineShapedFraction(benchmark::State& state) {
  const Octree tree =
      TreeOf(Thinned(Drive().SimulateFrame(10).cloud, 120'000), static_cast<int>(state.range(0)));
  const int min_count = TreeRefinementOptions{}.min_count_for_covariance;
  double fraction = 0.0;
  for (auto _ : state) {
    fraction = LineShapedFraction(tree, min_count).value_or(-1.0);
    benchmark::DoNotOptimize(fraction);
  }
  state.counters["line_fraction"] = fraction;
}
BENCHMARK(BM_LineShapedFraction)->ArgName("depth")->Arg(9)->Unit(benchmark::kMillisecond);

// The node-closeness benchmarks' pairs at the true pose: BM_RefineLidar's depth-9 scan pair, or a
// 1,024-point object pair at depth 6.
struct PairAtTruth {
  Octree source;
  Octree target;
  Eigen::Isometry3d truth = Eigen::Isometry3d::Identity();
  int depth = 0;  // the trees'
};

PairAtTruth ClosenessPair(bool lidar) {
  PairAtTruth p;
  if (lidar) {
    p.depth = 9;
    p.target = TreeOf(Thinned(Drive().SimulateFrame(10).cloud, 120'000), p.depth);
    p.source = TreeOf(Thinned(Drive().SimulateFrame(15).cloud, 120'000), p.depth);
    p.truth = TruthOf(10, 15);
  } else {
    p.depth = 6;
    PairOptions options;
    auto pair = MakeObjectPair(options, 1);
    if (!pair.ok()) std::abort();
    p.source = TreeOf(pair->source, p.depth);
    p.target = TreeOf(pair->target, p.depth);
    p.truth = pair->T_target_source;
  }
  return p;
}

// What telling two equally fitting answers apart costs (MeanNodeDistanceCells, run for each of two
// starts' answers when they differ), on ClosenessPair's pairs.
void BM_MeanNodeDistance(benchmark::State& state) {
  const PairAtTruth p = ClosenessPair(state.range(0) != 0);
  double cells = 0.0;
  for (auto _ : state) {
    cells = MeanNodeDistanceCells(p.source, p.target, p.truth, p.depth);
    benchmark::DoNotOptimize(cells);
  }
  state.counters["mean_cells"] = cells;
}
BENCHMARK(BM_MeanNodeDistance)->ArgName("lidar")->Arg(0)->Arg(1)->Unit(benchmark::kMillisecond);

// The confidence's turn contrast (confidence_model.cc's TurnContrast, run for every answer the
// registrar settles): FarNodeFractions over the true pose and its six 45-degree turns about the
// moved source's centre, 512 nodes one depth above the finest (SymmetryDepth), on the same pairs.
void BM_FarNodeFractions(benchmark::State& state) {
  const PairAtTruth p = ClosenessPair(state.range(0) != 0);
  const Eigen::Vector3d pivot = p.truth * p.source.level(0).center_of_mass[0].cast<double>();
  std::vector<Eigen::Isometry3d> poses = {p.truth};
  for (int axis = 0; axis < 3; ++axis) {
    for (double sign : {-1.0, 1.0}) {
      const Eigen::AngleAxisd turn(sign * M_PI / 4.0, Eigen::Vector3d::Unit(axis));
      Eigen::Isometry3d about = Eigen::Isometry3d::Identity();
      about.linear() = turn.toRotationMatrix();
      about.translation() = pivot - turn * pivot;
      poses.push_back(about * p.truth);
    }
  }
  const int depth = SymmetryDepth(p.source, p.target);
  const double far_cells = SelfSymmetryOptions{}.far_cells;
  NodeClosenessOptions sample;
  sample.max_source_nodes = 512;
  std::vector<double> far;
  for (auto _ : state) {
    far = FarNodeFractions(p.source, p.target, poses, depth, far_cells, sample);
    benchmark::DoNotOptimize(far.data());
  }
  state.counters["far_at_truth"] = far.front();
  state.counters["far_turned"] = far.back();
}
BENCHMARK(BM_FarNodeFractions)->ArgName("lidar")->Arg(0)->Arg(1)->Unit(benchmark::kMillisecond);

// The weak-direction start's scoring (BestWeakDirectionStart at SymmetryDepth, run on every
// object-scale answer without near-symmetries): 16 unseen object pairs of 2,048 points, each
// refined from its truth turned by 3 degrees, one call each per iteration. Counter: how many of
// the 16 found a step to refine.
void BM_BestWeakDirectionStart(benchmark::State& state) {
  struct Answer {
    Octree source;
    Octree target;
    TreeRefinementResult refined;
  };
  std::vector<Answer> answers;
  PairOptions options;
  options.split = ObjectSplit::kM2Unseen;
  options.num_points = 2048;
  for (uint64_t seed = 1; answers.size() < 16; ++seed) {
    auto pair = MakeObjectPair(options, seed);
    if (!pair.ok()) std::abort();
    Answer a{TreeOf(pair->source, 6), TreeOf(pair->target, 6), {}};
    const Eigen::AngleAxisd turn(3.0 * kDeg, Eigen::Vector3d::UnitZ());
    auto refined = RefineOnTrees(a.source, a.target, turn * pair->T_target_source);
    if (!refined.ok() || !refined->valid) continue;
    a.refined = *std::move(refined);
    answers.push_back(std::move(a));
  }
  int found = 0;
  for (auto _ : state) {
    found = 0;
    for (const Answer& a : answers) {
      found +=
          BestWeakDirectionStart(a.source, a.target, a.refined, SymmetryDepth(a.source, a.target))
              .has_value();
    }
  }
  state.counters["found"] = found;
}
BENCHMARK(BM_BestWeakDirectionStart)->Unit(benchmark::kMillisecond);

ObjectPair AsymmetricPair(const PairOptions& options, uint64_t& seed) {
  while (true) {
    auto pair = MakeObjectPair(options, seed++);
    if (!pair.ok()) std::abort();
    if (ShapeFamilies()[pair->family_index].symmetry == RotationalSymmetry::kNone) return *pair;
  }
}

Eigen::Isometry3d Perturbed(const Eigen::Isometry3d& truth, double angle_rad, double shift,
                            std::mt19937_64& rng) {
  std::normal_distribution<double> normal;
  const Eigen::Vector3d axis = Eigen::Vector3d(normal(rng), normal(rng), normal(rng)).normalized();
  const Eigen::Vector3d dir = Eigen::Vector3d(normal(rng), normal(rng), normal(rng)).normalized();
  return MakeTransform(Eigen::AngleAxisd(angle_rad, axis).toRotationMatrix(), shift * dir) * truth;
}

void BM_RefineObject(benchmark::State& state) {
  PairOptions options;
  options.num_points = static_cast<size_t>(state.range(0));
  uint64_t seed = 1;
  const ObjectPair pair = AsymmetricPair(options, seed);
  const Octree source = TreeOf(pair.source, 6);
  const Octree target = TreeOf(pair.target, 6);
  std::mt19937_64 rng(1);
  const Eigen::Isometry3d initial = Perturbed(pair.T_target_source, 10 * kDeg, 0.07, rng);
  TreeRefinementResult last;
  for (auto _ : state) {
    auto result = RefineOnTrees(source, target, initial);
    if (!result.ok()) std::abort();
    last = *std::move(result);
  }
  ReportResult(state, last, pair.T_target_source);
}
BENCHMARK(BM_RefineObject)->ArgName("points")->Arg(1024)->Arg(2048)->Unit(benchmark::kMillisecond);

void ReportSummary(benchmark::State& state, const std::vector<PairError>& errors,
                   const std::vector<RecallThreshold>& thresholds, int valid, double seconds) {
  const ErrorSummary summary = Summarize(errors, thresholds);
  state.counters["pairs"] = summary.count;
  state.counters["rot_rmse_deg"] = summary.rotation_rmse_deg;
  state.counters["rot_median_deg"] = summary.rotation_median_deg;
  state.counters["trans_rmse"] = summary.translation_rmse;
  state.counters["success"] = summary.recall[0];
  state.counters["valid_frac"] = static_cast<double>(valid) / summary.count;
  state.counters["ms_per_pair"] = 1e3 * seconds / summary.count;
}

void ObjectAccuracy(benchmark::State& state, bool from_identity) {
  const double angle = static_cast<double>(state.range(0));
  PairOptions options;
  options.num_points = 2048;
  if (from_identity) options.max_angle_deg = angle;
  std::vector<PairError> errors;
  int valid = 0;
  double seconds = 0.0;
  for (auto _ : state) {
    uint64_t seed = 1000;
    std::mt19937_64 rng(3);
    errors.clear();
    valid = 0;
    seconds = 0.0;
    for (int i = 0; i < 40; ++i) {
      const ObjectPair pair = AsymmetricPair(options, seed);
      const Octree source = TreeOf(pair.source, 6);
      const Octree target = TreeOf(pair.target, 6);
      const Eigen::Isometry3d initial =
          from_identity ? Eigen::Isometry3d::Identity()
                        : Perturbed(pair.T_target_source, angle * kDeg, 0.07, rng);
      auto result = RefineOnTrees(source, target, initial);
      if (!result.ok()) std::abort();
      errors.push_back(ErrorOf(result->T_target_source, pair.T_target_source));
      valid += result->valid;
      seconds += result->total_seconds;
    }
  }
  ReportSummary(state, errors, {{1.0, 0.01}}, valid, seconds);
}

void BM_ObjectAccuracy(benchmark::State& state) { ObjectAccuracy(state, false); }
BENCHMARK(BM_ObjectAccuracy)
    ->ArgName("from_truth_deg")
    ->Arg(5)
    ->Arg(10)
    ->Arg(15)
    ->Arg(20)
    ->Iterations(1)
    ->Unit(benchmark::kMillisecond);

void BM_ObjectBasin(benchmark::State& state) { ObjectAccuracy(state, true); }
BENCHMARK(BM_ObjectBasin)
    ->ArgName("max_angle_deg")
    ->Arg(10)
    ->Arg(20)
    ->Arg(30)
    ->Arg(45)
    ->Iterations(1)
    ->Unit(benchmark::kMillisecond);

void BM_LidarAccuracy(benchmark::State& state) {
  const int depth = static_cast<int>(state.range(0));
  std::vector<PairError> errors;
  int valid = 0;
  double seconds = 0.0;
  for (auto _ : state) {
    errors.clear();
    valid = 0;
    seconds = 0.0;
    for (int i = 0; i + 5 < Drive().frame_count(); i += 5) {
      const Octree target = TreeOf(Thinned(Drive().SimulateFrame(i).cloud, 120'000), depth);
      const Octree source = TreeOf(Thinned(Drive().SimulateFrame(i + 5).cloud, 120'000), depth);
      auto result = RefineOnTrees(source, target, Eigen::Isometry3d::Identity());
      if (!result.ok()) std::abort();
      errors.push_back(ErrorOf(result->T_target_source, TruthOf(i, i + 5)));
      valid += result->valid;
      seconds += result->total_seconds;
    }
  }
  ReportSummary(state, errors, {{1.0, 0.3}}, valid, seconds);
}
BENCHMARK(BM_LidarAccuracy)->ArgName("depth")->Arg(9)->Iterations(1)->Unit(benchmark::kMillisecond);

}  // namespace
}  // namespace rpsr::core

BENCHMARK_MAIN();
