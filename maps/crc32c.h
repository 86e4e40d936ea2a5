// CRC32C (Castagnoli polynomial 0x1EDC6F41, reflected), the checksum of .evmap files. Uses the
// SSE4.2 crc32 instruction when the CPU has it, a slicing-by-8 table otherwise.
#pragma once

#include <cstddef>
#include <cstdint>
#include <string_view>

namespace evloc {

// Extends `crc` (the value returned for the previous bytes; 0 for none) over `size` bytes.
// Crc32c(0, "123456789", 9) == 0xE3069283.
uint32_t ExtendCrc32c(uint32_t crc, const void* data, size_t size);

// CRC32C of a byte string.
inline uint32_t Crc32c(std::string_view bytes) {
  return ExtendCrc32c(0, bytes.data(), bytes.size());
}

namespace internal {
// The portable table implementation alone (ExtendCrc32c may use the CPU instruction); for tests.
uint32_t ExtendCrc32cSoftware(uint32_t crc, const void* data, size_t size);
}  // namespace internal

}  // namespace evloc
