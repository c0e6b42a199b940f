#include "core/net/registration_loss.h"

#include <cmath>

#include "gtest/gtest.h"

namespace rpsr::core::net {
namespace {

torch::Tensor RotationZ(double angle) {
  const double c = std::cos(angle), s = std::sin(angle);
  return torch::tensor({{c, -s, 0.0}, {s, c, 0.0}, {0.0, 0.0, 1.0}}, torch::kFloat64);
}

TEST(RegistrationLossTest, ZeroAtTheTruthUpToTheSigmaTerms) {
  torch::Tensor R = RotationZ(0.3).unsqueeze(0);
  torch::Tensor t = torch::tensor({{1.0, 2.0, 3.0}}, torch::kFloat64);
  torch::Tensor sr = torch::tensor({0.25}, torch::kFloat64);
  torch::Tensor st = torch::tensor({-0.5}, torch::kFloat64);
  PassLoss loss = RegistrationPassLoss(R, t, R, t, sr, st);
  EXPECT_NEAR(loss.rotation.item<double>(), 0.0, 1e-12);
  EXPECT_NEAR(loss.translation.item<double>(), 0.0, 1e-12);
  EXPECT_NEAR(loss.combined.item<double>(), 0.25 - 0.5, 1e-12);
}

TEST(RegistrationLossTest, RotationTermIsFourTimesOneMinusCosine) {
  // ||R^T R_gt - I||_F^2 = 4 (1 - cos theta) for a relative rotation by theta.
  const double theta = 0.4;
  torch::Tensor R = RotationZ(theta).unsqueeze(0);
  torch::Tensor R_gt = torch::eye(3, torch::kFloat64).unsqueeze(0);
  torch::Tensor t = torch::zeros({1, 3}, torch::kFloat64);
  torch::Tensor t_gt = torch::tensor({{0.0, 3.0, 4.0}}, torch::kFloat64);
  torch::Tensor zero = torch::zeros({1}, torch::kFloat64);
  PassLoss loss = RegistrationPassLoss(R, t, R_gt, t_gt, zero, zero);
  EXPECT_NEAR(loss.rotation.item<double>(), 4.0 * (1.0 - std::cos(theta)), 1e-12);
  EXPECT_NEAR(loss.translation.item<double>(), 25.0, 1e-12);
  EXPECT_NEAR(loss.combined.item<double>(), 4.0 * (1.0 - std::cos(theta)) + 25.0, 1e-12);
}

TEST(RegistrationLossTest, SigmaGradientBalancesTheTerm) {
  // d/ds (exp(-s) L + s) = 1 - exp(-s) L: zero at s = log L, the learned balance.
  torch::Tensor R = RotationZ(0.2).unsqueeze(0);
  torch::Tensor R_gt = torch::eye(3, torch::kFloat64).unsqueeze(0);
  torch::Tensor t = torch::zeros({1, 3}, torch::kFloat64);
  const double rotation_term = 4.0 * (1.0 - std::cos(0.2));
  torch::Tensor sr = torch::tensor({std::log(rotation_term)}, torch::kFloat64).requires_grad_(true);
  torch::Tensor st = torch::zeros({1}, torch::kFloat64).requires_grad_(true);
  RegistrationPassLoss(R, t, R_gt, t, sr, st).combined.backward();
  EXPECT_NEAR(sr.grad().item<double>(), 0.0, 1e-9);
  EXPECT_NEAR(st.grad().item<double>(), 1.0, 1e-12);  // translation term is 0
}

TEST(RegistrationLossTest, PassesWeighHalfTheOneBefore) {
  EXPECT_DOUBLE_EQ(PassWeight(1), 0.5);
  EXPECT_DOUBLE_EQ(PassWeight(3), 0.125);
}

}  // namespace
}  // namespace rpsr::core::net
