// Checks of absl::Status results shared by the core/io tests: the code, and that the message
// names the file and the place of the error.
#ifndef RPSR_TESTS_CORE_IO_STATUS_EXPECTATIONS_H_
#define RPSR_TESTS_CORE_IO_STATUS_EXPECTATIONS_H_

#include <string>
#include <vector>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "gmock/gmock.h"
#include "gtest/gtest.h"

namespace rpsr::core {

// Expects `status` to carry `code` and a message that contains every string of `parts`.
inline void ExpectError(const absl::Status& status, absl::StatusCode code,
                        const std::vector<std::string>& parts) {
  EXPECT_EQ(status.code(), code) << status;
  for (const std::string& part : parts) {
    EXPECT_THAT(std::string(status.message()), ::testing::HasSubstr(part));
  }
}

template <typename T>
void ExpectError(const absl::StatusOr<T>& result, absl::StatusCode code,
                 const std::vector<std::string>& parts) {
  ExpectError(result.status(), code, parts);
}

// Expects an InvalidArgument naming `name` and every string of `parts`.
template <typename T>
void ExpectInvalid(const T& result, const std::string& name, std::vector<std::string> parts = {}) {
  parts.insert(parts.begin(), name + ": ");
  ExpectError(result, absl::StatusCode::kInvalidArgument, parts);
}

}  // namespace rpsr::core

#endif  // RPSR_TESTS_CORE_IO_STATUS_EXPECTATIONS_H_
