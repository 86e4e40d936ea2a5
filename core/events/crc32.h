// CRC-32 (ISO-HDLC, as zlib and PNG: reflected polynomial 0xEDB88320), used by the .evb format.
#pragma once

#include <cstddef>
#include <cstdint>

namespace evloc {

// Continues a CRC-32 over `size` bytes; start with `crc = 0`. Crc32("123456789") == 0xCBF43926.
uint32_t Crc32(const void* data, size_t size, uint32_t crc = 0);

}  // namespace evloc
