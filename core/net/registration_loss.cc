#include "core/net/registration_loss.h"

#include <cmath>

namespace rpsr::core::net {

PassLoss RegistrationPassLoss(const torch::Tensor& R, const torch::Tensor& t,
                              const torch::Tensor& R_gt, const torch::Tensor& t_gt,
                              const torch::Tensor& sigma_rotation,
                              const torch::Tensor& sigma_translation) {
  PassLoss loss;
  loss.rotation = (torch::matmul(R.transpose(1, 2), R_gt) - torch::eye(3, R.options()))
                      .pow(2)
                      .sum({1, 2})
                      .mean();
  loss.translation = (t - t_gt).pow(2).sum(1).mean();
  loss.combined = torch::exp(-sigma_rotation) * loss.rotation + sigma_rotation +
                  torch::exp(-sigma_translation) * loss.translation + sigma_translation;
  return loss;
}

double PassWeight(int pass) { return std::pow(0.5, pass); }

}  // namespace rpsr::core::net
