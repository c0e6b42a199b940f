// Whole-file reads and writes with errors that name the file, shared by every format in core/io.
#ifndef RPSR_CORE_IO_FILE_BYTES_H_
#define RPSR_CORE_IO_FILE_BYTES_H_

#include <cstddef>
#include <string>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "absl/strings/string_view.h"

namespace rpsr::core {

// Largest file any reader in core/io accepts unless told otherwise: 4 GiB, well above a 10M-point
// binary cloud, and a guard against reading a device or a runaway file into memory.
inline constexpr size_t kDefaultMaxFileBytes = size_t{4} << 30;

// Reads the whole file. NotFound when it does not exist, PermissionDenied when it cannot be
// opened, InvalidArgument when it is not a regular file, ResourceExhausted when it is larger than
// `max_bytes`, DataLoss when a read fails part-way.
absl::StatusOr<std::string> ReadFileBytes(const std::string& path,
                                          size_t max_bytes = kDefaultMaxFileBytes);

// Writes `bytes` to `path` through a temporary file in the same folder and a rename, so that a
// reader never sees a half-written file and a failed write loses nothing that was there.
absl::Status WriteFileBytes(const std::string& path, absl::string_view bytes);

}  // namespace rpsr::core

#endif  // RPSR_CORE_IO_FILE_BYTES_H_
