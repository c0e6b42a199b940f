// The paper's registration loss (Eq. 6), private to core/net (LibTorch types).
#ifndef RPSR_CORE_NET_REGISTRATION_LOSS_H_
#define RPSR_CORE_NET_REGISTRATION_LOSS_H_

#include <torch/torch.h>

namespace rpsr::core::net {

struct PassLoss {
  torch::Tensor rotation;     // mean over the batch of ||R^T R_gt - I||_F^2
  torch::Tensor translation;  // mean over the batch of ||t - t_gt||^2
  torch::Tensor combined;     // exp(-s_R) rotation + s_R + exp(-s_t) translation + s_t
};

// R [B, 3, 3], t [B, 3] against R_gt, t_gt; sigma_rotation and sigma_translation are the learnable
// scalars (s_R, s_t) of the paper. The total over passes k = 1..K is sum_k (1/2)^k combined_k.
PassLoss RegistrationPassLoss(const torch::Tensor& R, const torch::Tensor& t,
                              const torch::Tensor& R_gt, const torch::Tensor& t_gt,
                              const torch::Tensor& sigma_rotation,
                              const torch::Tensor& sigma_translation);

// Weight of pass k (1-based) in the total: (1/2)^k.
double PassWeight(int pass);

}  // namespace rpsr::core::net

#endif  // RPSR_CORE_NET_REGISTRATION_LOSS_H_
