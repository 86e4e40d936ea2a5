#include "localizer/service/client_text.h"

#include <gtest/gtest.h>

namespace evloc::service {
namespace {

TEST(EscapeForLog, EscapesControlBytesAndCutsLongStrings) {
  EXPECT_EQ(EscapeForLog("replay-1"), "replay-1");
  EXPECT_EQ(EscapeForLog("a\nsession 9 end: OK"), "a\\x0asession 9 end: OK");
  EXPECT_EQ(EscapeForLog("back\\slash\r\x1b[31m\xc3\xa9"),
            "back\\x5cslash\\x0d\\x1b[31m\\xc3\\xa9");
  const std::string escaped = EscapeForLog(std::string(1000, 'x'), 16);
  EXPECT_EQ(escaped, std::string(16, 'x') + "...(1000 bytes)");
}

TEST(ScrubServerPaths, RemovesTheMapFolderAndOtherAbsolutePaths) {
  EXPECT_EQ(ScrubServerPaths("cannot read '/srv/maps/office/map.evmap': checksum", "/srv/maps"),
            "cannot read 'office/map.evmap': checksum");
  EXPECT_EQ(ScrubServerPaths("no map named 'x' in /srv/maps (see ListMaps)", "/srv/maps/"),
            "no map named 'x' in maps (see ListMaps)");
  EXPECT_EQ(ScrubServerPaths("staging /tmp/evloc-123/map.evmap failed", "/srv/maps"),
            "staging map.evmap failed");
  EXPECT_EQ(ScrubServerPaths("a / b and 3/4 of it", "/srv/maps"), "a / b and 3/4 of it");
}

}  // namespace
}  // namespace evloc::service
