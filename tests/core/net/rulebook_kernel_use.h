// Sets where the AVX2 kernel runs (rulebook_kernel.h) for a test's scope, and back to the
// default (kAuto) after it, even when an assertion leaves the test early.
#ifndef RPSR_TESTS_CORE_NET_RULEBOOK_KERNEL_USE_H_
#define RPSR_TESTS_CORE_NET_RULEBOOK_KERNEL_USE_H_

#include "core/net/rulebook_kernel.h"

namespace rpsr::core::testing {

class ScopedRulebookKernelUse {
 public:
  explicit ScopedRulebookKernelUse(net::RulebookKernelUse use) { net::SetRulebookKernelUse(use); }
  ~ScopedRulebookKernelUse() { net::SetRulebookKernelUse(net::RulebookKernelUse::kAuto); }
  ScopedRulebookKernelUse(const ScopedRulebookKernelUse&) = delete;
  ScopedRulebookKernelUse& operator=(const ScopedRulebookKernelUse&) = delete;
};

}  // namespace rpsr::core::testing

#endif  // RPSR_TESTS_CORE_NET_RULEBOOK_KERNEL_USE_H_
