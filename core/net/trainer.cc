#include "core/net/trainer.h"

#include <torch/torch.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <future>
#include <numeric>
#include <optional>
#include <sstream>
#include <thread>

#include "absl/strings/numbers.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_split.h"
#include "core/data/registration_metrics.h"
#include "core/io/file_bytes.h"
#include "core/net/registration_loss.h"
#include "core/net/rpsr_net_impl.h"
#include "core/net/weights_file.h"

namespace rpsr::core {
namespace {

// A pair ready for the network: its trees and the truth.
struct TreePair {
  Octree source;
  Octree target;
  Eigen::Isometry3d T_target_source;
};

// Generates pairs [first, first + count) on `threads` threads; the result depends on the indices
// only, not on the thread count.
absl::StatusOr<std::vector<TreePair>> MakeTreePairs(const TrainingPairGenerator& generator,
                                                    uint64_t first, int count, int threads,
                                                    const BarnesHutTreeOptions& tree_options) {
  std::vector<std::optional<TreePair>> pairs(count);
  std::vector<absl::Status> errors(count);
  std::atomic<int> next{0};
  auto work = [&] {
    for (int i = next++; i < count; i = next++) {
      absl::StatusOr<RegistrationPair> pair = generator(first + i);
      if (!pair.ok()) {
        errors[i] = pair.status();
        continue;
      }
      absl::StatusOr<Octree> source = BuildOctree(pair->source, tree_options);
      absl::StatusOr<Octree> target = BuildOctree(pair->target, tree_options);
      if (!source.ok() || !target.ok()) {
        errors[i] = source.ok() ? target.status() : source.status();
        continue;
      }
      pairs[i] = TreePair{*std::move(source), *std::move(target), pair->T_target_source};
    }
  };
  std::vector<std::thread> pool;
  for (int t = 1; t < std::max(threads, 1); ++t) pool.emplace_back(work);
  work();
  for (std::thread& t : pool) t.join();
  std::vector<TreePair> out;
  out.reserve(count);
  for (int i = 0; i < count; ++i) {
    if (!errors[i].ok()) {
      return absl::Status(errors[i].code(),
                          absl::StrCat("training pair ", first + i, ": ", errors[i].message()));
    }
    out.push_back(*std::move(pairs[i]));
  }
  return out;
}

std::vector<NetPair> AsNetPairs(const std::vector<TreePair>& pairs, size_t begin, size_t end) {
  std::vector<NetPair> out;
  for (size_t i = begin; i < end; ++i) out.push_back({&pairs[i].source, &pairs[i].target});
  return out;
}

struct TrainerState {
  int epochs_done = 0;
  double best_rotation_rmse_deg = 1e30;
};

absl::Status WriteState(const std::string& path, const TrainerState& state, double sigma_r,
                        double sigma_t) {
  return WriteFileBytes(
      path, absl::StrCat("epochs_done=", state.epochs_done,
                         "\nbest_rotation_rmse_deg=", state.best_rotation_rmse_deg,
                         "\nsigma_rotation=", sigma_r, "\nsigma_translation=", sigma_t, "\n"));
}

absl::Status ReadState(const std::string& path, TrainerState& state, double& sigma_r,
                       double& sigma_t) {
  absl::StatusOr<std::string> text = ReadFileBytes(path, 1 << 20);
  if (!text.ok()) return text.status();
  for (absl::string_view line : absl::StrSplit(*text, '\n', absl::SkipEmpty())) {
    std::pair<absl::string_view, absl::string_view> kv = absl::StrSplit(line, '=');
    bool ok = true;
    if (kv.first == "epochs_done") ok = absl::SimpleAtoi(kv.second, &state.epochs_done);
    if (kv.first == "best_rotation_rmse_deg") {
      ok = absl::SimpleAtod(kv.second, &state.best_rotation_rmse_deg);
    }
    if (kv.first == "sigma_rotation") ok = absl::SimpleAtod(kv.second, &sigma_r);
    if (kv.first == "sigma_translation") ok = absl::SimpleAtod(kv.second, &sigma_t);
    if (!ok) return absl::DataLossError(absl::StrCat(path, ": bad line '", line, "'"));
  }
  return absl::OkStatus();
}

// Rotations [B, 3, 3] (rotation = true) or translations [B, 3] of isometries, as float32.
torch::Tensor ToTensor(const std::vector<Eigen::Isometry3d>& estimates, bool rotation) {
  const int64_t b = static_cast<int64_t>(estimates.size());
  torch::Tensor out = torch::empty(
      rotation ? std::vector<int64_t>{b, 3, 3} : std::vector<int64_t>{b, 3}, torch::kFloat32);
  for (int64_t i = 0; i < b; ++i) {
    if (rotation) {
      const Eigen::Matrix<float, 3, 3, Eigen::RowMajor> r = estimates[i].linear().cast<float>();
      std::copy(r.data(), r.data() + 9, out.data_ptr<float>() + i * 9);
    } else {
      const Eigen::Vector3f v = estimates[i].translation().cast<float>();
      std::copy(v.data(), v.data() + 3, out.data_ptr<float>() + i * 3);
    }
  }
  return out;
}

absl::StatusOr<ErrorSummary> Validate(RpsrNet& net, const std::vector<TreePair>& pairs,
                                      int batch_size, int passes) {
  std::vector<PairError> errors;
  for (size_t begin = 0; begin < pairs.size(); begin += batch_size) {
    const size_t end = std::min(pairs.size(), begin + batch_size);
    std::vector<NetPair> batch = AsNetPairs(pairs, begin, end);
    absl::StatusOr<std::vector<NetEstimate>> estimates = net.Estimate(batch, passes);
    if (!estimates.ok()) return estimates.status();
    for (size_t i = begin; i < end; ++i) {
      errors.push_back(ErrorOf((*estimates)[i - begin].T_target_source, pairs[i].T_target_source));
    }
  }
  return Summarize(errors, {});
}

}  // namespace

absl::StatusOr<std::vector<EpochRecord>> TrainRpsrNet(
    RpsrNet& net, const TrainingPairGenerator& train, const TrainingPairGenerator& validation,
    const TrainerOptions& options, const std::function<void(const TrainerProgress&)>& on_progress,
    const std::function<void(const EpochRecord&)>& on_epoch) {
  if (options.output_dir.empty()) {
    return absl::InvalidArgumentError("training needs an output folder (--output)");
  }
  if (options.batch_size < 1 || options.epochs < 0 ||
      options.pairs_per_epoch < options.batch_size || options.passes < 1) {
    return absl::InvalidArgumentError(
        "training needs batch_size >= 1, pairs_per_epoch >= batch_size, passes >= 1");
  }
  std::error_code ec;
  std::filesystem::create_directories(options.output_dir, ec);
  if (ec) {
    return absl::PermissionDeniedError(
        absl::StrCat(options.output_dir, ": cannot create: ", ec.message()));
  }
  const std::string state_path = options.output_dir + "/trainer_state.txt";
  const std::string optimizer_path = options.output_dir + "/optimizer.pt";
  const std::string last_path = options.output_dir + "/last.rpsrw";
  const std::string best_path = options.output_dir + "/model.rpsrw";
  const std::string log_path = options.output_dir + "/training_log.csv";

  try {
    torch::manual_seed(options.seed);
    if (options.deterministic) at::globalContext().setDeterministicAlgorithms(true, true);
    torch::Device device(torch::kCPU);
    if (options.device == "cuda") {
      if (!torch::cuda::is_available()) {
        return absl::FailedPreconditionError(
            "--device cuda asked for, but this LibTorch build sees no CUDA device");
      }
      device = torch::Device(torch::kCUDA);
    } else if (options.device != "cpu") {
      return absl::InvalidArgumentError(absl::StrCat("unknown device '", options.device, "'"));
    }

    RpsrNet::Impl& impl = net.impl();
    TrainerState state;
    double sigma_r0 = 0.0;
    double sigma_t0 = 0.0;
    const bool resuming =
        options.resume && std::filesystem::exists(state_path) && std::filesystem::exists(last_path);
    if (resuming) {
      if (absl::Status s = ReadState(state_path, state, sigma_r0, sigma_t0); !s.ok()) return s;
      // Through the weights file's checks: a run resumed with other architecture flags gets a
      // clear error instead of a mismatched copy.
      absl::StatusOr<std::string> bytes = ReadFileBytes(last_path, size_t{1} << 30);
      if (!bytes.ok()) return bytes.status();
      absl::StatusOr<net::NamedTensors> weights = net::ParseWeights(*bytes, last_path);
      if (!weights.ok()) return weights.status();
      // What the tensors' shapes cannot tell (the cube the inputs are binned in) is compared by
      // the config text, so that a run resumed without the original flags fails clearly instead
      // of training on differently prepared inputs.
      absl::StatusOr<RpsrNetConfig> saved = net::ConfigFromText(weights->config_text);
      if (!saved.ok()) return saved.status();
      if (saved->cube_half_length != impl.config.cube_half_length) {
        return absl::FailedPreconditionError(
            absl::StrCat(last_path, ": saved with cube_half_length ", saved->cube_half_length,
                         " but this run asks for ", impl.config.cube_half_length,
                         "; resume with the flags of the original run or use a new --output"));
      }
      if (absl::Status s = net::LoadTensorsInto(*weights, *impl.network); !s.ok()) {
        return absl::FailedPreconditionError(
            absl::StrCat(last_path, ": ", s.message(),
                         "; resume with the flags of the original run or use a new --output"));
      }
    }
    impl.network->to(device);
    impl.device = device;
    torch::Tensor sigma_r =
        torch::full({1}, sigma_r0, torch::TensorOptions().device(device)).set_requires_grad(true);
    torch::Tensor sigma_t =
        torch::full({1}, sigma_t0, torch::TensorOptions().device(device)).set_requires_grad(true);
    std::vector<torch::Tensor> parameters = impl.network->parameters();
    parameters.push_back(sigma_r);
    parameters.push_back(sigma_t);
    torch::optim::Adam optimizer(
        parameters,
        torch::optim::AdamOptions(options.learning_rate).weight_decay(options.weight_decay));
    if (resuming && std::filesystem::exists(optimizer_path)) {
      torch::load(optimizer, optimizer_path);
    }
    std::vector<int> milestones = options.lr_milestones;
    if (milestones.empty()) {
      milestones = {static_cast<int>(options.epochs * 0.6),
                    static_cast<int>(options.epochs * 0.85)};
    }

    // The validation set is fixed: indices from a range disjoint from training's by the caller's
    // generator (validation is a different generator).
    absl::StatusOr<std::vector<TreePair>> validation_pairs = MakeTreePairs(
        validation, 0, options.validation_pairs, options.data_threads, options.tree_options);
    if (!validation_pairs.ok()) return validation_pairs.status();

    std::ofstream log(log_path, resuming ? std::ios::app : std::ios::trunc);
    if (!resuming) {
      log << "epoch,train_loss,train_rotation_loss,train_translation_loss,"
             "validation_rotation_rmse_deg,validation_rotation_median_deg,"
             "validation_translation_rmse,sigma_rotation,sigma_translation,learning_rate,"
             "skipped_batches,seconds\n";
    }

    const int batches = options.pairs_per_epoch / options.batch_size;
    const auto start = std::chrono::steady_clock::now();
    int batches_done_here = 0;
    const int total_batches_here = (options.epochs - state.epochs_done) * batches;
    std::vector<EpochRecord> records;
    for (int epoch = state.epochs_done + 1; epoch <= options.epochs; ++epoch) {
      const auto epoch_start = std::chrono::steady_clock::now();
      double lr = options.learning_rate;
      for (int m : milestones) {
        if (epoch > m) lr *= options.lr_gamma;
      }
      for (auto& group : optimizer.param_groups()) {
        static_cast<torch::optim::AdamOptions&>(group.options()).lr(lr);
      }
      impl.network->train();
      EpochRecord record;
      record.epoch = epoch;
      record.learning_rate = lr;
      double loss_sum = 0.0;
      double rotation_loss_sum = 0.0;
      double translation_loss_sum = 0.0;
      int stepped = 0;
      // The next batch's pairs are generated while this one trains: on a GPU the step is short
      // and generating synchronously left the device idle most of the time.
      auto make_batch = [&](int b) {
        const uint64_t first = (static_cast<uint64_t>(epoch - 1) * batches + b) *
                               static_cast<uint64_t>(options.batch_size);
        return MakeTreePairs(train, first, options.batch_size, options.data_threads,
                             options.tree_options);
      };
      std::future<absl::StatusOr<std::vector<TreePair>>> next_batch =
          std::async(std::launch::async, make_batch, 0);
      for (int b = 0; b < batches; ++b) {
        absl::StatusOr<std::vector<TreePair>> pairs = next_batch.get();
        if (b + 1 < batches) next_batch = std::async(std::launch::async, make_batch, b + 1);
        if (!pairs.ok()) {
          if (next_batch.valid()) next_batch.wait();
          return pairs.status();
        }
        std::vector<NetPair> batch = AsNetPairs(*pairs, 0, pairs->size());
        std::vector<Eigen::Isometry3d> truths;
        for (const TreePair& pair : *pairs) truths.push_back(pair.T_target_source);
        torch::Tensor R_gt = ToTensor(truths, true).to(device);
        torch::Tensor t_gt = ToTensor(truths, false).to(device);

        absl::StatusOr<net::PackedClouds> targets =
            net::PackTargets(batch, impl.config.cube_half_length);
        if (!targets.ok()) return targets.status();
        const net::PackedClouds target = targets->To(device);
        const net::EncodedTarget encoded_target = impl.network->EncodeTarget(target);
        std::vector<Eigen::Isometry3d> estimates(batch.size(), Eigen::Isometry3d::Identity());
        torch::Tensor loss = torch::zeros({1}, torch::TensorOptions().device(device));
        torch::Tensor rotation_loss, translation_loss;
        for (int pass = 1; pass <= options.passes; ++pass) {
          absl::StatusOr<net::PackedClouds> sources =
              net::PackMovedSources(batch, estimates, impl.config.cube_half_length);
          if (!sources.ok()) return sources.status();
          net::PassOutput out = impl.network->Pass(sources->To(device), target, encoded_target);
          // Compose with the (constant) estimate so far: T_k = step o T_{k-1}.
          torch::Tensor R_prev = ToTensor(estimates, true).to(device);
          torch::Tensor t_prev = ToTensor(estimates, false).to(device);
          torch::Tensor R = torch::matmul(out.rotation, R_prev);
          torch::Tensor t =
              torch::matmul(out.rotation, t_prev.unsqueeze(-1)).squeeze(-1) + out.translation;
          net::PassLoss pass_loss = net::RegistrationPassLoss(R, t, R_gt, t_gt, sigma_r, sigma_t);
          rotation_loss = pass_loss.rotation;
          translation_loss = pass_loss.translation;
          loss = loss + net::PassWeight(pass) * pass_loss.combined;
          estimates = net::ToIsometries(R, t);
        }
        const double loss_value = loss.item<double>();
        if (std::isfinite(loss_value)) {
          optimizer.zero_grad();
          loss.backward();
          // The total norm is non-finite iff some gradient is: one device sync instead of one
          // per parameter tensor.
          const double grad_norm =
              torch::nn::utils::clip_grad_norm_(parameters, options.gradient_clip_norm);
          if (std::isfinite(grad_norm)) {
            optimizer.step();
            loss_sum += loss_value;
            rotation_loss_sum += rotation_loss.item<double>();
            translation_loss_sum += translation_loss.item<double>();
            ++stepped;
          } else {
            ++record.skipped_batches;
          }
        } else {
          ++record.skipped_batches;
        }
        ++batches_done_here;
        if (on_progress) {
          TrainerProgress progress;
          progress.epoch = epoch;
          progress.epochs = options.epochs;
          progress.batch = b + 1;
          progress.batches = batches;
          progress.loss = stepped > 0 ? loss_sum / stepped : loss_value;
          progress.seconds_elapsed =
              std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
          progress.seconds_remaining = progress.seconds_elapsed / batches_done_here *
                                       (total_batches_here - batches_done_here);
          on_progress(progress);
        }
      }
      record.train_loss = stepped > 0 ? loss_sum / stepped : NAN;
      record.train_rotation_loss = stepped > 0 ? rotation_loss_sum / stepped : NAN;
      record.train_translation_loss = stepped > 0 ? translation_loss_sum / stepped : NAN;
      record.sigma_rotation = sigma_r.item<double>();
      record.sigma_translation = sigma_t.item<double>();

      impl.network->eval();
      absl::StatusOr<ErrorSummary> errors =
          Validate(net, *validation_pairs, options.batch_size, options.passes);
      if (!errors.ok()) return errors.status();
      record.validation_rotation_rmse_deg = errors->rotation_rmse_deg;
      record.validation_rotation_median_deg = errors->rotation_median_deg;
      record.validation_translation_rmse = errors->translation_rmse;
      record.seconds =
          std::chrono::duration<double>(std::chrono::steady_clock::now() - epoch_start).count();

      // Portable weights always on the CPU side of the file format; state last, so that a crash
      // between the writes resumes from the previous epoch's consistent set.
      if (absl::Status s = net.Save(last_path); !s.ok()) return s;
      if (errors->rotation_rmse_deg < state.best_rotation_rmse_deg) {
        state.best_rotation_rmse_deg = errors->rotation_rmse_deg;
        if (absl::Status s = net.Save(best_path); !s.ok()) return s;
      }
      torch::save(optimizer, optimizer_path);
      state.epochs_done = epoch;
      if (absl::Status s =
              WriteState(state_path, state, record.sigma_rotation, record.sigma_translation);
          !s.ok()) {
        return s;
      }
      log << record.epoch << "," << record.train_loss << "," << record.train_rotation_loss << ","
          << record.train_translation_loss << "," << record.validation_rotation_rmse_deg << ","
          << record.validation_rotation_median_deg << "," << record.validation_translation_rmse
          << "," << record.sigma_rotation << "," << record.sigma_translation << ","
          << record.learning_rate << "," << record.skipped_batches << "," << record.seconds << "\n";
      log.flush();
      records.push_back(record);
      if (on_epoch) on_epoch(record);
    }
    impl.network->eval();
    return records;
  } catch (const c10::Error& e) {
    return absl::InternalError(absl::StrCat("training failed: ", e.what_without_backtrace()));
  }
}

}  // namespace rpsr::core
