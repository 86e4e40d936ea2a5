// DSEC-style HDF5 event files: /events/{x,y,p,t} (t in microseconds, uint32 or int64),
// optional /t_offset (microseconds, added to t) and /ms_to_idx (docs/event-formats.md).
#pragma once

#include <cstdint>
#include <filesystem>
#include <optional>
#include <string>

#include "core/events/event_reader.h"

namespace evloc {

// Reads a DSEC-style HDF5 event file in hyperslab blocks.
class DsecHdf5Reader final : public EventReader {
 public:
  // Opens `path`. Throws IoError when the file cannot be opened or a dataset uses a compression
  // filter this HDF5 library lacks (e.g. Blosc, id 32001), ParseError when a dataset is
  // missing, not 1-D integer, or the lengths differ.
  explicit DsecHdf5Reader(const std::filesystem::path& path);
  ~DsecHdf5Reader() override;
  DsecHdf5Reader(const DsecHdf5Reader&) = delete;
  DsecHdf5Reader& operator=(const DsecHdf5Reader&) = delete;

  // Throws ParseError for a polarity other than 0/1 or a coordinate outside 0..65535.
  size_t Read(size_t max_events, EventBuffer* out) override;
  // DSEC files do not record the sensor size: nullopt unless /events has integer attributes
  // `width` and `height`.
  std::optional<SensorSize> sensor_size() const override { return sensor_size_; }
  // Number of events in the file.
  uint64_t event_count() const { return event_count_; }
  // The /t_offset value in microseconds (0 when absent).
  int64_t t_offset_us() const { return t_offset_us_; }

 private:
  std::string source_;
  int64_t file_ = -1;
  int64_t datasets_[4] = {-1, -1, -1, -1};  // x, y, p, t
  uint64_t event_count_ = 0;
  uint64_t next_ = 0;
  int64_t t_offset_us_ = 0;
  std::optional<SensorSize> sensor_size_;
};

}  // namespace evloc
