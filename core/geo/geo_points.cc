#include "core/geo/geo_points.h"

#include <algorithm>
#include <charconv>
#include <cmath>
#include <fstream>
#include <set>
#include <sstream>

#include "core/common/error.h"

namespace evloc {
namespace {

std::vector<std::string_view> SplitFields(std::string_view line) {
  std::vector<std::string_view> fields;
  size_t position = 0;
  while (position < line.size()) {
    while (position < line.size() && (line[position] == ' ' || line[position] == '\t')) ++position;
    const size_t start = position;
    while (position < line.size() && line[position] != ' ' && line[position] != '\t') ++position;
    if (position > start) fields.push_back(line.substr(start, position - start));
  }
  return fields;
}

}  // namespace

std::vector<GeoPointRecord> ParseGeoPoints(std::string_view text, const std::string& source) {
  std::vector<GeoPointRecord> records;
  std::set<std::string, std::less<>> image_names;
  int64_t line_number = 0;
  size_t position = 0;
  while (position < text.size()) {
    ++line_number;
    size_t end = text.find('\n', position);
    if (end == std::string_view::npos) end = text.size();
    std::string_view line = text.substr(position, end - position);
    position = end + 1;
    const auto fail = [&](const std::string& what) {
      return ParseError::AtLine(source, line_number, what);
    };
    if (line.size() > kMaxGeoPointsLineBytes) {
      throw fail("line of " + std::to_string(line.size()) + " bytes (at most " +
                 std::to_string(kMaxGeoPointsLineBytes) + ")");
    }
    if (!line.empty() && line.back() == '\r') line.remove_suffix(1);
    if (line.find('\0') != std::string_view::npos) throw fail("NUL byte in a text file");
    const std::vector<std::string_view> fields = SplitFields(line);
    if (fields.empty() || fields[0].front() == '#') continue;
    const auto number = [&](size_t index, const char* what) {
      const std::string_view field = fields[index];
      double value = 0.0;
      const auto [stop, error] = std::from_chars(field.data(), field.data() + field.size(), value);
      if (error != std::errc() || stop != field.data() + field.size() || !std::isfinite(value)) {
        throw fail(std::string(what) + " '" + std::string(field) + "' is not a finite number");
      }
      return value;
    };
    GeoPointRecord record;
    record.line = line_number;
    size_t first_geodetic = 0;
    if (fields[0] == "image") {
      if (fields.size() != 5) {
        throw fail("an image record is 'image NAME LATITUDE LONGITUDE ALTITUDE' (5 fields), got " +
                   std::to_string(fields.size()));
      }
      record.kind = GeoPointRecord::Kind::kImage;
      record.image_name = std::string(fields[1]);
      if (!image_names.insert(record.image_name).second) {
        throw fail("image '" + record.image_name + "' is listed twice");
      }
      first_geodetic = 2;
    } else if (fields[0] == "point") {
      if (fields.size() != 7) {
        throw fail("a point record is 'point X Y Z LATITUDE LONGITUDE ALTITUDE' (7 fields), got " +
                   std::to_string(fields.size()));
      }
      record.kind = GeoPointRecord::Kind::kPoint;
      record.p_map = {number(1, "x"), number(2, "y"), number(3, "z")};
      first_geodetic = 4;
    } else {
      throw fail("unknown record '" + std::string(fields[0]).substr(0, 64) +
                 "' (expected 'image' or 'point')");
    }
    record.geodetic = {number(first_geodetic, "latitude"), number(first_geodetic + 1, "longitude"),
                       number(first_geodetic + 2, "altitude")};
    try {
      CheckGeodeticPoint(record.geodetic, "position");
    } catch (const InvalidArgumentError& error) {
      throw fail(error.what());
    }
    records.push_back(std::move(record));
  }
  if (records.empty()) {
    throw ParseError::AtLine(source, std::max<int64_t>(line_number, 1),
                             "no 'image' or 'point' record in the geo points file");
  }
  return records;
}

std::vector<GeoPointRecord> ReadGeoPoints(const std::filesystem::path& path) {
  std::ifstream stream(path, std::ios::binary);
  if (!stream) throw IoError("cannot open geo points file '" + path.string() + "'");
  std::ostringstream text;
  text << stream.rdbuf();
  if (stream.bad()) throw IoError("cannot read geo points file '" + path.string() + "'");
  return ParseGeoPoints(text.str(), path.string());
}

}  // namespace evloc
