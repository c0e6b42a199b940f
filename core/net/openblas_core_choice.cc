#include "core/net/openblas_core_choice.h"

#include <dlfcn.h>
#include <strings.h>

#include <array>
#include <cstdlib>
#include <mutex>

#include "absl/strings/str_cat.h"

namespace rpsr::core::net {

namespace {

using NameFunction = char* (*)();
using VoidFunction = void (*)();

// OpenBLAS is looked up at run time, as in blas_info.cc: LibTorch links it, rpsr does not.
// gotoblas_dynamic_quit / gotoblas_dynamic_init are the exported halves of a DYNAMIC_ARCH
// OpenBLAS's start-up selection (the second reads OPENBLAS_CORETYPE, or the CPU's model, and runs
// the chosen core's parameter set-up); a build for one core has neither.
template <typename Function>
Function Lookup(const char* name) {
  return reinterpret_cast<Function>(dlsym(RTLD_DEFAULT, name));
}

// Cores with AVX2 kernels or better: OpenBLAS recognised the CPU, its choice stands.
constexpr std::array<const char*, 6> kCoresWithAvx2Kernels = {
    "Haswell", "Zen", "SkylakeX", "Cooperlake", "SapphireRapids", "Excavator"};

// The x86-64 names SwitchOpenBlasCore takes: OPENBLAS_CORETYPE's that openblas_get_corename
// reports back as themselves (without DYNAMIC_OLDER, Atom, Penryn, Dunnington, Opteron, Nano and
// Bobcat run and report another core's table; SapphireRapids cannot be forced), so that success
// can be read back. OpenBLAS answers an unknown name with a warning and a fallback of its own.
constexpr std::array<const char*, 13> kSwitchableCores = {
    "Prescott",    "Core2",   "Nehalem",   "Barcelona", "SandyBridge", "Bulldozer", "Piledriver",
    "Steamroller", "Haswell", "Excavator", "Zen",       "SkylakeX",    "Cooperlake"};

bool SameCore(absl::string_view a, absl::string_view b) {
  return a.size() == b.size() && strncasecmp(a.data(), b.data(), a.size()) == 0;
}

std::mutex switched_mutex;
std::optional<std::string> switched_from;  // guarded by switched_mutex

}  // namespace

CpuVectorFeatures DetectCpuVectorFeatures() {
  __builtin_cpu_init();
  CpuVectorFeatures cpu;
  cpu.avx2_fma = __builtin_cpu_supports("avx2") && __builtin_cpu_supports("fma");
  // libgcc also checks that the OS saves the AVX-512 state (XCR0), as OpenBLAS does.
  cpu.avx512 = cpu.avx2_fma && __builtin_cpu_supports("avx512f") &&
               __builtin_cpu_supports("avx512cd") && __builtin_cpu_supports("avx512bw") &&
               __builtin_cpu_supports("avx512dq") && __builtin_cpu_supports("avx512vl");
  cpu.avx512_bf16 = cpu.avx512 && __builtin_cpu_supports("avx512bf16");
  return cpu;
}

std::optional<std::string> BetterOpenBlasCore(absl::string_view openblas_core,
                                              const CpuVectorFeatures& cpu) {
  if (!cpu.avx2_fma) return std::nullopt;
  for (const char* core : kCoresWithAvx2Kernels) {
    if (SameCore(openblas_core, core)) return std::nullopt;
  }
  // What OpenBLAS's own fallback for an unknown x86-64 model picks in later releases.
  if (cpu.avx512_bf16) return "Cooperlake";
  if (cpu.avx512) return "SkylakeX";
  return "Haswell";
}

bool SwitchOpenBlasCore(const std::string& core) {
  const auto quit = Lookup<VoidFunction>("gotoblas_dynamic_quit");
  const auto init = Lookup<VoidFunction>("gotoblas_dynamic_init");
  const auto corename = Lookup<NameFunction>("openblas_get_corename");
  if (quit == nullptr || init == nullptr || corename == nullptr) return false;
  bool known = false;
  for (const char* name : kSwitchableCores) known = known || SameCore(core, name);
  if (!known) return false;
  // The selection reads OPENBLAS_CORETYPE; the caller's environment is restored afterwards, so
  // that BlasDescription does not take rpsr's choice for the environment's.
  std::optional<std::string> saved;
  if (const char* value = std::getenv("OPENBLAS_CORETYPE")) saved = value;
  setenv("OPENBLAS_CORETYPE", core.c_str(), 1);
  quit();
  init();
  if (saved) {
    setenv("OPENBLAS_CORETYPE", saved->c_str(), 1);
  } else {
    unsetenv("OPENBLAS_CORETYPE");
  }
  const char* running = corename();
  return running != nullptr && SameCore(running, core);
}

OpenBlasCoreChoice MatchOpenBlasCoreToCpu() {
  static const OpenBlasCoreChoice choice = [] {
    OpenBlasCoreChoice made;
    const auto corename = Lookup<NameFunction>("openblas_get_corename");
    if (corename == nullptr || corename() == nullptr) {
      made.reason = "no OpenBLAS loaded";
      return made;
    }
    made.detected = corename();
    made.running = made.detected;
    if (const char* forced = std::getenv("OPENBLAS_CORETYPE")) {
      made.reason = absl::StrCat("OPENBLAS_CORETYPE=", forced, " is respected");
      return made;
    }
    const std::optional<std::string> better =
        BetterOpenBlasCore(made.detected, DetectCpuVectorFeatures());
    if (!better) {
      made.reason = absl::StrCat("OpenBLAS's ", made.detected, " kernels suit this CPU");
      return made;
    }
    if (!SwitchOpenBlasCore(*better)) {
      made.running = corename() != nullptr ? corename() : "";
      made.reason = absl::StrCat("OpenBLAS took this CPU for ", made.detected,
                                 " and could not be switched to ", *better);
      return made;
    }
    made.running = *better;
    made.switched = true;
    made.reason = absl::StrCat("OpenBLAS took this CPU for ", made.detected, "; switched to its ",
                               *better, " kernels, which the CPU runs");
    std::lock_guard<std::mutex> lock(switched_mutex);
    switched_from = made.detected;
    return made;
  }();
  return choice;
}

std::optional<std::string> OpenBlasCoreSwitchedFrom() {
  std::lock_guard<std::mutex> lock(switched_mutex);
  return switched_from;
}

}  // namespace rpsr::core::net
