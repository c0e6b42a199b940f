// How far a parser in core/io trusts a record count that a file declares in its header (PLY
// `element vertex N`, PCD `POINTS N`, OFF `nv nf ne`): a count is checked against a hard limit
// and against the bytes actually present before anything is allocated for it.
#ifndef RPSR_CORE_IO_DECLARED_COUNTS_H_
#define RPSR_CORE_IO_DECLARED_COUNTS_H_

#include <algorithm>
#include <cstddef>
#include <cstdint>

namespace rpsr::core::io_internal {

// Declared counts above this are rejected outright: a billion records is beyond any cloud rpsr
// handles and keeps count * record size far from overflowing 64 bits.
inline constexpr uint64_t kMaxDeclaredCount = 1'000'000'000;

// How many records to reserve room for when a text file declares `declared` of them and
// `remaining_bytes` are left: a text record takes at least 2 bytes (a digit and a separator), so
// never more than remaining_bytes / 2, whatever the header says.
inline size_t TextReservation(uint64_t declared, size_t remaining_bytes) {
  return static_cast<size_t>(std::min<uint64_t>(declared, remaining_bytes / 2));
}

}  // namespace rpsr::core::io_internal

#endif  // RPSR_CORE_IO_DECLARED_COUNTS_H_
