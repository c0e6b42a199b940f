// OpenBLAS's failed CPU detection is corrected and nothing else is: the rule keeps every core with
// AVX2 kernels and each core a CPU without AVX2 gets, and picks the best kernels a newer Intel CPU
// runs where OpenBLAS took it for an SSE3 Prescott; the live switch really changes the kernels
// OpenBLAS runs, their products stay right, and the caller's environment is left as it was.
#include "core/net/openblas_core_choice.h"

#include <dlfcn.h>
#include <strings.h>
#include <torch/torch.h>

#include <cstdlib>
#include <optional>
#include <string>

#include "absl/strings/match.h"
#include "core/net/blas_info.h"
#include "gtest/gtest.h"

namespace rpsr::core::net {
namespace {

CpuVectorFeatures Features(bool avx2_fma, bool avx512, bool bf16) {
  CpuVectorFeatures cpu;
  cpu.avx2_fma = avx2_fma;
  cpu.avx512 = avx512;
  cpu.avx512_bf16 = bf16;
  return cpu;
}

TEST(OpenBlasCoreChoiceTest, CorrectsOnlyACoreWithoutTheCpusVectorKernels) {
  const CpuVectorFeatures emerald_rapids = Features(true, true, true);
  const CpuVectorFeatures skylake_server = Features(true, true, false);
  const CpuVectorFeatures avx2_only = Features(true, false, false);
  const CpuVectorFeatures sse_only = Features(false, false, false);
  // An Emerald Rapids (family 6 model 207) under OpenBLAS 0.3.21: Prescott.
  EXPECT_EQ(BetterOpenBlasCore("Prescott", emerald_rapids), "Cooperlake");
  EXPECT_EQ(BetterOpenBlasCore("Prescott", skylake_server), "SkylakeX");
  EXPECT_EQ(BetterOpenBlasCore("SandyBridge", avx2_only), "Haswell");
  EXPECT_EQ(BetterOpenBlasCore("Nehalem", avx2_only), "Haswell");
  EXPECT_EQ(BetterOpenBlasCore("unknown", avx2_only), "Haswell");
  // OpenBLAS recognised the CPU: its choice stands, in any case of the name.
  for (const char* core : {"Haswell", "Zen", "SkylakeX", "Cooperlake", "SapphireRapids",
                           "Excavator", "cooperlake", "HASWELL"}) {
    EXPECT_FALSE(BetterOpenBlasCore(core, emerald_rapids).has_value()) << core;
    EXPECT_FALSE(BetterOpenBlasCore(core, avx2_only).has_value()) << core;
  }
  // A CPU without AVX2 and FMA keeps what OpenBLAS gave it.
  EXPECT_FALSE(BetterOpenBlasCore("Prescott", sse_only).has_value());
  EXPECT_FALSE(BetterOpenBlasCore("SandyBridge", sse_only).has_value());
}

const char* RunningCore() {
  using NameFunction = char* (*)();
  const auto corename =
      reinterpret_cast<NameFunction>(dlsym(RTLD_DEFAULT, "openblas_get_corename"));
  return corename != nullptr ? corename() : nullptr;
}

// A product whose every entry is known, big enough for OpenBLAS's blocked GEMM kernels.
void ExpectProductRight() {
  const torch::Tensor a = torch::arange(96 * 80, torch::kFloat32).reshape({96, 80}) / 1000.0;
  const torch::Tensor b = torch::ones({80, 72}, torch::kFloat32);
  const torch::Tensor product = a.matmul(b);
  const torch::Tensor expected = a.sum(1, /*keepdim=*/true).expand({96, 72});
  EXPECT_TRUE(torch::allclose(product, expected, 1e-4, 1e-3));
}

TEST(OpenBlasCoreChoiceTest, SwitchingChangesTheKernelsOpenBlasRuns) {
  ExpectProductRight();  // loads and uses the BLAS
  const char* loaded = RunningCore();
  if (loaded == nullptr) GTEST_SKIP() << "no OpenBLAS loaded: " << BlasDescription();
  const std::string original = loaded;
  // A core that OPENBLAS_CORETYPE cannot name in this OpenBLAS could not be switched back to.
  if (original == "SapphireRapids" || absl::EqualsIgnoreCase(original, "unknown")) {
    GTEST_SKIP() << original;
  }
  std::optional<std::string> environment;
  if (const char* value = std::getenv("OPENBLAS_CORETYPE")) environment = value;

  ASSERT_TRUE(SwitchOpenBlasCore("Prescott"));  // every x86-64 CPU runs SSE3
  EXPECT_STREQ(RunningCore(), "Prescott");
  EXPECT_TRUE(absl::StrContains(BlasDescription(), " Prescott ")) << BlasDescription();
  ExpectProductRight();
  if (DetectCpuVectorFeatures().avx2_fma) {
    ASSERT_TRUE(SwitchOpenBlasCore("Haswell"));
    EXPECT_STREQ(RunningCore(), "Haswell");
    ExpectProductRight();
  }
  // A name OpenBLAS would answer with its own fallback is refused, and nothing changes.
  const std::string before = RunningCore();
  EXPECT_FALSE(SwitchOpenBlasCore("NoSuchCore"));
  EXPECT_EQ(RunningCore(), before);

  ASSERT_TRUE(SwitchOpenBlasCore(original));
  EXPECT_EQ(RunningCore(), original);
  ExpectProductRight();
  const char* after = std::getenv("OPENBLAS_CORETYPE");
  EXPECT_EQ(after != nullptr, environment.has_value());
  if (after != nullptr && environment) {
    EXPECT_EQ(std::string(after), *environment);
  }
}

TEST(OpenBlasCoreChoiceTest, MatchingAppliesTheRuleOnceAndSaysSo) {
  ExpectProductRight();
  const OpenBlasCoreChoice choice = MatchOpenBlasCoreToCpu();
  if (choice.detected.empty()) GTEST_SKIP() << choice.reason;
  ASSERT_NE(RunningCore(), nullptr);
  EXPECT_EQ(choice.running, RunningCore());
  const std::optional<std::string> better =
      BetterOpenBlasCore(choice.detected, DetectCpuVectorFeatures());
  if (std::getenv("OPENBLAS_CORETYPE") != nullptr) {
    EXPECT_FALSE(choice.switched) << choice.reason;  // the environment's core is respected
    EXPECT_TRUE(absl::StrContains(choice.reason, "OPENBLAS_CORETYPE")) << choice.reason;
  } else if (better.has_value()) {
    EXPECT_TRUE(choice.switched) << choice.reason;
    EXPECT_EQ(choice.running, *better);
    EXPECT_EQ(OpenBlasCoreSwitchedFrom(), choice.detected);
    EXPECT_TRUE(absl::StrContains(BlasDescription(), "chosen by rpsr for this CPU"))
        << BlasDescription();
    EXPECT_EQ(std::getenv("OPENBLAS_CORETYPE"), nullptr);
  } else {
    EXPECT_FALSE(choice.switched) << choice.reason;
    EXPECT_EQ(choice.running, choice.detected);
    EXPECT_FALSE(OpenBlasCoreSwitchedFrom().has_value());
  }
  ExpectProductRight();
  // A second call changes nothing.
  const OpenBlasCoreChoice again = MatchOpenBlasCoreToCpu();
  EXPECT_EQ(again.running, choice.running);
  EXPECT_EQ(again.switched, choice.switched);
  EXPECT_EQ(RunningCore(), choice.running);
}

}  // namespace
}  // namespace rpsr::core::net
