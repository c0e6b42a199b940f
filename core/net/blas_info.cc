#include "core/net/blas_info.h"

#include <dlfcn.h>

#include <cstdlib>
#include <optional>

#include "absl/strings/str_cat.h"
#include "core/net/openblas_core_choice.h"

namespace rpsr::core::net {

std::string BlasDescription() {
  // Looked up at run time: LibTorch links the BLAS, rpsr does not, and another BLAS may be
  // installed as the libblas.so.3 alternative.
  using NameFunction = char* (*)();
  const auto config = reinterpret_cast<NameFunction>(dlsym(RTLD_DEFAULT, "openblas_get_config"));
  if (config == nullptr) return "not OpenBLAS";
  std::string description =
      config();  // names the chosen core, e.g. "... USE_OPENMP Cooperlake ..."
  if (const char* forced = std::getenv("OPENBLAS_CORETYPE"); forced != nullptr) {
    absl::StrAppend(&description, " (OPENBLAS_CORETYPE=", forced, ")");
  }
  if (const std::optional<std::string> from = OpenBlasCoreSwitchedFrom()) {
    absl::StrAppend(&description, " (chosen by rpsr for this CPU; OpenBLAS took it for ", *from,
                    ")");
  }
  return description;
}

const char* OpenBlasCoreName() {
  using NameFunction = char* (*)();
  const auto corename =
      reinterpret_cast<NameFunction>(dlsym(RTLD_DEFAULT, "openblas_get_corename"));
  return corename != nullptr ? corename() : nullptr;
}

}  // namespace rpsr::core::net
