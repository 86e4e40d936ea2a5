// Shared parts of the Locate request fuzz target (docs/reliability.md §4): the in-memory maps it
// locates in (the synthetic rectangles map with relocalization data made from a rendered
// keyframe, and the same map without it, as a v1 map) and the seed requests.
#pragma once

#include <memory>
#include <string>
#include <vector>

#include <opencv2/imgcodecs.hpp>

#include "core/features/features.h"
#include "core/features/vocabulary.h"
#include "evloc/localizer.pb.h"
#include "localizer/service/map_registry.h"
#include "localizer/service/testing/service_fixture.h"
#include "localizer/tracking/testing/synthetic_scene.h"
#include "proto/convert/proto_convert.h"

namespace evloc::service::fuzz {

// The camera of the Locate fuzz maps and seeds (small: fast executions).
inline Camera LocateFuzzCamera() { return Camera::Pinhole(160, 120, 125, 125, 79.5, 59.5); }

// The rendered image of the keyframe (the rectangles at the synthetic motion's initial pose).
inline cv::Mat LocateFuzzKeyframeImage() {
  return tracking::testing::RenderRectangles(
      tracking::testing::DefaultRectangles(), LocateFuzzCamera(),
      tracking::testing::SmoothMotion(testing::kInitialTimeNs));
}

// The map "v2": the rectangles map with one keyframe whose features see landmarks 1 m along
// their rays; "v1": the same map without relocalization data.
inline std::shared_ptr<const LoadedMap> LocateFuzzMap(bool with_relocalization) {
  auto loaded = std::make_shared<LoadedMap>();
  loaded->name = with_relocalization ? "v2" : "v1";
  Map& map = loaded->map;
  map = testing::TestMap();
  const Camera camera = LocateFuzzCamera();
  const Rigid3d world_from_cam = tracking::testing::SmoothMotion(testing::kInitialTimeNs);
  map.cameras = {camera};
  Keyframe keyframe;
  keyframe.cam_from_world = world_from_cam.Inverse();
  map.keyframes = {keyframe};
  if (with_relocalization) {
    const features::Features features =
        features::ExtractFeatures(LocateFuzzKeyframeImage(), features::FeatureOptions());
    RelocalizationData data;
    features::VocabularyOptions vocabulary_options;
    vocabulary_options.num_words = std::max(1, std::min(4, features.size()));
    const features::Vocabulary vocabulary =
        features::Vocabulary::Train(std::vector<features::Features>{features}, vocabulary_options);
    data.vocabulary = vocabulary.ToVector();
    KeyframeFeatures keyframe_features;
    keyframe_features.keypoints = features.keypoints;
    keyframe_features.descriptors = features.descriptors;
    keyframe_features.global_descriptor = vocabulary.EncodeVlad(features);
    for (const Eigen::Vector2f& keypoint : features.keypoints) {
      Eigen::Vector3d ray;
      camera.Unproject(keypoint.cast<double>(), &ray);
      keyframe_features.landmarks.push_back(static_cast<uint32_t>(data.landmarks.size()));
      data.landmarks.push_back((world_from_cam * (ray / ray.z())).cast<float>());
    }
    data.keyframes = {keyframe_features};
    map.relocalization = std::move(data);
    // And a geo anchor, so that LocateRequest.gnss_fix reaches the restricted retrieval.
    GeoAnchor anchor;
    anchor.origin = {46.5191, 6.5668, 372.0};
    map.geo_anchor = anchor;
  }
  map.Check();
  loaded->content_crc32c = ComputeMapContentChecksum(map);
  loaded->version = MapVersionString(loaded->content_crc32c);
  loaded->info = SummarizeMap(map);
  loaded->visibility = std::make_unique<VisibilityIndex>(map);
  return loaded;
}

// Seed requests: the keyframe image as raw pixels, PNG and JPEG on "v2", raw pixels with a GNSS
// fix on "v2", as raw pixels on "v1", and one without an image.
inline std::vector<api::LocateRequest> LocateSeedRequests() {
  const cv::Mat image = LocateFuzzKeyframeImage();
  api::LocateRequest base;
  base.set_map_name("v2");
  *base.mutable_camera() = CameraToProto(LocateFuzzCamera());
  std::vector<api::LocateRequest> requests;
  api::LocateRequest raw = base;
  raw.mutable_gray()->set_width(image.cols);
  raw.mutable_gray()->set_height(image.rows);
  raw.mutable_gray()->set_pixels(
      std::string(reinterpret_cast<const char*>(image.data), image.total()));
  requests.push_back(raw);
  for (const char* extension : {".png", ".jpg"}) {
    std::vector<uint8_t> bytes;
    cv::imencode(extension, image, bytes);
    api::LocateRequest encoded = base;
    encoded.set_encoded(std::string(bytes.begin(), bytes.end()));
    requests.push_back(encoded);
  }
  // With a GNSS fix at the map's origin (3 m, 5 m).
  api::LocateRequest with_fix = raw;
  with_fix.mutable_gnss_fix()->set_latitude_deg(46.5191);
  with_fix.mutable_gnss_fix()->set_longitude_deg(6.5668);
  with_fix.mutable_gnss_fix()->set_altitude_m(372.0);
  with_fix.mutable_gnss_fix()->set_horizontal_accuracy_m(3.0);
  with_fix.mutable_gnss_fix()->set_vertical_accuracy_m(5.0);
  requests.push_back(with_fix);
  raw.set_map_name("v1");
  requests.push_back(raw);
  requests.push_back(base);
  return requests;
}

}  // namespace evloc::service::fuzz
