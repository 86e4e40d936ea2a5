#include "core/events/dsec_hdf5.h"

#include <gtest/gtest.h>
#include <hdf5.h>

#include <vector>

#include "core/common/error.h"
#include "core/common/test_data.h"
#include "core/events/event_reader.h"

namespace evloc {
namespace {

template <typename T>
void WriteDataset(hid_t file, const char* name, hid_t type, const std::vector<T>& values) {
  const hsize_t length = values.size();
  const hid_t space = H5Screate_simple(1, &length, nullptr);
  const hid_t dataset = H5Dcreate2(file, name, type, space, H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT);
  H5Dwrite(dataset, type, H5S_ALL, H5S_ALL, H5P_DEFAULT, values.data());
  H5Dclose(dataset);
  H5Sclose(space);
}

// A small DSEC-style file: t as uint32 microseconds, /t_offset, /ms_to_idx.
void WriteDsecFile(const std::filesystem::path& path, size_t count, bool with_p = true,
                   uint8_t bad_polarity = 0) {
  const hid_t file = H5Fcreate(path.c_str(), H5F_ACC_TRUNC, H5P_DEFAULT, H5P_DEFAULT);
  const hid_t group = H5Gcreate2(file, "/events", H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT);
  std::vector<uint16_t> x(count), y(count);
  std::vector<uint8_t> p(count);
  std::vector<uint32_t> t(count);
  for (size_t i = 0; i < count; ++i) {
    x[i] = static_cast<uint16_t>(i % 640);
    y[i] = static_cast<uint16_t>(i % 480);
    p[i] = static_cast<uint8_t>(i % 2);
    t[i] = static_cast<uint32_t>(i * 3);
  }
  if (bad_polarity) p[count / 2] = bad_polarity;
  WriteDataset(file, "/events/x", H5T_NATIVE_UINT16, x);
  WriteDataset(file, "/events/y", H5T_NATIVE_UINT16, y);
  if (with_p) WriteDataset(file, "/events/p", H5T_NATIVE_UINT8, p);
  WriteDataset(file, "/events/t", H5T_NATIVE_UINT32, t);
  WriteDataset(file, "/t_offset", H5T_NATIVE_INT64, std::vector<int64_t>{1'000'000});
  std::vector<uint64_t> ms_to_idx;
  for (size_t ms = 0; ms * 1000 <= count * 3; ++ms) ms_to_idx.push_back((ms * 1000 + 2) / 3);
  WriteDataset(file, "/ms_to_idx", H5T_NATIVE_UINT64, ms_to_idx);
  H5Gclose(group);
  H5Fclose(file);
}

TEST(DsecHdf5Reader, ReadsBackEventsInBlocksWithTimeOffset) {
  const auto directory = testing::MakeTempDir("dsec");
  const auto path = directory / "events.h5";
  WriteDsecFile(path, 10000);
  auto reader = OpenEventFile(path);
  EventBuffer events;
  while (reader->Read(999, &events) > 0) {
  }
  ASSERT_EQ(events.size(), 10000u);
  for (size_t i = 0; i < events.size(); i += 1237) {
    EXPECT_EQ(events[i], (Event{(1'000'000 + static_cast<int64_t>(i) * 3) * 1000,
                                static_cast<uint16_t>(i % 640), static_cast<uint16_t>(i % 480),
                                i % 2 ? int8_t{1} : int8_t{-1}}));
  }
  EXPECT_FALSE(reader->sensor_size().has_value());
  std::filesystem::remove_all(directory);
}

TEST(DsecHdf5Reader, MissingDatasetOrBadPolarityIsAParseError) {
  const auto directory = testing::MakeTempDir("dsec");
  WriteDsecFile(directory / "no_p.h5", 10, /*with_p=*/false);
  try {
    DsecHdf5Reader reader(directory / "no_p.h5");
    FAIL() << "no error";
  } catch (const ParseError& error) {
    EXPECT_NE(std::string(error.what()).find("dataset /events/p: missing"), std::string::npos)
        << error.what();
  }
  WriteDsecFile(directory / "bad_p.h5", 10, true, /*bad_polarity=*/3);
  DsecHdf5Reader reader(directory / "bad_p.h5");
  EventBuffer events;
  EXPECT_THROW(reader.Read(100, &events), ParseError);
  std::filesystem::remove_all(directory);
}

TEST(DsecHdf5Reader, UnavailableCompressionFilterIsAClearIoError) {
  const auto directory = testing::MakeTempDir("dsec");
  const auto path = directory / "blosc.h5";
  WriteDsecFile(path, 100);
  // Rewrite /events/t chunked with the Blosc filter (id 32001) registered as optional: HDF5
  // stores the pipeline although this library cannot run the filter, as in a DSEC download.
  {
    const hid_t file = H5Fopen(path.c_str(), H5F_ACC_RDWR, H5P_DEFAULT);
    H5Ldelete(file, "/events/t", H5P_DEFAULT);
    const hsize_t length = 100, chunk = 50;
    const hid_t space = H5Screate_simple(1, &length, nullptr);
    const hid_t properties = H5Pcreate(H5P_DATASET_CREATE);
    H5Pset_chunk(properties, 1, &chunk);
    ASSERT_GE(H5Pset_filter(properties, 32001, H5Z_FLAG_OPTIONAL, 0, nullptr), 0);
    const hid_t dataset = H5Dcreate2(file, "/events/t", H5T_NATIVE_UINT32, space, H5P_DEFAULT,
                                     properties, H5P_DEFAULT);
    ASSERT_GE(dataset, 0);
    H5Dclose(dataset);
    H5Pclose(properties);
    H5Sclose(space);
    H5Fclose(file);
  }
  if (H5Zfilter_avail(32001) > 0) GTEST_SKIP() << "this HDF5 has the Blosc filter installed";
  try {
    DsecHdf5Reader reader(path);
    FAIL() << "no error";
  } catch (const IoError& error) {
    EXPECT_NE(std::string(error.what()).find("Blosc (id 32001)"), std::string::npos)
        << error.what();
  }
  std::filesystem::remove_all(directory);
}

}  // namespace
}  // namespace evloc
