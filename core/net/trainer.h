// End-to-end training of RPSRNet (paper Sec. 3.3, Eq. 6).
//
// Loss of pass k (k = 1..K) on the composed estimate (R_k, t_k) of T_target_source:
//   L_k = exp(-s_R) ||R_k^T R_gt - I||^2 + s_R + exp(-s_t) ||t_k - t_gt||^2 + s_t,
//   L   = sum_k (1/2)^k L_k,
// with learnable s_R, s_t (the paper's sigma_R, sigma_t), both starting at 0. Adam with weight
// decay, the learning rate multiplied by lr_gamma at each milestone epoch. Gradients do not flow
// through the re-binning between passes (it is discrete); each pass's step does.
//
// Files in output_dir:
//   model.rpsrw           the weights with the best validation rotation RMSE so far (portable)
//   last.rpsrw            the weights after the last finished epoch (portable)
//   trainer_state.txt     epoch, s_R, s_t, best error; with optimizer.pt (Adam's moments, saved
//                         by this LibTorch, so resuming needs the same build) it resumes a run
//   training_log.csv      one row per epoch: losses, validation errors, time
#ifndef RPSR_CORE_NET_TRAINER_H_
#define RPSR_CORE_NET_TRAINER_H_

#include <cstdint>
#include <functional>
#include <string>
#include <vector>

#include "Eigen/Geometry"
#include "absl/status/statusor.h"
#include "core/cloud/point_cloud.h"
#include "core/data/training_pairs.h"
#include "core/net/rpsr_net.h"
#include "core/tree/bh_tree.h"

namespace rpsr::core {

// Must be a pure function of the index (deterministic training) and thread-safe.
using TrainingPairGenerator = RegistrationPairGenerator;

struct TrainerOptions {
  int epochs = 60;
  int pairs_per_epoch = 4096;
  int batch_size = 16;
  int validation_pairs = 256;
  double learning_rate = 1e-3;
  double weight_decay = 1e-4;
  std::vector<int> lr_milestones;  // empty: at 60% and 85% of the epochs
  double lr_gamma = 0.1;
  double gradient_clip_norm = 10.0;
  int passes = 3;
  uint64_t seed = 1;
  std::string output_dir;
  bool resume = true;          // continue from output_dir's state when present
  std::string device = "cpu";  // "cpu" or "cuda"
  int data_threads = 2;        // threads generating pairs and building trees
  bool deterministic = true;   // torch's deterministic algorithms
  BarnesHutTreeOptions tree_options;
};

struct EpochRecord {
  int epoch = 0;
  double train_loss = 0.0;
  double train_rotation_loss = 0.0;     // last pass, mean ||R^T R_gt - I||^2
  double train_translation_loss = 0.0;  // last pass, mean ||t - t_gt||^2
  double validation_rotation_rmse_deg = 0.0;
  double validation_translation_rmse = 0.0;
  double validation_rotation_median_deg = 0.0;
  double sigma_rotation = 0.0;
  double sigma_translation = 0.0;
  double learning_rate = 0.0;
  int skipped_batches = 0;  // non-finite losses (degenerate SVD), not stepped
  double seconds = 0.0;
};

struct TrainerProgress {
  int epoch = 0;
  int epochs = 0;
  int batch = 0;
  int batches = 0;
  double loss = 0.0;
  double seconds_elapsed = 0.0;
  double seconds_remaining = 0.0;  // estimate from the pace so far
};

// Trains `net` in place and returns the epochs run in this call. `on_progress` (optional) is
// called after every batch; `on_epoch` after every epoch.
absl::StatusOr<std::vector<EpochRecord>> TrainRpsrNet(
    RpsrNet& net, const TrainingPairGenerator& train, const TrainingPairGenerator& validation,
    const TrainerOptions& options,
    const std::function<void(const TrainerProgress&)>& on_progress = {},
    const std::function<void(const EpochRecord&)>& on_epoch = {});

}  // namespace rpsr::core

#endif  // RPSR_CORE_NET_TRAINER_H_
