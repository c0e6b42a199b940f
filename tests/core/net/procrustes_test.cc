// The differentiable SVD head: exact recovery, reflection fix, gradients by finite differences.
#include <torch/torch.h>

#include "core/net/rpsr_modules.h"
#include "gtest/gtest.h"

namespace rpsr::core::net {
namespace {

torch::Tensor RotationAbout(double angle, std::array<double, 3> axis) {
  torch::Tensor a = torch::tensor({axis[0], axis[1], axis[2]}, torch::kFloat64);
  a = a / a.norm();
  torch::Tensor K = torch::zeros({3, 3}, torch::kFloat64);
  K[0][1] = -a[2];
  K[0][2] = a[1];
  K[1][0] = a[2];
  K[1][2] = -a[0];
  K[2][0] = -a[1];
  K[2][1] = a[0];
  return torch::eye(3, torch::kFloat64) + std::sin(angle) * K +
         (1 - std::cos(angle)) * torch::matmul(K, K);
}

TEST(WeightedProcrustesTest, RecoversKnownMotionWithWeights) {
  torch::manual_seed(3);
  torch::Tensor src = torch::randn({2, 64, 3}, torch::kFloat64);
  torch::Tensor R = torch::stack({RotationAbout(0.7, {1, 2, 3}), RotationAbout(-0.3, {0, 1, 0})});
  torch::Tensor t = torch::tensor({{0.1, -0.2, 0.3}, {1.0, 2.0, -3.0}}, torch::kFloat64);
  torch::Tensor tgt = torch::matmul(src, R.transpose(1, 2)) + t.unsqueeze(1);
  // Zero-weight rows are garbage that must not matter.
  torch::Tensor weights = torch::rand({2, 64}, torch::kFloat64);
  weights.index_put_({torch::indexing::Slice(), torch::indexing::Slice(0, 10)}, 0.0);
  tgt.index_put_({torch::indexing::Slice(), torch::indexing::Slice(0, 10)}, 100.0);
  auto [R_est, t_est] = WeightedProcrustes(src, tgt, weights);
  EXPECT_LT((R_est - R).abs().max().item<double>(), 1e-9);
  EXPECT_LT((t_est - t).abs().max().item<double>(), 1e-9);
}

TEST(WeightedProcrustesTest, NeverReturnsAReflection) {
  torch::manual_seed(4);
  torch::Tensor src = torch::randn({1, 32, 3}, torch::kFloat64);
  torch::Tensor tgt = src.clone();
  tgt.index_put_({torch::indexing::Slice(), torch::indexing::Slice(), 2},
                 -src.index({torch::indexing::Slice(), torch::indexing::Slice(), 2}));  // mirror
  auto [R, t] = WeightedProcrustes(src, tgt, torch::ones({1, 32}, torch::kFloat64));
  EXPECT_NEAR(torch::linalg_det(R).item<double>(), 1.0, 1e-9);
}

TEST(WeightedProcrustesTest, GradientsMatchFiniteDifferences) {
  torch::manual_seed(5);
  torch::Tensor src = torch::randn({1, 16, 3}, torch::kFloat64);
  torch::Tensor tgt = torch::matmul(src, RotationAbout(0.4, {0.3, 1, 0.2}).t()) +
                      0.05 * torch::randn({1, 16, 3}, torch::kFloat64);
  torch::Tensor weights = torch::rand({1, 16}, torch::kFloat64) + 0.1;
  auto loss_of = [&](const torch::Tensor& target) {
    auto [R, t] = WeightedProcrustes(src, target, weights);
    // A loss of the kind training uses: rotation vs. a fixed matrix plus the translation norm.
    return (torch::matmul(R.transpose(1, 2), RotationAbout(0.5, {0, 1, 0}).unsqueeze(0)) -
            torch::eye(3, torch::kFloat64))
               .pow(2)
               .sum() +
           t.pow(2).sum();
  };
  torch::Tensor x = tgt.clone().requires_grad_(true);
  loss_of(x).backward();
  torch::Tensor analytic = x.grad();
  const double h = 1e-6;
  for (int i = 0; i < 16; i += 3) {
    for (int a = 0; a < 3; ++a) {
      torch::Tensor plus = tgt.clone();
      torch::Tensor minus = tgt.clone();
      plus[0][i][a] += h;
      minus[0][i][a] -= h;
      const double numeric =
          (loss_of(plus).item<double>() - loss_of(minus).item<double>()) / (2 * h);
      EXPECT_NEAR(analytic[0][i][a].item<double>(), numeric, 1e-5 * (1 + std::abs(numeric)))
          << "point " << i << " axis " << a;
    }
  }
}

}  // namespace
}  // namespace rpsr::core::net
