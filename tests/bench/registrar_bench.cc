// The whole registration pipeline (issue 5), trees given, one thread: milliseconds per pair of
// Registrar::Register for 2,048-point object pairs (trees to depth 6) and 120k-point simulated
// LiDAR pairs five frames apart (trees to depth 9, ~0.5 m cells), in each mode, and per stage
// (network, refinement, confidence) as counters, with `starts` (the refinements the registrar ran
// per pair, RegistrationResult::starts: 1.2 on the objects, so the refinement's time is mostly
// one start's; session 38). The goal for net+refine: at most 10 ms
// for objects and 25 ms for LiDAR scans. The *SmallModel rows run the same object pairs through
// the embedded objects-small model (core/models/objects-small: a quarter of the default's
// convolution FLOPs) and report an error when it is not embedded. The *SensorAlignedSlide and
// *SlowMotion rows time net+refine and refine with and without the sensor-aligned check on
// held-out pairs where it runs (refine: the check doubts the slides, refining the other start);
// the *Gears rows net+refine with and without the symmetric start on gears, where it runs.
//
//   OMP_WAIT_POLICY=PASSIVE build/tests/bench/registrar_bench --benchmark_counters_tabular=true
#include <cstdlib>
#include <functional>
#include <map>
#include <memory>
#include <string>
#include <vector>

#include "benchmark/benchmark.h"
#include "core/data/object_pairs.h"
#include "core/net/rpsr_net.h"
#include "core/refine/symmetry_starts.h"
#include "core/registrar/confidence_calibration.h"
#include "core/registrar/embedded_models.h"
#include "core/registrar/registrar.h"
#include "core/synth/lidar_sequence.h"
#include "tests/bench/bench_clouds.h"
#include "tests/bench/blas_benchmark_main.h"

namespace rpsr::core {
namespace {

// One registrar per embedded model, made on first use (nullptr when the model is not embedded).
const Registrar* RegistrarWithModel(const std::string& model) {
  static std::map<std::string, const Registrar*>* registrars =
      new std::map<std::string, const Registrar*>();
  auto it = registrars->find(model);
  if (it != registrars->end()) return it->second;
  SetNetThreads(1);
  RegistrarConfig config;
  config.model = model;
  auto created = Registrar::Create(config);
  const Registrar* registrar = created.ok() ? created->release() : nullptr;
  registrars->emplace(model, registrar);
  return registrar;
}

const Registrar& SharedRegistrar() {
  const Registrar* registrar = RegistrarWithModel(std::string(kDefaultEmbeddedModel));
  if (registrar == nullptr) std::abort();
  return *registrar;
}

constexpr char kSmallModel[] = "objects-small";

struct TreePairs {
  std::vector<Octree> trees;  // source, target, source, target, ...
  size_t size() const { return trees.size() / 2; }
};

BarnesHutTreeOptions ToDepth(int max_depth) {
  BarnesHutTreeOptions options;
  options.max_depth = max_depth;
  return options;
}

const TreePairs& ObjectTrees() {
  static const TreePairs* pairs =
      new TreePairs{bench::TreesOf(bench::UnseenObjectClouds(16, 2048), ToDepth(6))};
  return *pairs;
}

// The same objects with their sources jittered by 0.08 (where the noise polish runs).
const TreePairs& JitteredObjectTrees() {
  static const TreePairs* pairs =
      new TreePairs{bench::TreesOf(bench::UnseenObjectClouds(16, 2048, 4), ToDepth(6))};
  return *pairs;
}

const TreePairs& LidarTrees() {
  static const TreePairs* pairs = [] {
    LidarSequenceOptions options;
    options.frame_count = 40;
    options.seed = 1;
    options.sensor.azimuth_steps = 2400;  // ~140k points, thinned to 120k
    return new TreePairs{
        bench::TreesOf(bench::LidarCloudsFiveFramesApart(4, options, 120000), ToDepth(9))};
  }();
  return *pairs;
}

// Pairs of the held-out LiDAR stream (pair seed `pair_seed`, `frame_offset` frames apart, the
// streams of `rpsr calibrate --evaluate`), full resolution, trees to depth 9.
TreePairs HeldOutLidarTrees(uint64_t pair_seed, int frame_offset, const std::vector<int>& indices) {
  const RegistrationPairGenerator pairs = CalibrationLidarPairs(pair_seed, frame_offset);
  std::vector<PointCloud> clouds;
  for (int index : indices) {
    RegistrationPair pair = bench::OrDie(pairs(static_cast<uint64_t>(index)), "LiDAR pair");
    clouds.push_back(std::move(pair.source));
    clouds.push_back(std::move(pair.target));
  }
  return TreePairs{bench::TreesOf(clouds, ToDepth(9))};
}

// Two parking-lot pairs 5 frames apart (7 m) whose answer, without the sensor-aligned check,
// slides to the identity translation at confidence 0.99: the check searches and refines a
// further start (RegistrationOptions::check_sensor_aligned_answers).
const TreePairs& SensorAlignedSlideTrees() {
  static const TreePairs* pairs = new TreePairs{HeldOutLidarTrees(5003, 5, {26, 27})};
  return *pairs;
}

// Pairs 1 frame apart (under 1.5 m), right answers within a search cell of the identity: the check
// classifies both trees and searches, and its candidate lands near the answer (no refinement).
const TreePairs& SlowMotionLidarTrees() {
  static const TreePairs* pairs = new TreePairs{HeldOutLidarTrees(5003, 1, {56, 57, 58, 60})};
  return *pairs;
}

// Two pairs 10 frames apart at junctions (the vehicle turns 54-69 degrees): no start but the
// search over every turn reaches them, after every other start ended unconfident.
const TreePairs& JunctionTurnLidarTrees() {
  static const TreePairs* pairs = new TreePairs{HeldOutLidarTrees(7003, 10, {24, 58})};
  return *pairs;
}

// `prepared`: each target prepared once beforehand (Registrar::PrepareTarget), as a caller that
// registers many sources against one reference would; the preparation is not timed.
// `refinement`: the refinement's options (the *FinestAlone and *CoarseOneCell rows turn one of its
// choices off to measure what it costs). `adjust`: other options a row turns off (a later start).
void RunRegister(benchmark::State& state, const TreePairs& trees, bool prepared = false,
                 const Registrar& registrar = SharedRegistrar(),
                 const TreeRefinementOptions& refinement = {},
                 const std::function<void(RegistrationOptions&)>& adjust = {}) {
  RegistrationOptions options;
  options.mode = static_cast<RegistrationMode>(state.range(0));
  options.refinement = refinement;
  if (adjust) adjust(options);
  std::vector<std::shared_ptr<const PreparedTarget>> targets;
  for (size_t i = 0; prepared && i < trees.size(); ++i) {
    auto target = registrar.PrepareTarget(trees.trees[2 * i + 1]);
    if (!target.ok()) {
      state.SkipWithError("prepare failed");
      return;
    }
    targets.push_back(*std::move(target));
  }
  size_t k = 0;
  double net = 0.0, refine = 0.0, confidence = 0.0, valid = 0.0, starts = 0.0;
  for (auto _ : state) {
    const size_t i = k++ % trees.size();
    auto result = prepared
                      ? registrar.Register(trees.trees[2 * i], *targets[i], options)
                      : registrar.Register(trees.trees[2 * i], trees.trees[2 * i + 1], options);
    if (!result.ok()) {
      state.SkipWithError("register failed");
      break;
    }
    net += result->timings.net_seconds;
    refine += result->timings.refine_seconds;
    confidence += result->timings.confidence_seconds;
    valid += result->valid;
    starts += result->starts;
    benchmark::DoNotOptimize(result);
  }
  const double n = static_cast<double>(std::max<int64_t>(1, state.iterations()));
  state.counters["net_ms"] = 1e3 * net / n;
  state.counters["refine_ms"] = 1e3 * refine / n;
  state.counters["confidence_ms"] = 1e3 * confidence / n;
  state.counters["valid"] = valid / n;
  state.counters["starts"] = starts / n;
  state.SetLabel(std::string(RegistrationModeName(options.mode)));
}

void BM_RegisterObjects(benchmark::State& state) { RunRegister(state, ObjectTrees()); }
BENCHMARK(BM_RegisterObjects)
    ->ArgName("mode")
    ->Arg(static_cast<int>(RegistrationMode::kNetRefine))
    ->Arg(static_cast<int>(RegistrationMode::kNet))
    ->Arg(static_cast<int>(RegistrationMode::kRefine))
    ->Unit(benchmark::kMillisecond);

// The same pairs with the finest depth refined alone (no coarser depth in the finest stage).
TreeRefinementOptions FinestAlone() {
  TreeRefinementOptions options;
  options.joint_finest_stage = false;
  return options;
}
// The same pairs with the coarse stages searching as the finest does (one cell, 2x2x2 block)
// instead of two cells in the 3x3x3 block (TreeRefinementOptions::coarse_*).
TreeRefinementOptions CoarseOneCell() {
  TreeRefinementOptions options;
  SearchCoarseStagesAsTheFinest(options);
  return options;
}

// The same pairs without the noise polish (TreeRefinementOptions::noise_polish): on clean pairs
// it never runs, so the difference is its scatter measurement.
TreeRefinementOptions NoNoisePolish() {
  TreeRefinementOptions options;
  options.noise_polish = false;
  return options;
}

void BM_RegisterObjectsNoNoisePolish(benchmark::State& state) {
  RunRegister(state, ObjectTrees(), false, SharedRegistrar(), NoNoisePolish());
}
BENCHMARK(BM_RegisterObjectsNoNoisePolish)
    ->ArgName("mode")
    ->Arg(static_cast<int>(RegistrationMode::kNetRefine))
    ->Arg(static_cast<int>(RegistrationMode::kRefine))
    ->Unit(benchmark::kMillisecond);

// net+refine with every network pass run before refining (later_passes:0, the pipeline before
// session 32) and with the later passes only for an unconfident first answer (later_passes:1,
// the default: RegistrationOptions::later_passes_only_when_unconfident), on the objects
// (pairs:0), their jittered copies (pairs:2) and the scans (pairs:1).
void BM_RegisterLaterPasses(benchmark::State& state) {
  const int64_t kind = state.range(1);
  const bool later = state.range(2) != 0;
  const TreePairs& trees =
      kind == 1 ? LidarTrees() : (kind == 2 ? JitteredObjectTrees() : ObjectTrees());
  RunRegister(state, trees, false, SharedRegistrar(), {}, [later](RegistrationOptions& options) {
    options.later_passes_only_when_unconfident = later;
  });
}
BENCHMARK(BM_RegisterLaterPasses)
    ->ArgNames({"mode", "pairs", "later_passes"})
    ->ArgsProduct({{static_cast<int>(RegistrationMode::kNetRefine)}, {0, 2, 1}, {0, 1}})
    ->Unit(benchmark::kMillisecond);

// net+refine with the weak-direction start's two rounds (weak:2:
// RegistrationOptions::search_weak_direction_start and weak_direction_finest_round), its first
// round alone (weak:1, the default) and without it (weak:0), on the objects (pairs:0) and their
// jittered copies (pairs:2): its cost is the scoring of ten steps along the answer's weakest
// direction on every object pair without near-symmetries (at the finest depth too for clean, whole
// answers where the first round kept nothing), and a refinement where one leaves clearly fewer
// nodes without a partner.
void BM_RegisterWeakDirectionStart(benchmark::State& state) {
  const int64_t weak = state.range(2);
  const TreePairs& trees = state.range(1) == 2 ? JitteredObjectTrees() : ObjectTrees();
  RunRegister(state, trees, false, SharedRegistrar(), {}, [weak](RegistrationOptions& options) {
    options.search_weak_direction_start = weak >= 1;
    options.weak_direction_finest_round = weak >= 2;
  });
}
BENCHMARK(BM_RegisterWeakDirectionStart)
    ->ArgNames({"mode", "pairs", "weak"})
    ->ArgsProduct({{static_cast<int>(RegistrationMode::kNetRefine)}, {0, 2}, {0, 1, 2}})
    ->Unit(benchmark::kMillisecond);

// Registers the objects (pairs:0) or their jittered copies (pairs:2) with one of the registrar's
// on/off switches set to the third argument (0 or 1): the start benchmarks below.
void RunObjectsWithSwitch(benchmark::State& state, bool RegistrationOptions::*on_off) {
  const bool on = state.range(2) != 0;
  const TreePairs& trees = state.range(1) == 2 ? JitteredObjectTrees() : ObjectTrees();
  RunRegister(state, trees, false, SharedRegistrar(), {},
              [on, on_off](RegistrationOptions& options) { options.*on_off = on; });
}

// net+refine with the centroid-aligned start (centroid:1, the default:
// RegistrationOptions::search_centroid_start) and without (centroid:0), on the objects (pairs:0)
// and their jittered copies (pairs:2): a refinement more for each unconfident answer that leaves
// the clouds' centres of mass apart.
void BM_RegisterCentroidStart(benchmark::State& state) {
  RunObjectsWithSwitch(state, &RegistrationOptions::search_centroid_start);
}
BENCHMARK(BM_RegisterCentroidStart)
    ->ArgNames({"mode", "pairs", "centroid"})
    ->ArgsProduct({{static_cast<int>(RegistrationMode::kNetRefine)}, {0, 2}, {0, 1}})
    ->Unit(benchmark::kMillisecond);

// net+refine with the principal-axes start (pa:1, the default:
// RegistrationOptions::search_principal_axes_start) and without (pa:0), on the objects (pairs:0)
// and their jittered copies (pairs:2): four poses scored and two refinements for each valid answer
// that fits under 80% and reads below 0.5.
void BM_RegisterPrincipalAxesStart(benchmark::State& state) {
  RunObjectsWithSwitch(state, &RegistrationOptions::search_principal_axes_start);
}
BENCHMARK(BM_RegisterPrincipalAxesStart)
    ->ArgNames({"mode", "pairs", "pa"})
    ->ArgsProduct({{static_cast<int>(RegistrationMode::kNetRefine)}, {0, 2}, {0, 1}})
    ->Unit(benchmark::kMillisecond);

// net+refine with the extent slide (slide:1, the default: RegistrationOptions::search_extent_slide)
// and without (slide:0), on the objects (pairs:0) and their jittered copies (pairs:2): six extent
// reads of the finest nodes for each valid answer without near-symmetries, and one measurement at
// the moved pose where both ends agree.
void BM_RegisterExtentSlide(benchmark::State& state) {
  RunObjectsWithSwitch(state, &RegistrationOptions::search_extent_slide);
}
BENCHMARK(BM_RegisterExtentSlide)
    ->ArgNames({"mode", "pairs", "slide"})
    ->ArgsProduct({{static_cast<int>(RegistrationMode::kNetRefine)}, {0, 2}, {0, 1}})
    ->Unit(benchmark::kMillisecond);

// net+refine with the weak-direction chamfer (chamfer:1, the default:
// RegistrationOptions::search_weak_direction_chamfer) and without (chamfer:0), on the objects
// (pairs:0) and their jittered copies (pairs:2): for answers inside its gates, 13 poses' weighted
// node distances both ways at the finest depth, and one measurement where it moves the answer.
void BM_RegisterWeakDirectionChamfer(benchmark::State& state) {
  RunObjectsWithSwitch(state, &RegistrationOptions::search_weak_direction_chamfer);
}
BENCHMARK(BM_RegisterWeakDirectionChamfer)
    ->ArgNames({"mode", "pairs", "chamfer"})
    ->ArgsProduct({{static_cast<int>(RegistrationMode::kNetRefine)}, {0, 2}, {0, 1}})
    ->Unit(benchmark::kMillisecond);

// net+refine with the half-turn start (half:1, the default: RegistrationOptions::
// search_half_turn_start) and without (half:0), on the objects (pairs:0) and their jittered copies
// (pairs:2): for answers fitting below 0.95, four poses' two-way far fractions, and a refinement
// for each half turn under which the target nearly maps onto itself.
void BM_RegisterHalfTurnStart(benchmark::State& state) {
  RunObjectsWithSwitch(state, &RegistrationOptions::search_half_turn_start);
}
BENCHMARK(BM_RegisterHalfTurnStart)
    ->ArgNames({"mode", "pairs", "half"})
    ->ArgsProduct({{static_cast<int>(RegistrationMode::kNetRefine)}, {0, 2}, {0, 1}})
    ->Unit(benchmark::kMillisecond);

// net+refine with the round-axis start's screw turns (screw:1, the default: RegistrationOptions::
// round_axis_screw_turns) and without (screw:0), on the objects (pairs:0) and their jittered
// copies (pairs:2): where the round-axis start runs, one lean self-registration of the target and
// 23 more poses' two-way far fractions when it shows a screw.
void BM_RegisterScrewTurns(benchmark::State& state) {
  RunObjectsWithSwitch(state, &RegistrationOptions::round_axis_screw_turns);
}
BENCHMARK(BM_RegisterScrewTurns)
    ->ArgNames({"mode", "pairs", "screw"})
    ->ArgsProduct({{static_cast<int>(RegistrationMode::kNetRefine)}, {0, 2}, {0, 1}})
    ->Unit(benchmark::kMillisecond);

// net+refine with the far-count valley (valley:1, the default: RegistrationOptions::
// search_far_valley) and without (valley:0), on the objects (pairs:0) and their jittered copies
// (pairs:2): for answers inside the chamfer's gates, 49 poses' two-way far fractions one depth
// above the finest, and one measurement where it moves the answer.
void BM_RegisterFarValley(benchmark::State& state) {
  RunObjectsWithSwitch(state, &RegistrationOptions::search_far_valley);
}
BENCHMARK(BM_RegisterFarValley)
    ->ArgNames({"mode", "pairs", "valley"})
    ->ArgsProduct({{static_cast<int>(RegistrationMode::kNetRefine)}, {0, 2}, {0, 1}})
    ->Unit(benchmark::kMillisecond);

// Objects jittered by 0.08, with the noise polish (polish:1) and without (polish:0).
void BM_RegisterJitteredObjects(benchmark::State& state) {
  RunRegister(state, JitteredObjectTrees(), false, SharedRegistrar(),
              state.range(1) ? TreeRefinementOptions{} : NoNoisePolish());
}
BENCHMARK(BM_RegisterJitteredObjects)
    ->ArgNames({"mode", "polish"})
    ->Args({static_cast<int>(RegistrationMode::kNetRefine), 1})
    ->Args({static_cast<int>(RegistrationMode::kNetRefine), 0})
    ->Unit(benchmark::kMillisecond);

void BM_RegisterObjectsFinestAlone(benchmark::State& state) {
  RunRegister(state, ObjectTrees(), false, SharedRegistrar(), FinestAlone());
}
BENCHMARK(BM_RegisterObjectsFinestAlone)
    ->ArgName("mode")
    ->Arg(static_cast<int>(RegistrationMode::kNetRefine))
    ->Arg(static_cast<int>(RegistrationMode::kRefine))
    ->Unit(benchmark::kMillisecond);

void BM_RegisterObjectsCoarseOneCell(benchmark::State& state) {
  RunRegister(state, ObjectTrees(), false, SharedRegistrar(), CoarseOneCell());
}
BENCHMARK(BM_RegisterObjectsCoarseOneCell)
    ->ArgName("mode")
    ->Arg(static_cast<int>(RegistrationMode::kNetRefine))
    ->Arg(static_cast<int>(RegistrationMode::kRefine))
    ->Unit(benchmark::kMillisecond);

// Many sources against one reference: the target's network encoding and refinement side done
// once.
void BM_RegisterObjectsPreparedTarget(benchmark::State& state) {
  RunRegister(state, ObjectTrees(), /*prepared=*/true);
}
BENCHMARK(BM_RegisterObjectsPreparedTarget)
    ->ArgName("mode")
    ->Arg(static_cast<int>(RegistrationMode::kNetRefine))
    ->Arg(static_cast<int>(RegistrationMode::kNet))
    ->Arg(static_cast<int>(RegistrationMode::kRefine))
    ->Unit(benchmark::kMillisecond);

// The same pairs through the smaller embedded model (its own confidence calibration).
void RunSmallModel(benchmark::State& state, bool prepared) {
  const Registrar* small = RegistrarWithModel(kSmallModel);
  if (small == nullptr) {
    state.SkipWithError("objects-small is not embedded (core/models/objects-small/model.rpsrw)");
    return;
  }
  RunRegister(state, ObjectTrees(), prepared, *small);
}
void BM_RegisterObjectsSmallModel(benchmark::State& state) { RunSmallModel(state, false); }
BENCHMARK(BM_RegisterObjectsSmallModel)
    ->ArgName("mode")
    ->Arg(static_cast<int>(RegistrationMode::kNetRefine))
    ->Arg(static_cast<int>(RegistrationMode::kNet))
    ->Unit(benchmark::kMillisecond);
void BM_RegisterObjectsSmallModelPreparedTarget(benchmark::State& state) {
  RunSmallModel(state, true);
}
BENCHMARK(BM_RegisterObjectsSmallModelPreparedTarget)
    ->ArgName("mode")
    ->Arg(static_cast<int>(RegistrationMode::kNetRefine))
    ->Unit(benchmark::kMillisecond);

// What preparing a target costs (Registrar::PrepareTarget): arg 1 with the network's encoding,
// 0 the refinement's side alone (what the service prepares for mode refine).
void RunPrepare(benchmark::State& state, const TreePairs& trees) {
  const Registrar& registrar = SharedRegistrar();
  const bool for_network = state.range(0) != 0;
  size_t k = 0;
  double bytes = 0.0;
  for (auto _ : state) {
    const size_t i = k++ % trees.size();
    auto prepared = registrar.PrepareTarget(trees.trees[2 * i + 1], for_network);
    if (!prepared.ok()) {
      state.SkipWithError("prepare failed");
      break;
    }
    bytes += static_cast<double>((*prepared)->bytes());
    benchmark::DoNotOptimize(prepared);
  }
  state.counters["KB"] =
      bytes / 1024.0 / static_cast<double>(std::max<int64_t>(1, state.iterations()));
}
void BM_PrepareObjectTarget(benchmark::State& state) { RunPrepare(state, ObjectTrees()); }
BENCHMARK(BM_PrepareObjectTarget)
    ->ArgName("network")
    ->Arg(1)
    ->Arg(0)
    ->Unit(benchmark::kMillisecond);
void BM_PrepareLidarTarget(benchmark::State& state) { RunPrepare(state, LidarTrees()); }
BENCHMARK(BM_PrepareLidarTarget)->ArgName("network")->Arg(1)->Arg(0)->Unit(benchmark::kMillisecond);

void BM_RegisterLidar(benchmark::State& state) { RunRegister(state, LidarTrees()); }
BENCHMARK(BM_RegisterLidar)
    ->ArgName("mode")
    ->Arg(static_cast<int>(RegistrationMode::kNetRefine))
    ->Arg(static_cast<int>(RegistrationMode::kNet))
    ->Arg(static_cast<int>(RegistrationMode::kRefine))
    ->Unit(benchmark::kMillisecond);

void BM_RegisterLidarNoNoisePolish(benchmark::State& state) {
  RunRegister(state, LidarTrees(), false, SharedRegistrar(), NoNoisePolish());
}
BENCHMARK(BM_RegisterLidarNoNoisePolish)
    ->ArgName("mode")
    ->Arg(static_cast<int>(RegistrationMode::kNetRefine))
    ->Unit(benchmark::kMillisecond);

void BM_RegisterLidarFinestAlone(benchmark::State& state) {
  RunRegister(state, LidarTrees(), false, SharedRegistrar(), FinestAlone());
}
BENCHMARK(BM_RegisterLidarFinestAlone)
    ->ArgName("mode")
    ->Arg(static_cast<int>(RegistrationMode::kNetRefine))
    ->Arg(static_cast<int>(RegistrationMode::kRefine))
    ->Unit(benchmark::kMillisecond);

void BM_RegisterLidarCoarseOneCell(benchmark::State& state) {
  RunRegister(state, LidarTrees(), false, SharedRegistrar(), CoarseOneCell());
}
BENCHMARK(BM_RegisterLidarCoarseOneCell)
    ->ArgName("mode")
    ->Arg(static_cast<int>(RegistrationMode::kNetRefine))
    ->Arg(static_cast<int>(RegistrationMode::kRefine))
    ->Unit(benchmark::kMillisecond);

// The sensor-aligned check's rows: net+refine and refine, each with `check` 1 (the default) or 0.
std::function<void(RegistrationOptions&)> CheckSensorAlignedAnswers(bool check) {
  return [check](RegistrationOptions& options) { options.check_sensor_aligned_answers = check; };
}

void ModesWithAndWithoutTheCheck(benchmark::internal::Benchmark* b) {
  b->ArgNames({"mode", "check"});
  for (RegistrationMode mode : {RegistrationMode::kNetRefine, RegistrationMode::kRefine}) {
    for (int check : {1, 0}) b->Args({static_cast<int>(mode), check});
  }
}

// The sensor-aligned check's cost where it runs.
void BM_RegisterLidarSensorAlignedSlide(benchmark::State& state) {
  RunRegister(state, SensorAlignedSlideTrees(), false, SharedRegistrar(), {},
              CheckSensorAlignedAnswers(state.range(1) != 0));
}
BENCHMARK(BM_RegisterLidarSensorAlignedSlide)
    ->Apply(ModesWithAndWithoutTheCheck)
    ->Unit(benchmark::kMillisecond);

// The headline pairs (about 3 m apart, within a search cell: the check classifies and searches)
// without it.
void BM_RegisterLidarNoSensorAlignedCheck(benchmark::State& state) {
  RunRegister(state, LidarTrees(), false, SharedRegistrar(), {}, CheckSensorAlignedAnswers(false));
}
BENCHMARK(BM_RegisterLidarNoSensorAlignedCheck)
    ->ArgName("mode")
    ->Arg(static_cast<int>(RegistrationMode::kNetRefine))
    ->Unit(benchmark::kMillisecond);

void BM_RegisterLidarSlowMotion(benchmark::State& state) {
  RunRegister(state, SlowMotionLidarTrees(), false, SharedRegistrar(), {},
              CheckSensorAlignedAnswers(state.range(1) != 0));
}
BENCHMARK(BM_RegisterLidarSlowMotion)
    ->Apply(ModesWithAndWithoutTheCheck)
    ->Unit(benchmark::kMillisecond);

// Gears (unseen-class object pairs of 2,048 points whose target has near-symmetries, pair seeds
// 100, 101, ...): what the symmetric start costs where it runs (symmetric:1) against the same
// pairs without it (symmetric:0). It finds both clouds' breaking nodes, and refines one more start
// when a twin's meet clearly better (a tooth off).
const TreePairs& GearTrees() {
  static const TreePairs* pairs = [] {
    PairOptions options;
    options.num_points = 2048;
    options.split = ObjectSplit::kM2Unseen;
    std::vector<PointCloud> clouds;
    for (uint64_t seed = 100; seed < 1000 && clouds.size() < 8; ++seed) {
      ObjectPair pair = bench::OrDie(MakeObjectPair(options, seed), "object pair");
      const Octree target = bench::OrDie(BuildOctree(pair.target, ToDepth(6)), "tree");
      if (FindSelfSymmetries(target).empty()) continue;
      clouds.push_back(std::move(pair.source));
      clouds.push_back(std::move(pair.target));
    }
    return new TreePairs{bench::TreesOf(clouds, ToDepth(6))};
  }();
  return *pairs;
}

void BM_RegisterGears(benchmark::State& state) {
  const bool symmetric = state.range(1) != 0;
  RunRegister(
      state, GearTrees(), false, SharedRegistrar(), {},
      [symmetric](RegistrationOptions& options) { options.try_symmetric_starts = symmetric; });
}
BENCHMARK(BM_RegisterGears)
    ->ArgNames({"mode", "symmetric"})
    ->Args({static_cast<int>(RegistrationMode::kNetRefine), 1})
    ->Args({static_cast<int>(RegistrationMode::kNetRefine), 0})
    ->Unit(benchmark::kMillisecond);

// What a junction's turn costs net+refine: every start, the search over every turn included.
void BM_RegisterLidarJunctionTurn(benchmark::State& state) {
  RunRegister(state, JunctionTurnLidarTrees());
}
BENCHMARK(BM_RegisterLidarJunctionTurn)
    ->ArgName("mode")
    ->Arg(static_cast<int>(RegistrationMode::kNetRefine))
    ->Unit(benchmark::kMillisecond);

// Many scans against one reference scan (a map, the last frame of a stream).
void BM_RegisterLidarPreparedTarget(benchmark::State& state) {
  RunRegister(state, LidarTrees(), /*prepared=*/true);
}
BENCHMARK(BM_RegisterLidarPreparedTarget)
    ->ArgName("mode")
    ->Arg(static_cast<int>(RegistrationMode::kNetRefine))
    ->Arg(static_cast<int>(RegistrationMode::kRefine))
    ->Unit(benchmark::kMillisecond);

}  // namespace
}  // namespace rpsr::core

RPSR_BENCHMARK_MAIN_WITH_BLAS();
