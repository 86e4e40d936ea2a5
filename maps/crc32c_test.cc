#include "maps/crc32c.h"

#include <gtest/gtest.h>

#include <random>
#include <string>
#include <vector>

namespace evloc {
namespace {

TEST(Crc32c, MatchesTheStandardCheckValue) {
  // The CRC-32C check value of the catalogue of parametrised CRC algorithms.
  EXPECT_EQ(Crc32c("123456789"), 0xE3069283u);
  EXPECT_EQ(Crc32c(""), 0u);
  // RFC 3720 (iSCSI) B.4: 32 bytes of zeros.
  EXPECT_EQ(Crc32c(std::string(32, '\0')), 0x8A9136AAu);
}

TEST(Crc32c, HardwareAndTableImplementationsAgreeOnEveryLengthAndAlignment) {
  std::mt19937 random(7);
  std::vector<unsigned char> bytes(1000);
  for (unsigned char& byte : bytes) byte = static_cast<unsigned char>(random());
  for (size_t offset = 0; offset < 8; ++offset) {
    for (size_t size = 0; size + offset <= bytes.size(); size += 37) {
      EXPECT_EQ(ExtendCrc32c(0, bytes.data() + offset, size),
                internal::ExtendCrc32cSoftware(0, bytes.data() + offset, size))
          << "offset " << offset << " size " << size;
    }
  }
}

TEST(Crc32c, ExtendingPieceByPieceEqualsTheWhole) {
  const std::string text = "The quick brown fox jumps over the lazy dog";
  for (size_t split = 0; split <= text.size(); ++split) {
    const uint32_t first = ExtendCrc32c(0, text.data(), split);
    EXPECT_EQ(ExtendCrc32c(first, text.data() + split, text.size() - split), Crc32c(text));
  }
  EXPECT_EQ(Crc32c(text), 0x22620404u);
}

}  // namespace
}  // namespace evloc
