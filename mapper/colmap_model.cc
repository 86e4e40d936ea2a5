#include "mapper/colmap_model.h"

#include <charconv>
#include <cmath>
#include <cstdio>
#include <sstream>

#include "core/common/error.h"
#include "core/common/file_util.h"

namespace evloc::mapper {
namespace {

// Splits a line into whitespace-separated tokens.
std::vector<std::string> Tokenize(const std::string& line) {
  std::istringstream stream(line);
  std::vector<std::string> tokens;
  std::string token;
  while (stream >> token) tokens.push_back(token);
  return tokens;
}

// The lines of a file with their 1-based numbers, skipping nothing.
std::vector<std::string> ReadLines(const std::filesystem::path& path) {
  const std::string text = ReadFileToString(path);
  std::vector<std::string> lines;
  std::string line;
  std::istringstream stream(text);
  while (std::getline(stream, line)) {
    if (!line.empty() && line.back() == '\r') line.pop_back();
    lines.push_back(line);
  }
  return lines;
}

bool IsCommentOrBlank(const std::string& line) {
  const size_t first = line.find_first_not_of(" \t");
  return first == std::string::npos || line[first] == '#';
}

double ParseDouble(const std::string& token, const std::string& source, int64_t line,
                   const std::string& field) {
  double value = 0.0;
  const auto result = std::from_chars(token.data(), token.data() + token.size(), value);
  if (result.ec != std::errc() || result.ptr != token.data() + token.size() ||
      !std::isfinite(value)) {
    throw ParseError::AtLine(source, line, field + " '" + token + "' is not a finite number");
  }
  return value;
}

template <typename Integer>
Integer ParseInteger(const std::string& token, const std::string& source, int64_t line,
                     const std::string& field) {
  Integer value = 0;
  const auto result = std::from_chars(token.data(), token.data() + token.size(), value);
  if (result.ec != std::errc() || result.ptr != token.data() + token.size()) {
    throw ParseError::AtLine(source, line, field + " '" + token + "' is not a valid integer");
  }
  return value;
}

std::string FormatDouble(double value) {
  char buffer[64];
  const auto result = std::to_chars(buffer, buffer + sizeof(buffer), value);
  return std::string(buffer, result.ptr);
}

}  // namespace

double ColmapModel::MeanReprojectionError() const {
  if (points.empty()) return 0.0;
  double sum = 0.0;
  for (const auto& [id, point] : points) sum += point.error;
  return sum / static_cast<double>(points.size());
}

uint32_t ColmapModel::FindImageId(const std::string& name) const {
  for (const auto& [id, image] : images) {
    if (image.name == name) return id;
  }
  return 0;
}

ColmapModel ReadColmapTextModel(const std::filesystem::path& directory) {
  ColmapModel model;
  {
    const std::filesystem::path path = directory / "cameras.txt";
    model.cameras = ParseColmapCameras(ReadFileToString(path), path.string());
  }
  {
    const std::filesystem::path path = directory / "images.txt";
    const std::string source = path.string();
    const std::vector<std::string> lines = ReadLines(path);
    size_t i = 0;
    while (i < lines.size()) {
      const int64_t line_number = static_cast<int64_t>(i) + 1;
      if (IsCommentOrBlank(lines[i])) {
        ++i;
        continue;
      }
      const std::vector<std::string> tokens = Tokenize(lines[i]);
      if (tokens.size() != 10) {
        throw ParseError::AtLine(source, line_number,
                                 "expected IMAGE_ID QW QX QY QZ TX TY TZ CAMERA_ID NAME (" +
                                     std::to_string(tokens.size()) + " fields)");
      }
      ColmapImage image;
      image.image_id = ParseInteger<uint32_t>(tokens[0], source, line_number, "IMAGE_ID");
      const Eigen::Quaterniond rotation(ParseDouble(tokens[1], source, line_number, "QW"),
                                        ParseDouble(tokens[2], source, line_number, "QX"),
                                        ParseDouble(tokens[3], source, line_number, "QY"),
                                        ParseDouble(tokens[4], source, line_number, "QZ"));
      if (rotation.norm() < 1e-12) {
        throw ParseError::AtLine(source, line_number, "zero quaternion");
      }
      const Eigen::Vector3d translation(ParseDouble(tokens[5], source, line_number, "TX"),
                                        ParseDouble(tokens[6], source, line_number, "TY"),
                                        ParseDouble(tokens[7], source, line_number, "TZ"));
      image.cam_from_world = Rigid3d(rotation, translation);
      image.camera_id = ParseInteger<uint32_t>(tokens[8], source, line_number, "CAMERA_ID");
      image.name = tokens[9];
      if (!model.cameras.contains(image.camera_id)) {
        throw ParseError::AtLine(source, line_number,
                                 "unknown CAMERA_ID " + std::to_string(image.camera_id));
      }
      // The keypoint line follows the pose line; it may be empty or missing at the end.
      ++i;
      if (i < lines.size()) {
        const int64_t keypoint_line_number = static_cast<int64_t>(i) + 1;
        const std::vector<std::string> keypoint_tokens = Tokenize(lines[i]);
        if (keypoint_tokens.size() % 3 != 0) {
          throw ParseError::AtLine(source, keypoint_line_number, "expected triples X Y POINT3D_ID");
        }
        for (size_t k = 0; k < keypoint_tokens.size(); k += 3) {
          const double x = ParseDouble(keypoint_tokens[k], source, keypoint_line_number, "X");
          const double y = ParseDouble(keypoint_tokens[k + 1], source, keypoint_line_number, "Y");
          const int64_t id = ParseInteger<int64_t>(keypoint_tokens[k + 2], source,
                                                   keypoint_line_number, "POINT3D_ID");
          image.keypoints.emplace_back(x - kColmapPixelOffset, y - kColmapPixelOffset);
          image.point3d_ids.push_back(id < 0 ? kNoPoint3D : static_cast<uint64_t>(id));
        }
        ++i;
      }
      if (!model.images.emplace(image.image_id, std::move(image)).second) {
        throw ParseError::AtLine(source, line_number, "duplicate IMAGE_ID");
      }
    }
  }
  {
    const std::filesystem::path path = directory / "points3D.txt";
    const std::string source = path.string();
    const std::vector<std::string> lines = ReadLines(path);
    for (size_t i = 0; i < lines.size(); ++i) {
      const int64_t line_number = static_cast<int64_t>(i) + 1;
      if (IsCommentOrBlank(lines[i])) continue;
      const std::vector<std::string> tokens = Tokenize(lines[i]);
      if (tokens.size() < 8 || (tokens.size() - 8) % 2 != 0) {
        throw ParseError::AtLine(source, line_number,
                                 "expected POINT3D_ID X Y Z R G B ERROR TRACK[] as "
                                 "(IMAGE_ID, POINT2D_IDX) pairs");
      }
      ColmapPoint3D point;
      point.point3d_id = ParseInteger<uint64_t>(tokens[0], source, line_number, "POINT3D_ID");
      for (int k = 0; k < 3; ++k) {
        point.position[k] = ParseDouble(tokens[1 + k], source, line_number, "XYZ");
        point.color[k] = ParseInteger<int>(tokens[4 + k], source, line_number, "RGB");
      }
      point.error = ParseDouble(tokens[7], source, line_number, "ERROR");
      for (size_t k = 8; k < tokens.size(); k += 2) {
        ColmapTrackElement element;
        element.image_id = ParseInteger<uint32_t>(tokens[k], source, line_number, "IMAGE_ID");
        element.keypoint_index =
            ParseInteger<uint32_t>(tokens[k + 1], source, line_number, "POINT2D_IDX");
        const auto image = model.images.find(element.image_id);
        if (image == model.images.end()) {
          throw ParseError::AtLine(
              source, line_number,
              "track refers to unknown IMAGE_ID " + std::to_string(element.image_id));
        }
        if (element.keypoint_index >= image->second.keypoints.size()) {
          throw ParseError::AtLine(source, line_number,
                                   "track refers to keypoint " +
                                       std::to_string(element.keypoint_index) + " of image " +
                                       std::to_string(element.image_id) + ", which has only " +
                                       std::to_string(image->second.keypoints.size()));
        }
        point.track.push_back(element);
      }
      if (!model.points.emplace(point.point3d_id, std::move(point)).second) {
        throw ParseError::AtLine(source, line_number, "duplicate POINT3D_ID");
      }
    }
  }
  // Every keypoint's 3D point id must exist.
  for (const auto& [image_id, image] : model.images) {
    for (const uint64_t point3d_id : image.point3d_ids) {
      if (point3d_id != kNoPoint3D && !model.points.contains(point3d_id)) {
        throw ParseError((directory / "images.txt").string(), "image " + image.name,
                         "keypoint refers to unknown POINT3D_ID " + std::to_string(point3d_id));
      }
    }
  }
  return model;
}

void WriteColmapTextModel(const std::filesystem::path& directory, const ColmapModel& model) {
  std::error_code error;
  std::filesystem::create_directories(directory, error);
  if (error) {
    throw IoError("cannot create directory " + directory.string() + ": " + error.message());
  }
  WriteFileAtomically(directory / "cameras.txt", [&](std::ostream& out) {
    out << "# Camera list with one line of data per camera:\n"
           "#   CAMERA_ID, MODEL, WIDTH, HEIGHT, PARAMS[]\n";
    for (const auto& [id, camera] : model.cameras) {
      out << id << ' ' << camera.model_name << ' ' << camera.width << ' ' << camera.height;
      for (const double param : camera.params) out << ' ' << FormatDouble(param);
      out << '\n';
    }
  });
  WriteFileAtomically(directory / "images.txt", [&](std::ostream& out) {
    out << "# Image list with two lines of data per image:\n"
           "#   IMAGE_ID, QW, QX, QY, QZ, TX, TY, TZ, CAMERA_ID, NAME\n"
           "#   POINTS2D[] as (X, Y, POINT3D_ID)\n";
    for (const auto& [id, image] : model.images) {
      const Eigen::Quaterniond& q = image.cam_from_world.rotation;
      const Eigen::Vector3d& t = image.cam_from_world.translation;
      out << id << ' ' << FormatDouble(q.w()) << ' ' << FormatDouble(q.x()) << ' '
          << FormatDouble(q.y()) << ' ' << FormatDouble(q.z()) << ' ' << FormatDouble(t.x()) << ' '
          << FormatDouble(t.y()) << ' ' << FormatDouble(t.z()) << ' ' << image.camera_id << ' '
          << image.name << '\n';
      for (size_t k = 0; k < image.keypoints.size(); ++k) {
        if (k > 0) out << ' ';
        const uint64_t point3d_id =
            k < image.point3d_ids.size() ? image.point3d_ids[k] : kNoPoint3D;
        out << FormatDouble(image.keypoints[k].x() + kColmapPixelOffset) << ' '
            << FormatDouble(image.keypoints[k].y() + kColmapPixelOffset) << ' '
            << (point3d_id == kNoPoint3D ? std::string("-1") : std::to_string(point3d_id));
      }
      out << '\n';
    }
  });
  WriteFileAtomically(directory / "points3D.txt", [&](std::ostream& out) {
    out << "# 3D point list with one line of data per point:\n"
           "#   POINT3D_ID, X, Y, Z, R, G, B, ERROR, TRACK[] as (IMAGE_ID, POINT2D_IDX)\n";
    for (const auto& [id, point] : model.points) {
      out << id << ' ' << FormatDouble(point.position.x()) << ' '
          << FormatDouble(point.position.y()) << ' ' << FormatDouble(point.position.z()) << ' '
          << point.color.x() << ' ' << point.color.y() << ' ' << point.color.z() << ' '
          << FormatDouble(point.error);
      for (const ColmapTrackElement& element : point.track) {
        out << ' ' << element.image_id << ' ' << element.keypoint_index;
      }
      out << '\n';
    }
  });
}

std::string FormatColmapParams(const std::vector<double>& params) {
  std::string text;
  for (size_t i = 0; i < params.size(); ++i) {
    if (i > 0) text += ',';
    text += FormatDouble(params[i]);
  }
  return text;
}

}  // namespace evloc::mapper
