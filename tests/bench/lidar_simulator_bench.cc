// LiDAR simulator throughput: one scan per street style, whole sequences in memory on the
// configured worker threads, and sequences written in the KITTI layout.
//   build/tests/bench/lidar_simulator_bench --benchmark_counters_tabular=true
// The counter frames_per_second counts simulated scans per wall-clock second.
#include <atomic>
#include <filesystem>

#include "benchmark/benchmark.h"
#include "core/data/simulated_kitti.h"
#include "core/synth/lidar_sequence.h"

namespace rpsr::core {
namespace {

void BM_SimulateScan(benchmark::State& state) {
  LidarSequenceOptions options;
  options.style = static_cast<StreetStyle>(state.range(0));
  options.frame_count = 50;
  absl::StatusOr<LidarSequenceSimulator> sequence = LidarSequenceSimulator::Create(options);
  if (!sequence.ok()) {
    state.SkipWithError(std::string(sequence.status().message()).c_str());
    return;
  }
  int frame = 0;
  size_t points = 0;
  for (auto _ : state) {
    const LidarScan scan = sequence->SimulateFrame(frame);
    points += scan.cloud.size();
    frame = (frame + 1) % sequence->frame_count();
  }
  state.SetLabel(StreetStyleName(options.style));
  state.counters["points_per_scan"] =
      benchmark::Counter(static_cast<double>(points), benchmark::Counter::kAvgIterations);
  state.counters["rays_per_second"] = benchmark::Counter(
      static_cast<double>(state.iterations()) * 64 * 2000, benchmark::Counter::kIsRate);
}
BENCHMARK(BM_SimulateScan)->ArgName("style")->DenseRange(0, 3)->Unit(benchmark::kMillisecond);

// Scene generation, drive planning and every frame, on `threads` workers (points discarded).
void BM_SimulateSequence(benchmark::State& state) {
  LidarSequenceOptions options;
  options.frame_count = static_cast<int>(state.range(0));
  options.thread_count = static_cast<int>(state.range(1));
  std::atomic<size_t> points{0};
  for (auto _ : state) {
    absl::StatusOr<LidarSequenceSimulator> sequence = LidarSequenceSimulator::Create(options);
    if (!sequence.ok()) {
      state.SkipWithError(std::string(sequence.status().message()).c_str());
      return;
    }
    absl::Status status = sequence->SimulateAllFrames([&](int, LidarScan scan) {
      points += scan.cloud.size();
      return absl::OkStatus();
    });
    if (!status.ok()) state.SkipWithError(std::string(status.message()).c_str());
  }
  const double frames = static_cast<double>(state.iterations()) * options.frame_count;
  state.counters["frames_per_second"] = benchmark::Counter(frames, benchmark::Counter::kIsRate);
  state.counters["points_per_scan"] = static_cast<double>(points.load()) / frames;
}
BENCHMARK(BM_SimulateSequence)
    ->ArgNames({"frames", "threads"})
    ->Args({30, 1})
    ->Args({30, 2})
    ->Args({300, 2})
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime()
    ->Iterations(1);

// As above, plus writing scans, labels, poses, calib and times to a temporary folder.
void BM_WriteSimulatedKittiSequence(benchmark::State& state) {
  LidarSequenceOptions options;
  options.frame_count = static_cast<int>(state.range(0));
  const std::filesystem::path root =
      std::filesystem::temp_directory_path() / "rpsr_lidar_simulator_bench";
  for (auto _ : state) {
    std::filesystem::remove_all(root);
    absl::StatusOr<SimulatedKittiSummary> summary =
        WriteSimulatedKittiSequence(root.string(), 0, options);
    if (!summary.ok()) state.SkipWithError(std::string(summary.status().message()).c_str());
  }
  std::filesystem::remove_all(root);
  state.counters["frames_per_second"] = benchmark::Counter(
      static_cast<double>(state.iterations()) * options.frame_count, benchmark::Counter::kIsRate);
}
BENCHMARK(BM_WriteSimulatedKittiSequence)
    ->ArgName("frames")
    ->Arg(30)
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime()
    ->Iterations(1);

}  // namespace
}  // namespace rpsr::core

BENCHMARK_MAIN();
