// rpsr train: trains RPSRNet from scratch (or resumes) on a seeded pair protocol and writes the
// weights, the optimizer state and a CSV log to --output.
#include <cmath>
#include <cstdio>
#include <string>
#include <thread>
#include <vector>

#include "absl/flags/flag.h"
#include "absl/strings/numbers.h"
#include "absl/strings/str_format.h"
#include "absl/strings/str_split.h"
#include "client/cli/cli_progress.h"
#include "client/cli/shared_flags.h"
#include "client/cli/subcommands.h"
#include "core/data/training_pairs.h"
#include "core/net/rpsr_net.h"
#include "core/net/trainer.h"
#include "core/registrar/embedded_models.h"

// --protocol, --output, --seed and --num_points are shared with other subcommands
// (shared_flags.cc).
ABSL_FLAG(int, epochs, 40, "epochs to train (a resumed run continues up to this many)");
ABSL_FLAG(int, pairs_per_epoch, 4096, "training pairs per epoch (fresh pairs every epoch)");
ABSL_FLAG(int, validation_pairs, 256, "held-out pairs evaluated after every epoch");
ABSL_FLAG(double, lr, 1e-3, "Adam learning rate");
ABSL_FLAG(std::string, lr_milestones, "",
          "comma-separated epochs after which the rate is multiplied by 0.1 (default: at 60% "
          "and 85% of the epochs)");
ABSL_FLAG(std::string, device, "cpu", "cpu or cuda (when built against a CUDA LibTorch)");
ABSL_FLAG(int, data_threads, 2, "threads generating pairs and building trees");
ABSL_FLAG(bool, resume, true, "continue from the state in --output when present");
ABSL_FLAG(int, embedding_width, 128, "token width E after Tree-to-Voxel");
ABSL_FLAG(int, feedforward_width, 256, "Transformer feed-forward width");
ABSL_FLAG(std::string, conv_widths, "32,64,128", "tree convolution widths at depths 5,4,3");
ABSL_FLAG(double, net_cube_half_length, 0.0,
          "0: the network bins each pair in its target's own cube; > 0: in a cube of this "
          "half-length around the target's centre of mass, points outside dropped (for LiDAR "
          "scenes, e.g. 40 metres; stored in the weights)");
ABSL_FLAG(std::string, init, "",
          "start from these weights instead of fresh ones (fine-tuning): a .rpsrw file or the "
          "name of an embedded model (objects); the architecture is the file's, so the width "
          "flags are ignored and --net_cube_half_length is refused; a run resumed from --output "
          "keeps its own weights");
ABSL_FLAG(double, disturbed_fraction, 0.3,
          "objects: fraction of training pairs with noise, outliers, a crop or jitter");

namespace rpsr::client {
namespace {

absl::StatusOr<std::array<int, 3>> ParseWidths(const std::string& text) {
  std::vector<std::string> parts = absl::StrSplit(text, ',');
  std::array<int, 3> widths;
  if (parts.size() != 3) return absl::InvalidArgumentError("--conv_widths needs three numbers");
  for (int i = 0; i < 3; ++i) {
    if (!absl::SimpleAtoi(parts[i], &widths[i]) || widths[i] < 1) {
      return absl::InvalidArgumentError("--conv_widths needs three positive numbers");
    }
  }
  return widths;
}

// The network training starts from: fresh weights, or --init's (a file or an embedded model).
absl::StatusOr<std::unique_ptr<core::RpsrNet>> InitialNetwork(const core::RpsrNetConfig& config,
                                                              uint64_t seed) {
  const std::string init = absl::GetFlag(FLAGS_init);
  if (init.empty()) return core::RpsrNet::Create(config, seed);
  if (init.find('/') == std::string::npos && init.find('.') == std::string::npos) {
    absl::StatusOr<core::EmbeddedModel> embedded = core::FindEmbeddedModel(init);
    if (!embedded.ok()) return embedded.status();
    return core::RpsrNet::LoadFromBytes(embedded->weights, "embedded model " + init);
  }
  return core::RpsrNet::Load(init);
}

}  // namespace

int RunTrainCommand(const std::vector<std::string>& /*args*/) {
  const std::string output = absl::GetFlag(FLAGS_output);
  if (output.empty()) {
    std::fprintf(stderr, "rpsr train: --output FOLDER is required\n");
    return 2;
  }
  absl::StatusOr<std::array<int, 3>> widths = ParseWidths(absl::GetFlag(FLAGS_conv_widths));
  if (!widths.ok()) {
    std::fprintf(stderr, "rpsr train: %s\n", std::string(widths.status().message()).c_str());
    return 2;
  }
  core::TrainerOptions options;
  options.epochs = absl::GetFlag(FLAGS_epochs);
  options.pairs_per_epoch = absl::GetFlag(FLAGS_pairs_per_epoch);
  options.batch_size = absl::GetFlag(FLAGS_batch_size);
  options.validation_pairs = absl::GetFlag(FLAGS_validation_pairs);
  options.passes = absl::GetFlag(FLAGS_passes) > 0 ? absl::GetFlag(FLAGS_passes) : 3;
  options.learning_rate = absl::GetFlag(FLAGS_lr);
  options.seed = absl::GetFlag(FLAGS_seed);
  options.output_dir = output;
  options.resume = absl::GetFlag(FLAGS_resume);
  options.device = absl::GetFlag(FLAGS_device);
  options.data_threads = absl::GetFlag(FLAGS_data_threads);
  for (absl::string_view m :
       absl::StrSplit(absl::GetFlag(FLAGS_lr_milestones), ',', absl::SkipEmpty())) {
    int epoch = 0;
    if (!absl::SimpleAtoi(m, &epoch)) {
      std::fprintf(stderr, "rpsr train: bad --lr_milestones\n");
      return 2;
    }
    options.lr_milestones.push_back(epoch);
  }

  core::RegistrationPairGenerator train_stream;
  core::RegistrationPairGenerator validation_stream;
  const std::string protocol = absl::GetFlag(FLAGS_protocol);
  const uint64_t seed = options.seed;
  if (protocol == "objects") {
    core::ObjectStreamOptions stream;
    stream.pair.split = core::ObjectSplit::kM2Seen;
    stream.pair.num_points = absl::GetFlag(FLAGS_num_points);
    stream.disturbed_fraction = absl::GetFlag(FLAGS_disturbed_fraction);
    stream.stream_seed = seed * 2;
    train_stream = core::MakeObjectPairStream(stream);
    stream.stream_seed = seed * 2 + 1;  // other objects of the same (seen) classes
    validation_stream = core::MakeObjectPairStream(stream);
  } else if (protocol == "lidar") {
    // LiDAR trees go deeper so that refinement has ~1 m cells; the network reads depths 2..5.
    options.tree_options.max_depth = 8;
    core::LidarStreamOptions stream;
    stream.stream_seed = seed * 2;
    train_stream = core::MakeLidarPairStream(stream);
    stream.stream_seed = seed * 2 + 1;  // other simulated streets
    validation_stream = core::MakeLidarPairStream(stream);
  } else {
    std::fprintf(stderr, "rpsr train: unknown --protocol '%s' (objects or lidar)\n",
                 protocol.c_str());
    return 2;
  }

  core::RpsrNetConfig config;
  config.conv_widths = *widths;
  config.embedding_width = absl::GetFlag(FLAGS_embedding_width);
  config.feedforward_width = absl::GetFlag(FLAGS_feedforward_width);
  config.passes = options.passes;
  config.cube_half_length = absl::GetFlag(FLAGS_net_cube_half_length);
  if (config.cube_half_length != 0.0 && !absl::GetFlag(FLAGS_init).empty()) {
    std::fprintf(stderr,
                 "rpsr train: --net_cube_half_length cannot change a model given by --init (the "
                 "cube is part of its architecture); train from fresh weights instead\n");
    return 2;
  }
  if (!(config.cube_half_length >= 0) || !std::isfinite(config.cube_half_length)) {
    std::fprintf(stderr, "rpsr train: --net_cube_half_length must be >= 0\n");
    return 2;
  }
  absl::StatusOr<std::unique_ptr<core::RpsrNet>> net = InitialNetwork(config, seed);
  if (!net.ok()) {
    std::fprintf(stderr, "rpsr train: %s\n", std::string(net.status().message()).c_str());
    return 1;
  }
  core::SetNetThreads(absl::GetFlag(FLAGS_threads));
  std::fprintf(stderr, "rpsr train: %s protocol, %lld parameters, %d epochs of %d pairs, on %s\n",
               protocol.c_str(), static_cast<long long>((*net)->NumParameters()), options.epochs,
               options.pairs_per_epoch, options.device.c_str());

  ProgressBar bar("train");
  auto on_progress = [&](const core::TrainerProgress& p) {
    bar.Update((p.epoch - 1) * p.batches + p.batch, static_cast<double>(p.epochs) * p.batches,
               p.seconds_remaining,
               absl::StrFormat("epoch %d/%d loss %.4f", p.epoch, p.epochs, p.loss));
  };
  auto on_epoch = [&](const core::EpochRecord& r) {
    bar.Finish();
    std::fprintf(stderr,
                 "epoch %d: loss %.4f  validation rotation RMSE %.3f deg (median %.3f), "
                 "translation RMSE %.4f  [%s]\n",
                 r.epoch, r.train_loss, r.validation_rotation_rmse_deg,
                 r.validation_rotation_median_deg, r.validation_translation_rmse,
                 FormatDuration(r.seconds).c_str());
  };
  absl::StatusOr<std::vector<core::EpochRecord>> records =
      core::TrainRpsrNet(**net, train_stream, validation_stream, options, on_progress, on_epoch);
  if (!records.ok()) {
    std::fprintf(stderr, "rpsr train: %s\n", std::string(records.status().message()).c_str());
    return 1;
  }
  std::fprintf(stderr, "rpsr train: done; best weights in %s/model.rpsrw\n", output.c_str());
  return 0;
}

}  // namespace rpsr::client
