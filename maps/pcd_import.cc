#include "maps/pcd_import.h"

#include <algorithm>
#include <array>
#include <bit>
#include <charconv>
#include <cmath>
#include <cstring>
#include <limits>
#include <sstream>
#include <string>
#include <string_view>

#include "core/common/error.h"
#include "core/common/file_util.h"

namespace evloc {
namespace {

constexpr size_t kMaxReportedDrops = 10;
constexpr std::array<const char*, 6> kRequiredFields = {"x",        "y",        "z",
                                                        "normal_x", "normal_y", "normal_z"};

// One field of the PCD header.
struct PcdField {
  std::string name;
  int size = 4;
  char type = 'F';
  int count = 1;
};

// The parsed PCD header.
struct PcdHeader {
  std::vector<PcdField> fields;
  uint64_t num_points = 0;
  bool has_points = false;
  std::string data;
  // Offset of the first data byte, and the line number of the first data line.
  size_t data_offset = 0;
  int64_t data_line = 0;
  // Line number of the FIELDS line.
  int64_t fields_line = 0;
};

std::vector<std::string> SplitWords(std::string_view line) {
  std::vector<std::string> words;
  std::istringstream stream{std::string(line)};
  std::string word;
  while (stream >> word) words.push_back(word);
  return words;
}

// Reads the next line starting at *offset (without the newline, and without a trailing '\r').
std::string_view NextLine(const std::string& content, size_t* offset) {
  const size_t begin = *offset;
  size_t end = content.find('\n', begin);
  if (end == std::string::npos) {
    end = content.size();
    *offset = end;
  } else {
    *offset = end + 1;
  }
  std::string_view line(content.data() + begin, end - begin);
  if (!line.empty() && line.back() == '\r') line.remove_suffix(1);
  return line;
}

int ParseHeaderInt(const std::string& word, const std::string& source, int64_t line,
                   const std::string& key) {
  int value = 0;
  const auto [end, error] = std::from_chars(word.data(), word.data() + word.size(), value);
  if (error != std::errc() || end != word.data() + word.size()) {
    throw ParseError::AtLine(source, line, key + ": '" + word + "' is not an integer");
  }
  return value;
}

PcdHeader ParseHeader(const std::string& content, const std::string& source) {
  PcdHeader header;
  size_t offset = 0;
  int64_t line_number = 0;
  std::vector<int> sizes, counts;
  std::vector<char> types;
  while (offset < content.size()) {
    ++line_number;
    const std::string_view line = NextLine(content, &offset);
    const std::vector<std::string> words = SplitWords(line);
    if (words.empty() || words[0][0] == '#') continue;
    const std::string& key = words[0];
    const std::vector<std::string> values(words.begin() + 1, words.end());
    if (key == "VERSION" || key == "WIDTH" || key == "HEIGHT" || key == "VIEWPOINT") {
      continue;
    } else if (key == "FIELDS") {
      for (const std::string& name : values) header.fields.push_back({name});
      header.fields_line = line_number;
    } else if (key == "SIZE") {
      for (const std::string& v : values)
        sizes.push_back(ParseHeaderInt(v, source, line_number, key));
    } else if (key == "TYPE") {
      for (const std::string& v : values) {
        if (v.size() != 1 || (v[0] != 'F' && v[0] != 'I' && v[0] != 'U')) {
          throw ParseError::AtLine(source, line_number, "TYPE '" + v + "' is not F, I or U");
        }
        types.push_back(v[0]);
      }
    } else if (key == "COUNT") {
      for (const std::string& v : values)
        counts.push_back(ParseHeaderInt(v, source, line_number, key));
    } else if (key == "POINTS") {
      if (values.size() != 1) {
        throw ParseError::AtLine(source, line_number, "POINTS needs exactly one value");
      }
      const int points = ParseHeaderInt(values[0], source, line_number, key);
      if (points < 0) throw ParseError::AtLine(source, line_number, "POINTS is negative");
      header.num_points = static_cast<uint64_t>(points);
      header.has_points = true;
    } else if (key == "DATA") {
      if (values.size() != 1) {
        throw ParseError::AtLine(source, line_number, "DATA needs exactly one value");
      }
      header.data = values[0];
      header.data_offset = offset;
      header.data_line = line_number + 1;
      break;
    } else {
      throw ParseError::AtLine(source, line_number,
                               "unknown PCD header key '" + key + "'; is this a PCD file?");
    }
  }
  if (header.data.empty()) {
    throw ParseError::AtLine(source, line_number,
                             "no DATA line: not a PCD file (expected a header ending with "
                             "'DATA ascii' or 'DATA binary')");
  }
  const size_t num_fields = header.fields.size();
  if (num_fields == 0) throw ParseError::AtLine(source, header.data_line - 1, "no FIELDS line");
  if (!header.has_points) throw ParseError::AtLine(source, header.data_line - 1, "no POINTS line");
  const auto check_count = [&](size_t actual, const char* key) {
    if (actual != 0 && actual != num_fields) {
      throw ParseError::AtLine(source, header.data_line - 1,
                               std::string(key) + " has " + std::to_string(actual) +
                                   " entries but FIELDS has " + std::to_string(num_fields));
    }
  };
  check_count(sizes.size(), "SIZE");
  check_count(types.size(), "TYPE");
  check_count(counts.size(), "COUNT");
  for (size_t i = 0; i < num_fields; ++i) {
    if (!sizes.empty()) header.fields[i].size = sizes[i];
    if (!types.empty()) header.fields[i].type = types[i];
    if (!counts.empty()) header.fields[i].count = counts[i];
    if (header.fields[i].count < 1 || (header.fields[i].size != 1 && header.fields[i].size != 2 &&
                                       header.fields[i].size != 4 && header.fields[i].size != 8)) {
      throw ParseError::AtLine(source, header.data_line - 1,
                               "field '" + header.fields[i].name + "' has SIZE " +
                                   std::to_string(header.fields[i].size) + " and COUNT " +
                                   std::to_string(header.fields[i].count));
    }
  }
  return header;
}

// Where each required field sits: its position among the values of a point (ASCII) and its byte
// offset in a record (binary).
struct FieldLayout {
  std::array<size_t, 6> value_index{};
  std::array<size_t, 6> byte_offset{};
  std::array<int, 6> size{};
  size_t values_per_point = 0;
  size_t bytes_per_point = 0;
};

FieldLayout LayoutFields(const PcdHeader& header, const std::string& source) {
  FieldLayout layout;
  std::array<bool, 6> found{};
  for (const PcdField& field : header.fields) {
    for (size_t r = 0; r < kRequiredFields.size(); ++r) {
      if (field.name != kRequiredFields[r]) continue;
      if (field.type != 'F' || (field.size != 4 && field.size != 8) || field.count != 1) {
        throw ParseError::AtLine(
            source, header.fields_line,
            "field '" + field.name + "' must be a single float (TYPE F, SIZE 4 or 8, COUNT 1)");
      }
      found[r] = true;
      layout.value_index[r] = layout.values_per_point;
      layout.byte_offset[r] = layout.bytes_per_point;
      layout.size[r] = field.size;
    }
    layout.values_per_point += static_cast<size_t>(field.count);
    layout.bytes_per_point += static_cast<size_t>(field.size) * static_cast<size_t>(field.count);
  }
  for (size_t r = 0; r < kRequiredFields.size(); ++r) {
    if (!found[r]) {
      throw ParseError::AtLine(source, header.fields_line,
                               std::string("PCD file has no field '") + kRequiredFields[r] +
                                   "'; a Canny-EVT map needs FIELDS x y z normal_x normal_y "
                                   "normal_z");
    }
  }
  return layout;
}

// Accumulates points into the map and the report.
class PointCollector {
 public:
  PointCollector(const PcdImportOptions& options, PcdImport* result)
      : options_(options), result_(result) {}

  void Add(size_t index, const std::array<double, 6>& values) {
    PcdImportReport& report = result_->report;
    const Eigen::Vector3d position(values[0], values[1], values[2]);
    const Eigen::Vector3d end_point(values[3], values[4], values[5]);
    if (!position.allFinite() || !end_point.allFinite()) {
      ++report.num_dropped_non_finite;
      NoteDrop(index);
      return;
    }
    const Eigen::Vector3d offset = end_point - position;
    const double length = offset.norm();
    if (!(length >= options_.min_gradient_offset_m)) {
      ++report.num_dropped_zero_gradient;
      NoteDrop(index);
      return;
    }
    offsets_.push_back(length);
    result_->map.AddPoint(position.cast<float>(), (offset / length).cast<float>());
  }

  void Finish() {
    PcdImportReport& report = result_->report;
    report.num_imported = result_->map.size();
    if (!offsets_.empty()) {
      auto middle = offsets_.begin() + offsets_.size() / 2;
      std::nth_element(offsets_.begin(), middle, offsets_.end());
      report.median_gradient_offset_m = *middle;
    }
  }

 private:
  void NoteDrop(size_t index) {
    if (result_->report.first_dropped_points.size() < kMaxReportedDrops) {
      result_->report.first_dropped_points.push_back(index);
    }
  }

  const PcdImportOptions& options_;
  PcdImport* result_;
  std::vector<double> offsets_;
};

void ReadAscii(const std::string& content, const PcdHeader& header, const FieldLayout& layout,
               const std::string& source, PointCollector* collector) {
  size_t offset = header.data_offset;
  int64_t line_number = header.data_line - 1;
  std::vector<double> values(layout.values_per_point);
  uint64_t index = 0;
  while (offset < content.size()) {
    ++line_number;
    const std::string_view line = NextLine(content, &offset);
    if (line.find_first_not_of(" \t") == std::string_view::npos) continue;
    if (index == header.num_points) {
      throw ParseError::AtLine(source, line_number,
                               "more data lines than POINTS " + std::to_string(header.num_points));
    }
    const char* cursor = line.data();
    const char* end = line.data() + line.size();
    for (size_t v = 0; v < values.size(); ++v) {
      while (cursor < end && (*cursor == ' ' || *cursor == '\t')) ++cursor;
      if (cursor == end) {
        throw ParseError::AtLine(
            source, line_number,
            "expected " + std::to_string(values.size()) + " values, found " + std::to_string(v));
      }
      // from_chars also accepts "nan" and "inf", which PCL writes for invalid points.
      const auto [next, error] = std::from_chars(cursor, end, values[v]);
      if (error != std::errc() || (next != end && *next != ' ' && *next != '\t')) {
        const char* word_end =
            std::find_if(cursor, end, [](char c) { return c == ' ' || c == '\t'; });
        throw ParseError::AtLine(source, line_number,
                                 "value " + std::to_string(v + 1) + " '" +
                                     std::string(cursor, word_end) + "' is not a number");
      }
      cursor = next;
    }
    while (cursor < end && (*cursor == ' ' || *cursor == '\t')) ++cursor;
    if (cursor != end) {
      throw ParseError::AtLine(source, line_number,
                               "more than " + std::to_string(values.size()) + " values");
    }
    std::array<double, 6> required{};
    for (size_t r = 0; r < required.size(); ++r) required[r] = values[layout.value_index[r]];
    collector->Add(index, required);
    ++index;
  }
  if (index != header.num_points) {
    throw ParseError::AtLine(source, line_number,
                             "file ends after " + std::to_string(index) + " of " +
                                 std::to_string(header.num_points) +
                                 " points (POINTS); the file is truncated");
  }
}

void ReadBinary(const std::string& content, const PcdHeader& header, const FieldLayout& layout,
                const std::string& source, PointCollector* collector) {
  static_assert(std::endian::native == std::endian::little, "PCD binary data is little-endian");
  const uint64_t available = content.size() - header.data_offset;
  const uint64_t needed = header.num_points * layout.bytes_per_point;
  if (available < needed) {
    throw ParseError::AtByte(source, content.size(),
                             "binary PCD data is truncated: " + std::to_string(header.num_points) +
                                 " points of " + std::to_string(layout.bytes_per_point) +
                                 " bytes need " + std::to_string(needed) +
                                 " bytes after the "
                                 "header, the file has " +
                                 std::to_string(available));
  }
  const char* record = content.data() + header.data_offset;
  for (uint64_t index = 0; index < header.num_points; ++index, record += layout.bytes_per_point) {
    std::array<double, 6> required{};
    for (size_t r = 0; r < required.size(); ++r) {
      if (layout.size[r] == 4) {
        float value;
        std::memcpy(&value, record + layout.byte_offset[r], sizeof(value));
        required[r] = value;
      } else {
        std::memcpy(&required[r], record + layout.byte_offset[r], sizeof(double));
      }
    }
    collector->Add(index, required);
  }
}

}  // namespace

void PcdImportOptions::Check() const {
  if (!std::isfinite(min_gradient_offset_m) || min_gradient_offset_m <= 0.0) {
    throw InvalidArgumentError("PCD import min_gradient_offset_m must be finite and > 0, got " +
                               std::to_string(min_gradient_offset_m));
  }
}

PcdImport ImportCannyEvtPcd(const std::filesystem::path& path, const PcdImportOptions& options) {
  options.Check();
  const std::string source = path.string();
  const std::string content = ReadFileToString(path);
  const PcdHeader header = ParseHeader(content, source);
  const FieldLayout layout = LayoutFields(header, source);
  PcdImport result;
  result.report.num_points_in_file = header.num_points;
  result.map.Reserve(header.num_points);
  PointCollector collector(options, &result);
  if (header.data == "ascii") {
    ReadAscii(content, header, layout, source, &collector);
  } else if (header.data == "binary") {
    ReadBinary(content, header, layout, source, &collector);
  } else if (header.data == "binary_compressed") {
    throw ParseError::AtLine(source, header.data_line - 1,
                             "DATA binary_compressed is not supported; convert the file with "
                             "`pcl_convert_pcd_ascii_binary IN.pcd OUT.pcd 1` (binary) first");
  } else {
    throw ParseError::AtLine(source, header.data_line - 1,
                             "unknown DATA format '" + header.data + "' (ascii or binary)");
  }
  collector.Finish();
  return result;
}

}  // namespace evloc
