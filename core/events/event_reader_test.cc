#include "core/events/event_reader.h"

#include <gtest/gtest.h>

#include <fstream>

#include "core/common/error.h"
#include "core/common/file_util.h"
#include "core/common/test_data.h"
#include "core/events/ecd_text.h"
#include "core/events/evb.h"

namespace evloc {
namespace {

TEST(OpenEventFile, ChoosesTheReaderByContentAndExtension) {
  const auto directory = testing::MakeTempDir("open-events");
  EventBuffer events;
  events.push_back({1000, 1, 2, 1});
  events.push_back({2000, 3, 4, -1});
  {
    EvbWriter writer(directory / "a.bin", SensorSize{8, 8});
    writer.Write(events);
    writer.Close();
    EcdTextWriter text_writer(directory / "b.txt");
    text_writer.Write(events);
    text_writer.Close();
  }
  EXPECT_EQ(DetectEventFileFormat(directory / "a.bin"), EventFileFormat::kEvb);
  EXPECT_EQ(DetectEventFileFormat(directory / "b.txt"), EventFileFormat::kEcdText);
  for (const char* name : {"a.bin", "b.txt"}) {
    auto reader = OpenEventFile(directory / name);
    EventBuffer read;
    while (reader->Read(10, &read) > 0) {
    }
    EXPECT_EQ(read, events) << name;
  }
  WriteFileAtomically(directory / "c.dat", std::string("\x7f"
                                                       "ELF garbage"));
  try {
    OpenEventFile(directory / "c.dat");
    FAIL() << "no error";
  } catch (const ParseError& error) {
    EXPECT_NE(std::string(error.what()).find("unknown event file format"), std::string::npos);
  }
  EXPECT_THROW(OpenEventFile(directory / "missing.evb"), IoError);
  std::filesystem::remove_all(directory);
}

TEST(OpenEventFile, OpensTheSharedPropheseeSamples) {
  EVLOC_REQUIRE_SHARED_DATA(path, "prophesee/evt3_sample.raw");
  EXPECT_EQ(DetectEventFileFormat(path), EventFileFormat::kPropheseeRaw);
  auto reader = OpenEventFile(path);
  EventBuffer events;
  EXPECT_EQ(reader->Read(5000, &events), 5000u);
}

}  // namespace
}  // namespace evloc
