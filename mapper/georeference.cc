#include "mapper/georeference.h"

#include <exiv2/exiv2.hpp>

#include <cmath>
#include <iomanip>
#include <numbers>
#include <sstream>
#include <unordered_map>
#include <vector>

#include "core/common/cli.h"
#include "core/common/error.h"
#include "core/geo/geo_points.h"

namespace evloc::mapper {
namespace {

constexpr double kRadPerDeg = std::numbers::pi / 180.0;

// The camera centres of the map's keyframes by image name.
std::unordered_map<std::string, Eigen::Vector3d> KeyframeCentres(const Map& map) {
  std::unordered_map<std::string, Eigen::Vector3d> centres;
  for (const Keyframe& keyframe : map.keyframes) {
    if (!keyframe.image_name.empty()) {
      centres[keyframe.image_name] = keyframe.cam_from_world.Inverse().translation;
    }
  }
  return centres;
}

GeoReferenceResult FromPointsFile(const Map& map, const std::filesystem::path& file,
                                  const GeoAlignmentOptions& alignment) {
  const std::vector<GeoPointRecord> records = ReadGeoPoints(file);
  const auto centres = KeyframeCentres(map);
  std::vector<GeoCorrespondence> correspondences;
  size_t images = 0;
  for (const GeoPointRecord& record : records) {
    GeoCorrespondence correspondence;
    correspondence.geodetic = record.geodetic;
    correspondence.label = file.string() + ": line " + std::to_string(record.line);
    if (record.kind == GeoPointRecord::Kind::kImage) {
      const auto centre = centres.find(record.image_name);
      if (centre == centres.end()) {
        throw InvalidArgumentError(correspondence.label + ": image '" + record.image_name +
                                   "' is not a keyframe of the map (evloc-mapper info lists the "
                                   "map; only keyframe images have a pose in it)");
      }
      correspondence.p_map = centre->second;
      ++images;
    } else {
      correspondence.p_map = record.p_map;
    }
    correspondences.push_back(std::move(correspondence));
  }
  GeoReferenceResult result;
  result.alignment = AlignMapToGeodetic(correspondences, alignment, kGeoAnchorSourceSurvey);
  result.anchor = result.alignment->anchor;
  result.inputs = std::to_string(images) + " images and " +
                  std::to_string(records.size() - images) + " points from " + file.string();
  return result;
}

GeoReferenceResult FromExif(const Map& map, const std::filesystem::path& image_dir,
                            const GeoAlignmentOptions& alignment) {
  std::vector<GeoCorrespondence> correspondences;
  size_t keyframes_with_names = 0;
  for (const Keyframe& keyframe : map.keyframes) {
    if (keyframe.image_name.empty()) continue;
    ++keyframes_with_names;
    const std::filesystem::path image = image_dir / keyframe.image_name;
    const std::optional<GeodeticPoint> position = ReadExifGnssPosition(image);
    if (!position) continue;
    GeoCorrespondence correspondence;
    correspondence.p_map = keyframe.cam_from_world.Inverse().translation;
    correspondence.geodetic = *position;
    correspondence.label = image.string() + " (EXIF GNSS)";
    correspondences.push_back(std::move(correspondence));
  }
  if (correspondences.size() < 3) {
    throw InvalidArgumentError(
        "--geo-exif: " + std::to_string(correspondences.size()) + " of the " +
        std::to_string(keyframes_with_names) + " keyframe images in '" + image_dir.string() +
        "' carry GNSS tags (at least 3 needed); use --geo-points or --geo-anchor instead");
  }
  GeoReferenceResult result;
  result.alignment = AlignMapToGeodetic(correspondences, alignment, kGeoAnchorSourceExif);
  result.anchor = result.alignment->anchor;
  result.inputs = std::to_string(correspondences.size()) + " of " +
                  std::to_string(keyframes_with_names) + " keyframe images with GNSS tags";
  return result;
}

// Degrees from the three rationals of an EXIF GPSLatitude/GPSLongitude tag.
double DegreesFromDms(const Exiv2::Exifdatum& datum, const std::string& where) {
  if (datum.count() != 3) {
    throw ParseError(
        where, datum.key(),
        "expected 3 rationals (degrees, minutes, seconds), got " + std::to_string(datum.count()));
  }
  double degrees = 0.0;
  double unit = 1.0;
  for (long i = 0; i < 3; ++i) {
    const Exiv2::Rational value = datum.toRational(i);
    if (value.second == 0) throw ParseError(where, datum.key(), "zero denominator");
    degrees += unit * static_cast<double>(value.first) / static_cast<double>(value.second);
    unit /= 60.0;
  }
  return degrees;
}

// "D/1 M/1 S/1000000" for a non-negative angle in degrees.
std::string DmsText(double degrees) {
  const double whole_degrees = std::floor(degrees);
  const double minutes_total = (degrees - whole_degrees) * 60.0;
  const double whole_minutes = std::floor(minutes_total);
  const auto micro_seconds =
      static_cast<int64_t>(std::llround((minutes_total - whole_minutes) * 60.0 * 1e6));
  std::ostringstream text;
  text << static_cast<int64_t>(whole_degrees) << "/1 " << static_cast<int64_t>(whole_minutes)
       << "/1 " << micro_seconds << "/1000000";
  return text.str();
}

}  // namespace

GivenGeoAnchor ParseGeoAnchorFlag(const std::string& flag, const std::string& value) {
  std::vector<double> numbers;
  std::stringstream stream(value);
  std::string token;
  while (std::getline(stream, token, ',')) numbers.push_back(ParseDoubleFlag(flag, token));
  if (numbers.size() != 3 && numbers.size() != 4) {
    throw UsageError(flag + " expects LAT,LON,ALT or LAT,LON,ALT,HEADING, got '" + value + "'");
  }
  GivenGeoAnchor anchor;
  anchor.origin = {numbers[0], numbers[1], numbers[2]};
  try {
    CheckGeodeticPoint(anchor.origin, flag);
  } catch (const InvalidArgumentError& error) {
    throw UsageError(error.what());
  }
  if (numbers.size() == 4) {
    if (numbers[3] < -360.0 || numbers[3] > 360.0) {
      throw UsageError(flag + ": heading " + token + " is outside [-360, 360] degrees");
    }
    anchor.map_y_heading_deg = numbers[3];
  }
  return anchor;
}

void GeoReferenceOptions::Check() const {
  const int sources = (given ? 1 : 0) + (points_file ? 1 : 0) + (exif ? 1 : 0);
  if (sources > 1) {
    throw InvalidArgumentError("give one anchor source: --geo-anchor, --geo-points or --geo-exif");
  }
  alignment.Check();
}

GeoReferenceResult GeoReferenceMap(const Map& map, const std::filesystem::path& image_dir,
                                   const GeoReferenceOptions& options) {
  options.Check();
  if (options.points_file) return FromPointsFile(map, *options.points_file, options.alignment);
  if (options.exif) return FromExif(map, image_dir, options.alignment);
  if (!options.given) throw InvalidArgumentError("no anchor source given");
  GeoReferenceResult result;
  result.anchor.origin = options.given->origin;
  // The map's +y axis at heading h: a rotation about up by -h (clockwise seen from above).
  result.anchor.enu_from_map =
      Rigid3d(Eigen::Quaterniond(Eigen::AngleAxisd(-options.given->map_y_heading_deg * kRadPerDeg,
                                                   Eigen::Vector3d::UnitZ())),
              Eigen::Vector3d::Zero());
  result.anchor.source = kGeoAnchorSourceGiven;
  result.anchor.Check();
  result.inputs = "the given origin";
  return result;
}

std::string FormatGeoReference(const GeoAnchor& anchor,
                               const std::optional<GeoAlignment>& alignment,
                               const std::string& inputs) {
  std::ostringstream text;
  text << std::fixed << std::setprecision(9) << "geo anchor: " << anchor.origin.latitude_deg << ", "
       << anchor.origin.longitude_deg << std::setprecision(3) << ", " << anchor.origin.altitude_m
       << " m (WGS84), source " << anchor.source << " (" << inputs << "), sigma "
       << anchor.horizontal_sigma_m << " m horizontal, " << anchor.vertical_sigma_m
       << " m vertical\n";
  if (alignment) text << "geo alignment: " << FormatGeoAlignment(*alignment) << "\n";
  return text.str();
}

std::optional<GeodeticPoint> ReadExifGnssPosition(const std::filesystem::path& image) {
  const std::string where = image.string();
  Exiv2::Image::AutoPtr file;
  try {
    file = Exiv2::ImageFactory::open(where);
    file->readMetadata();
  } catch (const Exiv2::AnyError& error) {
    throw IoError("cannot read the EXIF data of '" + where + "': " + error.what());
  }
  const Exiv2::ExifData& exif = file->exifData();
  const auto find = [&exif](const char* key) {
    const auto datum = exif.findKey(Exiv2::ExifKey(key));
    return datum == exif.end() ? nullptr : &*datum;
  };
  const Exiv2::Exifdatum* latitude = find("Exif.GPSInfo.GPSLatitude");
  const Exiv2::Exifdatum* longitude = find("Exif.GPSInfo.GPSLongitude");
  if (!latitude || !longitude) return std::nullopt;
  GeodeticPoint position;
  position.latitude_deg = DegreesFromDms(*latitude, where);
  position.longitude_deg = DegreesFromDms(*longitude, where);
  const auto reference = [&](const char* key, const char* negative, const char* positive) {
    const Exiv2::Exifdatum* datum = find(key);
    if (!datum) throw ParseError(where, key, "missing (needed with the coordinate)");
    const std::string text = datum->toString();
    if (text == negative) return -1.0;
    if (text == positive) return 1.0;
    throw ParseError(where, key,
                     "'" + text + "' is neither '" + negative + "' nor '" + positive + "'");
  };
  position.latitude_deg *= reference("Exif.GPSInfo.GPSLatitudeRef", "S", "N");
  position.longitude_deg *= reference("Exif.GPSInfo.GPSLongitudeRef", "W", "E");
  if (const Exiv2::Exifdatum* altitude = find("Exif.GPSInfo.GPSAltitude")) {
    const Exiv2::Rational value = altitude->toRational(0);
    if (altitude->count() != 1 || value.second == 0) {
      throw ParseError(where, altitude->key(), "expected one rational with a non-zero denominator");
    }
    position.altitude_m = static_cast<double>(value.first) / static_cast<double>(value.second);
    if (const Exiv2::Exifdatum* below = find("Exif.GPSInfo.GPSAltitudeRef");
        below && below->toLong(0) == 1) {
      position.altitude_m = -position.altitude_m;
    }
  }
  try {
    CheckGeodeticPoint(position, where + ": EXIF GNSS position");
  } catch (const InvalidArgumentError& error) {
    throw ParseError(where, "Exif.GPSInfo", error.what());
  }
  return position;
}

void WriteExifGnssPosition(const std::filesystem::path& image, const GeodeticPoint& position) {
  CheckGeodeticPoint(position, "EXIF GNSS position for " + image.string());
  try {
    auto file = Exiv2::ImageFactory::open(image.string());
    file->readMetadata();
    Exiv2::ExifData exif = file->exifData();
    exif["Exif.GPSInfo.GPSVersionID"] = "2 3 0 0";
    exif["Exif.GPSInfo.GPSLatitudeRef"] = position.latitude_deg < 0 ? "S" : "N";
    exif["Exif.GPSInfo.GPSLatitude"] = DmsText(std::abs(position.latitude_deg));
    exif["Exif.GPSInfo.GPSLongitudeRef"] = position.longitude_deg < 0 ? "W" : "E";
    exif["Exif.GPSInfo.GPSLongitude"] = DmsText(std::abs(position.longitude_deg));
    exif["Exif.GPSInfo.GPSAltitudeRef"] = position.altitude_m < 0 ? "1" : "0";
    std::ostringstream altitude;
    altitude << std::llround(std::abs(position.altitude_m) * 1000.0) << "/1000";
    exif["Exif.GPSInfo.GPSAltitude"] = altitude.str();
    file->setExifData(exif);
    file->writeMetadata();
  } catch (const Exiv2::AnyError& error) {
    throw IoError("cannot write the EXIF GNSS tags of '" + image.string() + "': " + error.what());
  }
}

}  // namespace evloc::mapper
