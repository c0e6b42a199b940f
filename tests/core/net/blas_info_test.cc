// The BLAS under LibTorch is named correctly: deploy/setup.sh installs OpenBLAS (reference BLAS
// runs the network ~14x slower, ../shared/DEPS.md), and a core forced by the environment is
// said, since it decides the network's speed.
#include "core/net/blas_info.h"

#include <torch/torch.h>

#include <cstdlib>
#include <optional>
#include <string>

#include "absl/strings/match.h"
#include "gtest/gtest.h"

namespace rpsr::core::net {
namespace {

class BlasInfoTest : public ::testing::Test {
 protected:
  void SetUp() override {
    if (const char* value = std::getenv("OPENBLAS_CORETYPE")) saved_ = value;
  }
  void TearDown() override {
    if (saved_) {
      setenv("OPENBLAS_CORETYPE", saved_->c_str(), 1);
    } else {
      unsetenv("OPENBLAS_CORETYPE");
    }
  }
  std::optional<std::string> saved_;
};

TEST_F(BlasInfoTest, NamesOpenBlasUnderLibTorch) {
  // A matrix product through LibTorch makes sure its BLAS is loaded and used.
  const torch::Tensor product = torch::ones({64, 64}).matmul(torch::ones({64, 64}));
  ASSERT_FLOAT_EQ(product[0][0].item<float>(), 64.0f);
  unsetenv("OPENBLAS_CORETYPE");
  const std::string description = BlasDescription();
  EXPECT_TRUE(absl::StartsWith(description, "OpenBLAS ")) << description;
  EXPECT_FALSE(absl::StrContains(description, "OPENBLAS_CORETYPE")) << description;
}

TEST_F(BlasInfoTest, SaysWhenTheEnvironmentForcesACore) {
  setenv("OPENBLAS_CORETYPE", "Haswell", 1);
  EXPECT_TRUE(absl::EndsWith(BlasDescription(), " (OPENBLAS_CORETYPE=Haswell)"))
      << BlasDescription();
}

}  // namespace
}  // namespace rpsr::core::net
