#include "localizer/service/locate_rpc.h"

#include <chrono>
#include <vector>

#include <opencv2/imgcodecs.hpp>

#include "core/common/error.h"
#include "core/geo/geo_trajectory.h"
#include "localizer/service/session.h"
#include "proto/convert/proto_convert.h"

namespace evloc::service {
namespace {

// Big-endian 16- and 32-bit values at `offset` (the caller checked the length).
uint32_t BigEndian16(const std::string& bytes, size_t offset) {
  return (static_cast<uint32_t>(static_cast<uint8_t>(bytes[offset])) << 8) |
         static_cast<uint8_t>(bytes[offset + 1]);
}

uint32_t BigEndian32(const std::string& bytes, size_t offset) {
  return (BigEndian16(bytes, offset) << 16) | BigEndian16(bytes, offset + 2);
}

// A size of 1..65535 on each side (the camera's limits), or nullopt.
std::optional<EncodedImageSize> ValidSize(uint32_t width, uint32_t height) {
  if (width < 1 || height < 1 || width > 65535 || height > 65535) return std::nullopt;
  return EncodedImageSize{static_cast<int>(width), static_cast<int>(height)};
}

}  // namespace

std::optional<EncodedImageSize> ReadEncodedImageSize(const std::string& bytes) {
  static const std::string kPngSignature("\x89PNG\r\n\x1a\n", 8);
  if (bytes.size() >= 24 && bytes.compare(0, 8, kPngSignature) == 0 &&
      bytes.compare(12, 4, "IHDR") == 0) {
    return ValidSize(BigEndian32(bytes, 16), BigEndian32(bytes, 20));
  }
  if (bytes.size() < 4 || static_cast<uint8_t>(bytes[0]) != 0xff ||
      static_cast<uint8_t>(bytes[1]) != 0xd8) {
    return std::nullopt;
  }
  // JPEG: walk the marker segments up to the first start-of-frame.
  size_t offset = 2;
  while (offset + 4 <= bytes.size()) {
    if (static_cast<uint8_t>(bytes[offset]) != 0xff) return std::nullopt;
    const uint8_t marker = static_cast<uint8_t>(bytes[offset + 1]);
    if (marker == 0xff) {  // Fill byte.
      ++offset;
      continue;
    }
    const uint32_t length = BigEndian16(bytes, offset + 2);
    if (length < 2) return std::nullopt;
    const bool start_of_frame =
        marker >= 0xc0 && marker <= 0xcf && marker != 0xc4 && marker != 0xc8 && marker != 0xcc;
    if (start_of_frame) {
      if (offset + 9 > bytes.size() || length < 7) return std::nullopt;
      return ValidSize(BigEndian16(bytes, offset + 7), BigEndian16(bytes, offset + 5));
    }
    if (marker == 0xd9 || marker == 0xda) return std::nullopt;  // End of image or scan first.
    offset += 2 + length;
  }
  return std::nullopt;
}

cv::Mat LocateImageFromProto(const api::LocateRequest& request, const Camera& camera) {
  switch (request.image_case()) {
    case api::LocateRequest::kGray:
      return GrayFromProto(request.gray().width(), request.gray().height(), request.gray().pixels(),
                           camera, "LocateRequest.gray");
    case api::LocateRequest::kEncoded: {
      const std::string& bytes = request.encoded();
      const std::optional<EncodedImageSize> size = ReadEncodedImageSize(bytes);
      if (!size) {
        throw InvalidArgumentError(
            "LocateRequest.encoded: not a PNG or JPEG file (or its header is malformed)");
      }
      if (size->width != camera.width || size->height != camera.height) {
        throw InvalidArgumentError("LocateRequest.encoded: size " + std::to_string(size->width) +
                                   "x" + std::to_string(size->height) +
                                   " differs from the camera's " + std::to_string(camera.width) +
                                   "x" + std::to_string(camera.height));
      }
      const cv::Mat buffer(1, static_cast<int>(bytes.size()), CV_8UC1,
                           const_cast<char*>(bytes.data()));
      cv::Mat gray;
      try {
        gray = cv::imdecode(buffer, cv::IMREAD_GRAYSCALE);
      } catch (const cv::Exception& error) {
        throw InvalidArgumentError(std::string("LocateRequest.encoded: cannot decode: ") +
                                   error.what());
      }
      if (gray.empty() || gray.cols != camera.width || gray.rows != camera.height ||
          gray.type() != CV_8UC1) {
        throw InvalidArgumentError(
            "LocateRequest.encoded: cannot decode the image as 8-bit grey of the camera's size");
      }
      return gray;
    }
    case api::LocateRequest::IMAGE_NOT_SET:
      break;
  }
  throw InvalidArgumentError("LocateRequest: the image is missing (set encoded or gray)");
}

relocalization::LocateOptions NearGnssFix(relocalization::LocateOptions options,
                                          const GnssPrior& prior, const GeoAnchor& anchor) {
  options.search_center = GeoReference(anchor).MapFromGeodetic(prior.position);
  options.search_radius_m = GnssSearchRadiusM(prior, anchor);
  return options;
}

api::LocateResponse LocateResponseFromResult(const relocalization::LocateResult& result) {
  api::LocateResponse response;
  const bool found = result.status == relocalization::LocateStatus::kFound;
  response.set_status(found ? api::FOUND : api::NOT_FOUND);
  if (found) {
    *response.mutable_world_from_cam() = RigidToProto(result.world_from_cam);
    for (int row = 0; row < 6; ++row) {
      for (int col = 0; col < 6; ++col) response.add_covariance(result.covariance(row, col));
    }
  }
  response.set_inliers(static_cast<uint32_t>(result.inliers));
  response.set_keyframe(result.keyframe);
  response.set_score(result.score);
  response.set_reason(result.reason);
  return response;
}

namespace {

// The request's camera, checked against the server's limit, after checking that an image is set.
// Throws InvalidArgumentError.
Camera CheckedLocateCamera(const api::LocateRequest& request, int64_t max_camera_pixels) {
  if (!request.has_camera()) throw InvalidArgumentError("LocateRequest.camera is missing");
  const Camera camera = CameraFromProto(request.camera(), "LocateRequest.camera");
  const int64_t pixels = int64_t{camera.width} * camera.height;
  if (pixels > max_camera_pixels) {
    throw InvalidArgumentError("LocateRequest.camera: " + std::to_string(camera.width) + "x" +
                               std::to_string(camera.height) + " = " + std::to_string(pixels) +
                               " pixels exceeds this server's limit of " +
                               std::to_string(max_camera_pixels) +
                               " (evloc-localizer --max-camera-pixels)");
  }
  if (request.image_case() == api::LocateRequest::IMAGE_NOT_SET) {
    throw InvalidArgumentError("LocateRequest: the image is missing (set encoded or gray)");
  }
  return camera;
}

// The status of the exception being handled (inside a catch block).
grpc::Status StatusOfCurrentException(const std::string& map_name) {
  try {
    throw;
  } catch (const MapNotFoundError& error) {
    return {grpc::StatusCode::NOT_FOUND, error.what()};
  } catch (const InvalidArgumentError& error) {
    return {grpc::StatusCode::INVALID_ARGUMENT, error.what()};
  } catch (const Error& error) {
    return {grpc::StatusCode::FAILED_PRECONDITION,
            "map '" + map_name + "' cannot be loaded: " + error.what()};
  }
}

}  // namespace

grpc::Status LocateInLoadedMap(const api::LocateRequest& request, const LoadedMap& map,
                               int64_t max_camera_pixels,
                               const relocalization::LocateOptions& options,
                               api::LocateResponse* response) {
  const auto start = std::chrono::steady_clock::now();
  try {
    const Camera camera = CheckedLocateCamera(request, max_camera_pixels);
    const cv::Mat gray = LocateImageFromProto(request, camera);
    if (!map.site && !map.map.relocalization) {
      return {grpc::StatusCode::FAILED_PRECONDITION,
              "map '" + map.name + "': " + relocalization::kNoRelocalizationDataMessage};
    }
    relocalization::LocateOptions located = options;
    if (request.has_gnss_fix()) {
      // Only the keyframes near the fix are retrieved (docs/geo.md, "GNSS prior").
      const GnssPrior prior = GnssPriorFromProto(request.gnss_fix(), "LocateRequest.gnss_fix");
      if (!map.map.geo_anchor) {
        return {grpc::StatusCode::FAILED_PRECONDITION,
                "LocateRequest.gnss_fix: " + MissingGeoAnchorMessage(map.name)};
      }
      located = NearGnssFix(located, prior, *map.map.geo_anchor);
    }
    if (map.site) {
      // The tiles near the fix (every tile without one), verified against the tiles a session
      // at the pose would track against (docs/relocalization.md, "Sites").
      const relocalization::LocateResult result =
          relocalization::LocateImageInSite(map.site, map.tiles, camera, gray, located);
      *response = LocateResponseFromResult(result);
      if (result.tile >= 0) {
        response->set_tile(map.site->manifest.tiles[static_cast<size_t>(result.tile)].file_name);
      }
    } else {
      *response = LocateResponseFromResult(
          relocalization::LocateImage(map.map, *map.visibility, camera, gray, located));
    }
    *response->mutable_map() = DescribeMap(map);
  } catch (const Error&) {
    return StatusOfCurrentException(map.name);
  }
  response->set_locate_ms(
      std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count());
  return grpc::Status::OK;
}

grpc::Status HandleLocate(const api::LocateRequest& request, MapRegistry& registry,
                          int64_t max_camera_pixels, const relocalization::LocateOptions& options,
                          api::LocateResponse* response) {
  std::shared_ptr<const LoadedMap> map;
  try {
    // The request is checked before its map is loaded: a bad request costs no map load.
    CheckedLocateCamera(request, max_camera_pixels);
    map = registry.Get(request.map_name(), request.map_version());
  } catch (const Error&) {
    return StatusOfCurrentException(request.map_name());
  }
  return LocateInLoadedMap(request, *map, max_camera_pixels, options, response);
}

}  // namespace evloc::service
