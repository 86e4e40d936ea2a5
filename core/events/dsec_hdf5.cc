#include "core/events/dsec_hdf5.h"

#include <hdf5.h>

#include <algorithm>
#include <vector>

#include "core/common/error.h"

namespace evloc {
namespace {

// Silences the HDF5 error stack printing (library code never prints) for one scope.
class SilenceHdf5Errors {
 public:
  SilenceHdf5Errors() {
    H5Eget_auto2(H5E_DEFAULT, &function_, &data_);
    H5Eset_auto2(H5E_DEFAULT, nullptr, nullptr);
  }
  ~SilenceHdf5Errors() { H5Eset_auto2(H5E_DEFAULT, function_, data_); }

 private:
  H5E_auto2_t function_ = nullptr;
  void* data_ = nullptr;
};

// Largest number of events read by one hyperslab.
constexpr uint64_t kMaxBlock = uint64_t{1} << 20;

constexpr const char* kDatasetNames[4] = {"/events/x", "/events/y", "/events/p", "/events/t"};

std::string FilterName(H5Z_filter_t id) {
  switch (id) {
    case 32001:
      return "Blosc (id 32001)";
    case 32004:
      return "LZ4 (id 32004)";
    case 32008:
      return "bitshuffle (id 32008)";
    case 32015:
      return "Zstandard (id 32015)";
    default:
      return "id " + std::to_string(id);
  }
}

void CheckFiltersAvailable(hid_t dataset, const std::string& source, const char* name) {
  const hid_t properties = H5Dget_create_plist(dataset);
  if (properties < 0) return;
  const int filter_count = H5Pget_nfilters(properties);
  for (int i = 0; i < filter_count; ++i) {
    unsigned flags = 0;
    size_t element_count = 0;
    char filter_name[64] = {0};
    unsigned filter_config = 0;
    const H5Z_filter_t id =
        H5Pget_filter2(properties, static_cast<unsigned>(i), &flags, &element_count, nullptr,
                       sizeof(filter_name), filter_name, &filter_config);
    if (id >= 0 && H5Zfilter_avail(id) <= 0) {
      H5Pclose(properties);
      throw IoError(source + ": dataset " + name + " is compressed with filter " + FilterName(id) +
                    ", which this HDF5 library cannot decode; install the filter plugin (e.g. "
                    "hdf5-blosc) and set HDF5_PLUGIN_PATH, or re-save the file uncompressed or "
                    "with gzip");
    }
  }
  H5Pclose(properties);
}

}  // namespace

DsecHdf5Reader::DsecHdf5Reader(const std::filesystem::path& path) : source_(path.string()) {
  SilenceHdf5Errors silence;
  if (H5Fis_hdf5(source_.c_str()) <= 0) throw IoError(source_ + ": not a readable HDF5 file");
  file_ = H5Fopen(source_.c_str(), H5F_ACC_RDONLY, H5P_DEFAULT);
  if (file_ < 0) throw IoError(source_ + ": cannot open as HDF5");
  try {
    for (int i = 0; i < 4; ++i) {
      if (H5Lexists(file_, "/events", H5P_DEFAULT) <= 0 ||
          H5Lexists(file_, kDatasetNames[i], H5P_DEFAULT) <= 0) {
        throw ParseError(source_, std::string("dataset ") + kDatasetNames[i],
                         "missing (a DSEC event file has /events/x, y, p and t)");
      }
      datasets_[i] = H5Dopen2(file_, kDatasetNames[i], H5P_DEFAULT);
      if (datasets_[i] < 0) throw IoError(source_ + ": cannot open " + kDatasetNames[i]);
      const hid_t type = H5Dget_type(datasets_[i]);
      const bool is_integer = H5Tget_class(type) == H5T_INTEGER;
      H5Tclose(type);
      const hid_t space = H5Dget_space(datasets_[i]);
      const int rank = H5Sget_simple_extent_ndims(space);
      hsize_t length = 0;
      if (rank == 1) H5Sget_simple_extent_dims(space, &length, nullptr);
      H5Sclose(space);
      if (!is_integer || rank != 1) {
        throw ParseError(source_, std::string("dataset ") + kDatasetNames[i],
                         "must be a 1-D integer array");
      }
      if (i == 0) event_count_ = length;
      if (length != event_count_) {
        throw ParseError(source_, std::string("dataset ") + kDatasetNames[i],
                         "has " + std::to_string(length) + " elements, /events/x has " +
                             std::to_string(event_count_));
      }
      CheckFiltersAvailable(datasets_[i], source_, kDatasetNames[i]);
    }
    if (H5Lexists(file_, "/t_offset", H5P_DEFAULT) > 0) {
      const hid_t dataset = H5Dopen2(file_, "/t_offset", H5P_DEFAULT);
      const hid_t space = H5Dget_space(dataset);
      const hssize_t points = H5Sget_simple_extent_npoints(space);
      H5Sclose(space);
      herr_t status = -1;
      if (points == 1) {
        status = H5Dread(dataset, H5T_NATIVE_INT64, H5S_ALL, H5S_ALL, H5P_DEFAULT, &t_offset_us_);
      }
      H5Dclose(dataset);
      if (status < 0) throw ParseError(source_, "dataset /t_offset", "must be one integer");
    }
    int64_t width = 0, height = 0;
    const hid_t events = H5Gopen2(file_, "/events", H5P_DEFAULT);
    if (H5Aexists(events, "width") > 0 && H5Aexists(events, "height") > 0) {
      const hid_t width_attribute = H5Aopen(events, "width", H5P_DEFAULT);
      const hid_t height_attribute = H5Aopen(events, "height", H5P_DEFAULT);
      H5Aread(width_attribute, H5T_NATIVE_INT64, &width);
      H5Aread(height_attribute, H5T_NATIVE_INT64, &height);
      H5Aclose(width_attribute);
      H5Aclose(height_attribute);
    }
    H5Gclose(events);
    if (width > 0 && height > 0 && width <= 65535 && height <= 65535) {
      sensor_size_ = SensorSize{static_cast<int>(width), static_cast<int>(height)};
    }
  } catch (...) {
    for (int64_t dataset : datasets_) {
      if (dataset >= 0) H5Dclose(dataset);
    }
    H5Fclose(file_);
    throw;
  }
}

DsecHdf5Reader::~DsecHdf5Reader() {
  SilenceHdf5Errors silence;
  for (int64_t dataset : datasets_) {
    if (dataset >= 0) H5Dclose(dataset);
  }
  if (file_ >= 0) H5Fclose(file_);
}

size_t DsecHdf5Reader::Read(size_t max_events, EventBuffer* out) {
  if (out == nullptr) throw InvalidArgumentError("DsecHdf5Reader::Read: output buffer is null");
  const uint64_t count = std::min<uint64_t>({max_events, event_count_ - next_, kMaxBlock});
  if (count == 0) return 0;
  SilenceHdf5Errors silence;
  std::vector<int64_t> columns[4];
  for (int i = 0; i < 4; ++i) {
    columns[i].resize(count);
    const hid_t file_space = H5Dget_space(datasets_[i]);
    const hsize_t start = next_, length = count;
    H5Sselect_hyperslab(file_space, H5S_SELECT_SET, &start, nullptr, &length, nullptr);
    const hid_t memory_space = H5Screate_simple(1, &length, nullptr);
    const herr_t status = H5Dread(datasets_[i], H5T_NATIVE_INT64, memory_space, file_space,
                                  H5P_DEFAULT, columns[i].data());
    H5Sclose(memory_space);
    H5Sclose(file_space);
    if (status < 0) {
      throw IoError(source_ + ": reading " + kDatasetNames[i] + " elements " +
                    std::to_string(next_) + ".." + std::to_string(next_ + count - 1) + " failed");
    }
  }
  for (uint64_t k = 0; k < count; ++k) {
    const int64_t x = columns[0][k], y = columns[1][k], p = columns[2][k], t = columns[3][k];
    if (x < 0 || x > 65535 || y < 0 || y > 65535 || (p != 0 && p != 1) ||
        (sensor_size_ && !sensor_size_->Contains(static_cast<int>(x), static_cast<int>(y)))) {
      throw ParseError(source_, "event " + std::to_string(next_ + k),
                       "invalid x, y or p (" + std::to_string(x) + ", " + std::to_string(y) + ", " +
                           std::to_string(p) + ")");
    }
    int64_t time_us = 0;
    if (__builtin_add_overflow(t, t_offset_us_, &time_us) ||
        time_us < -9'000'000'000'000'000 / 1000 || time_us > 9'000'000'000'000'000 / 1000) {
      throw ParseError(source_, "event " + std::to_string(next_ + k), "time out of range");
    }
    out->push_back({time_us * 1000, static_cast<uint16_t>(x), static_cast<uint16_t>(y),
                    p == 1 ? int8_t{1} : int8_t{-1}});
  }
  next_ += count;
  return count;
}

}  // namespace evloc
