// The Locate RPC without the network (proto/evloc/localizer.proto, docs/api.md): request
// validation, image decoding bounded by the camera size, and LocateImage against a registry map.
// The server's handler and the fuzz target call HandleLocate.
#pragma once

#include <cstdint>
#include <optional>
#include <string>

#include <grpcpp/support/status.h>
#include <opencv2/core/mat.hpp>

#include "core/camera/camera.h"
#include "evloc/localizer.pb.h"
#include "localizer/relocalization/image_locator.h"
#include "localizer/service/map_registry.h"
#include "localizer/service/session.h"

namespace evloc::service {

// Width and height of an encoded image.
struct EncodedImageSize {
  // Width, pixels.
  int width = 0;
  // Height, pixels.
  int height = 0;
};

// The size a PNG (IHDR) or baseline/progressive JPEG (SOF marker) file declares, read from its
// header without decoding; nullopt for other formats or a malformed header.
std::optional<EncodedImageSize> ReadEncodedImageSize(const std::string& bytes);

// The request's image as grey pixels (CV_8UC1) of the camera's size: raw pixels are copied, a
// PNG or JPEG is decoded only after its header declares the camera's size (so decoding never
// allocates more than the camera's pixels). Throws InvalidArgumentError for a missing image, a
// size mismatch, another format or undecodable bytes.
cv::Mat LocateImageFromProto(const api::LocateRequest& request, const Camera& camera);

// `options` narrowed to the keyframes (and in a site the tiles) within GnssSearchRadiusM of a
// GNSS fix, converted to the map frame through `anchor` (docs/geo.md, "GNSS prior"): the Locate
// RPC's gnss_fix and evloc-localizer locate --gnss.
relocalization::LocateOptions NearGnssFix(relocalization::LocateOptions options,
                                          const GnssPrior& prior, const GeoAnchor& anchor);

// The response fields of a result (map and locate_ms are left unset).
api::LocateResponse LocateResponseFromResult(const relocalization::LocateResult& result);

// Locates the request's image in an already loaded map: the camera and image checks of
// HandleLocate (the image is decoded), then FAILED_PRECONDITION for a map without relocalization
// data, else OK with the
// response (its map description included). Never throws for a bad request.
grpc::Status LocateInLoadedMap(const api::LocateRequest& request, const LoadedMap& map,
                               int64_t max_camera_pixels,
                               const relocalization::LocateOptions& options,
                               api::LocateResponse* response);

// Handles one Locate request: validates the camera (at most max_camera_pixels) and the image,
// gets the map from the registry (loading it on first use), checks that it has relocalization
// data and runs LocateImage with `options`. Returns OK with the response (FOUND or NOT_FOUND),
// or NOT_FOUND (unknown map), INVALID_ARGUMENT (bad camera or image), FAILED_PRECONDITION (a map
// that cannot be loaded, or has no relocalization data: the message says how to upgrade it).
// Never throws for a bad request; safe to call from many threads at once.
grpc::Status HandleLocate(const api::LocateRequest& request, MapRegistry& registry,
                          int64_t max_camera_pixels, const relocalization::LocateOptions& options,
                          api::LocateResponse* response);

}  // namespace evloc::service
