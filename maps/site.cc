// Sites of tiles: the manifest container and the tiler (docs/map-format.md, "Sites").
#include "maps/site.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <map>
#include <system_error>
#include <tuple>
#include <unordered_set>

#include "core/common/error.h"
#include "core/common/file_util.h"
#include "core/common/provenance.h"
#include "evloc/site.pb.h"
#include "maps/crc32c.h"
#include "proto/convert/proto_convert.h"

namespace evloc {
namespace {

namespace pb = ::evloc::map_format;

constexpr std::string_view kSiteMagic = "EVLOCSIT";
constexpr const char* kGridPlane = "xy";

void PutLittleEndian(std::string* bytes, uint64_t value, size_t size) {
  for (size_t i = 0; i < size; ++i) bytes->push_back(static_cast<char>(value >> (8 * i)));
}

uint64_t GetLittleEndian(std::string_view bytes, size_t offset, size_t size) {
  uint64_t value = 0;
  for (size_t i = 0; i < size; ++i) {
    value |= static_cast<uint64_t>(static_cast<unsigned char>(bytes[offset + i])) << (8 * i);
  }
  return value;
}

bool IsPlainComponent(const std::string& name) {
  return !name.empty() && name.front() != '.' && name.find('/') == std::string::npos &&
         name.find('\\') == std::string::npos && name.find('\0') == std::string::npos;
}

bool EndsWith(const std::string& text, std::string_view suffix) {
  return text.size() >= suffix.size() &&
         text.compare(text.size() - suffix.size(), suffix.size(), suffix) == 0;
}

std::string TileFileName(TileIndex index) {
  char name[64];
  std::snprintf(name, sizeof(name), "tile_%+d_%+d.evmap", index.ix, index.iy);
  return name;
}

bool SameRectangle(const TileRectangle& a, const TileRectangle& b) {
  return a.min_x == b.min_x && a.min_y == b.min_y && a.max_x == b.max_x && a.max_y == b.max_y;
}

pb::Rectangle RectangleToProto(const TileRectangle& rectangle) {
  pb::Rectangle out;
  out.set_min_x(rectangle.min_x);
  out.set_min_y(rectangle.min_y);
  out.set_max_x(rectangle.max_x);
  out.set_max_y(rectangle.max_y);
  return out;
}

TileRectangle RectangleFromProto(const pb::Rectangle& rectangle) {
  return {rectangle.min_x(), rectangle.min_y(), rectangle.max_x(), rectangle.max_y()};
}

pb::SiteManifest ToProto(const SiteManifest& manifest) {
  pb::SiteManifest out;
  out.set_format_version(manifest.format_version);
  out.set_name(manifest.name);
  out.set_version(manifest.version);
  if (!manifest.geo_anchor.empty() &&
      !out.mutable_geo_anchor()->ParseFromString(manifest.geo_anchor)) {
    throw InvalidArgumentError("site manifest: the geo anchor is not a valid GeoAnchor message");
  }
  pb::TileGrid& grid = *out.mutable_grid();
  grid.set_origin_x(manifest.grid.origin_x);
  grid.set_origin_y(manifest.grid.origin_y);
  grid.set_tile_size_m(manifest.grid.tile_size_m);
  grid.set_overlap_m(manifest.grid.overlap_m);
  grid.set_plane(kGridPlane);
  for (const SiteTile& tile : manifest.tiles) {
    pb::TileEntry& entry = *out.add_tiles();
    entry.set_ix(tile.index.ix);
    entry.set_iy(tile.index.iy);
    entry.set_file_name(tile.file_name);
    *entry.mutable_core() = RectangleToProto(tile.core);
    *entry.mutable_padded() = RectangleToProto(tile.padded);
    entry.set_num_points(tile.num_points);
    entry.set_num_core_points(tile.num_core_points);
    entry.set_num_keyframes(tile.num_keyframes);
    entry.set_file_bytes(tile.file_bytes);
    entry.set_content_crc32c(tile.content_crc32c);
    entry.set_num_core_keyframes(tile.num_core_keyframes);
    for (int i = 0; i < 3; ++i) entry.add_bounding_box(tile.box_min[i]);
    for (int i = 0; i < 3; ++i) entry.add_bounding_box(tile.box_max[i]);
  }
  out.set_source_content_crc32c(manifest.source_content_crc32c);
  pb::Provenance& provenance = *out.mutable_provenance();
  provenance.set_tool(manifest.provenance.tool);
  provenance.set_tool_version(manifest.provenance.tool_version);
  provenance.set_created_utc(manifest.provenance.created_utc);
  provenance.set_command_line(manifest.provenance.command_line);
  for (const std::string& input : manifest.provenance.inputs) provenance.add_inputs(input);
  return out;
}

SiteManifest FromProto(const pb::SiteManifest& in, const std::string& source) {
  if (in.grid().plane() != kGridPlane) {
    throw ParseError(source, "byte 24",
                     "the tile grid's plane is '" + in.grid().plane() +
                         "'; this build reads 'xy' grids (z-up map frame)");
  }
  SiteManifest manifest;
  manifest.format_version = in.format_version();
  manifest.name = in.name();
  manifest.version = in.version();
  if (in.has_geo_anchor()) manifest.geo_anchor = in.geo_anchor().SerializeAsString();
  manifest.grid.origin_x = in.grid().origin_x();
  manifest.grid.origin_y = in.grid().origin_y();
  manifest.grid.tile_size_m = in.grid().tile_size_m();
  manifest.grid.overlap_m = in.grid().overlap_m();
  manifest.tiles.reserve(static_cast<size_t>(in.tiles_size()));
  for (const pb::TileEntry& entry : in.tiles()) {
    SiteTile tile;
    tile.index = {entry.ix(), entry.iy()};
    tile.file_name = entry.file_name();
    tile.core = RectangleFromProto(entry.core());
    tile.padded = RectangleFromProto(entry.padded());
    tile.num_points = entry.num_points();
    tile.num_core_points = entry.num_core_points();
    tile.num_keyframes = entry.num_keyframes();
    tile.file_bytes = entry.file_bytes();
    tile.content_crc32c = entry.content_crc32c();
    tile.num_core_keyframes = entry.num_core_keyframes();
    if (entry.bounding_box_size() != 6) {
      throw ParseError(source, "byte 24",
                       "tile (" + std::to_string(entry.ix()) + ", " + std::to_string(entry.iy()) +
                           ") has " + std::to_string(entry.bounding_box_size()) +
                           " bounding box values; expected 6");
    }
    for (int i = 0; i < 3; ++i) {
      tile.box_min[i] = entry.bounding_box(i);
      tile.box_max[i] = entry.bounding_box(3 + i);
    }
    manifest.tiles.push_back(std::move(tile));
  }
  manifest.source_content_crc32c = in.source_content_crc32c();
  manifest.provenance.tool = in.provenance().tool();
  manifest.provenance.tool_version = in.provenance().tool_version();
  manifest.provenance.created_utc = in.provenance().created_utc();
  manifest.provenance.command_line = in.provenance().command_line();
  manifest.provenance.inputs.assign(in.provenance().inputs().begin(),
                                    in.provenance().inputs().end());
  try {
    manifest.Check();
  } catch (const InvalidArgumentError& error) {
    throw ParseError(source, "byte 24", error.what());
  }
  return manifest;
}

}  // namespace

double TileRectangle::DistanceTo(double x, double y) const {
  const double dx = std::max({min_x - x, 0.0, x - max_x});
  const double dy = std::max({min_y - y, 0.0, y - max_y});
  return std::hypot(dx, dy);
}

TileIndex TileGrid::IndexOf(double x, double y) const {
  const double fx = std::floor((x - origin_x) / tile_size_m);
  const double fy = std::floor((y - origin_y) / tile_size_m);
  // Clamped to the int32 range: positions are checked finite, a site spans far less.
  const auto clamp = [](double value) {
    return static_cast<int32_t>(std::clamp(value, -2147483648.0, 2147483647.0));
  };
  return {clamp(fx), clamp(fy)};
}

TileRectangle TileGrid::Core(TileIndex index) const {
  return {origin_x + index.ix * tile_size_m, origin_y + index.iy * tile_size_m,
          origin_x + (index.ix + 1.0) * tile_size_m, origin_y + (index.iy + 1.0) * tile_size_m};
}

TileRectangle TileGrid::Padded(TileIndex index) const {
  const TileRectangle core = Core(index);
  return {core.min_x - overlap_m, core.min_y - overlap_m, core.max_x + overlap_m,
          core.max_y + overlap_m};
}

bool TileGrid::Holds(TileIndex index, double x, double y) const {
  if (IndexOf(x, y) == index) return true;
  const TileRectangle padded = Padded(index);
  return x >= padded.min_x && x < padded.max_x && y >= padded.min_y && y < padded.max_y;
}

void TileGrid::Check() const {
  if (!std::isfinite(origin_x) || !std::isfinite(origin_y)) {
    throw InvalidArgumentError("tile grid: the origin must be finite");
  }
  if (!std::isfinite(tile_size_m) || tile_size_m <= 0) {
    throw InvalidArgumentError(
        "tile grid: the tile size must be a positive number of metres, got " +
        std::to_string(tile_size_m));
  }
  if (!std::isfinite(overlap_m) || overlap_m < 0 || overlap_m >= tile_size_m) {
    throw InvalidArgumentError("tile grid: the overlap must be in [0, tile size) metres, got " +
                               std::to_string(overlap_m) + " for tiles of " +
                               std::to_string(tile_size_m) + " m");
  }
}

std::optional<size_t> SiteManifest::Find(TileIndex index) const {
  const auto found = std::lower_bound(
      tiles.begin(), tiles.end(), index,
      [](const SiteTile& tile, const TileIndex& wanted) { return tile.index < wanted; });
  if (found == tiles.end() || !(found->index == index)) return std::nullopt;
  return static_cast<size_t>(found - tiles.begin());
}

void SiteManifest::Check() const {
  if (format_version != kSiteFormatVersion) {
    throw InvalidArgumentError("site manifest: format version " + std::to_string(format_version) +
                               " is not supported; this build reads version " +
                               std::to_string(kSiteFormatVersion));
  }
  grid.Check();
  SiteGeoAnchor(*this);  // A stored anchor must decode and be valid.
  std::unordered_set<std::string> names;
  for (size_t i = 0; i < tiles.size(); ++i) {
    const SiteTile& tile = tiles[i];
    const std::string what = "site manifest: tile " + std::to_string(i) + " (" +
                             std::to_string(tile.index.ix) + ", " + std::to_string(tile.index.iy) +
                             ")";
    if (i > 0 && !(tiles[i - 1].index < tile.index)) {
      throw InvalidArgumentError(what +
                                 " is out of order or repeated (tiles are sorted by iy, ix)");
    }
    if (!IsPlainComponent(tile.file_name) || !EndsWith(tile.file_name, ".evmap")) {
      throw InvalidArgumentError(what + " has file name '" + tile.file_name +
                                 "'; expected one plain path component ending in .evmap");
    }
    if (!names.insert(tile.file_name).second) {
      throw InvalidArgumentError(what + " repeats the file name '" + tile.file_name + "'");
    }
    if (!SameRectangle(tile.core, grid.Core(tile.index)) ||
        !SameRectangle(tile.padded, grid.Padded(tile.index))) {
      throw InvalidArgumentError(what + " has core or padded bounds that are not the grid's");
    }
    if (tile.num_core_points > tile.num_points || tile.num_core_keyframes > tile.num_keyframes) {
      throw InvalidArgumentError(what +
                                 " has more core points (or keyframes) than points (or "
                                 "keyframes)");
    }
    if (!tile.box_min.allFinite() || !tile.box_max.allFinite() ||
        (tile.box_min.array() > tile.box_max.array()).any()) {
      throw InvalidArgumentError(what + " has a bounding box that is not finite or min > max");
    }
  }
  const std::string expected = SiteVersionOf(tiles);
  if (version != expected) {
    throw InvalidArgumentError("site manifest: version '" + version + "' is not the tiles' (" +
                               expected + ")");
  }
}

std::optional<GeoAnchor> SiteGeoAnchor(const SiteManifest& manifest) {
  if (manifest.geo_anchor.empty()) return std::nullopt;
  const std::string what = "site '" + manifest.name + "': the manifest's geo anchor";
  pb::GeoAnchor anchor;
  if (!anchor.ParseFromString(manifest.geo_anchor)) {
    throw InvalidArgumentError(what + " is not a valid GeoAnchor message");
  }
  return GeoAnchorFromProto(anchor, what);
}

MapInfo SummarizeSite(const SiteManifest& manifest) {
  MapInfo info;
  info.format_version = manifest.format_version;
  info.content_crc32c = static_cast<uint32_t>(std::strtoul(manifest.version.c_str(), nullptr, 16));
  for (size_t t = 0; t < manifest.tiles.size(); ++t) {
    const SiteTile& tile = manifest.tiles[t];
    info.num_points += tile.num_core_points;
    info.num_keyframes += tile.num_core_keyframes;
    info.bounding_box_min = t == 0 ? tile.box_min : info.bounding_box_min.cwiseMin(tile.box_min);
    info.bounding_box_max = t == 0 ? tile.box_max : info.bounding_box_max.cwiseMax(tile.box_max);
  }
  info.provenance = manifest.provenance;
  info.geo_anchor = SiteGeoAnchor(manifest);
  return info;
}

std::string SiteVersionOf(const std::vector<SiteTile>& tiles) {
  std::string bytes;
  bytes.reserve(tiles.size() * 12);
  for (const SiteTile& tile : tiles) {
    PutLittleEndian(&bytes, static_cast<uint32_t>(tile.index.ix), 4);
    PutLittleEndian(&bytes, static_cast<uint32_t>(tile.index.iy), 4);
    PutLittleEndian(&bytes, tile.content_crc32c, 4);
  }
  char text[16];
  std::snprintf(text, sizeof(text), "%08x", Crc32c(bytes));
  return text;
}

bool IsSiteDirectory(const std::filesystem::path& directory) {
  std::error_code error;
  return std::filesystem::is_regular_file(directory / kSiteManifestFileName, error);
}

std::string EncodeSiteManifest(const SiteManifest& manifest) {
  manifest.Check();
  std::string payload;
  if (!ToProto(manifest).SerializeToString(&payload)) {
    throw InvalidArgumentError("site manifest: cannot serialize (larger than 2 GiB?)");
  }
  std::string bytes(kSiteMagic);
  PutLittleEndian(&bytes, manifest.format_version, 4);
  PutLittleEndian(&bytes, Crc32c(payload), 4);
  PutLittleEndian(&bytes, payload.size(), 8);
  return bytes + payload;
}

SiteManifest DecodeSiteManifest(std::string_view bytes, const std::string& source) {
  if (bytes.size() < kSiteMagic.size() || bytes.substr(0, kSiteMagic.size()) != kSiteMagic) {
    throw ParseError::AtByte(source, 0, "not an evloc site manifest (no EVLOCSIT magic)");
  }
  if (bytes.size() < kSiteManifestHeaderSize) {
    throw ParseError::AtByte(source, bytes.size(),
                             "truncated site manifest: expected at least " +
                                 std::to_string(kSiteManifestHeaderSize) +
                                 " bytes but the file has " + std::to_string(bytes.size()));
  }
  const auto version = static_cast<uint32_t>(GetLittleEndian(bytes, 8, 4));
  if (version != kSiteFormatVersion) {
    throw ParseError::AtByte(source, 8,
                             "site format version " + std::to_string(version) +
                                 " is not supported; this build reads version " +
                                 std::to_string(kSiteFormatVersion));
  }
  const auto crc = static_cast<uint32_t>(GetLittleEndian(bytes, 12, 4));
  const uint64_t length = GetLittleEndian(bytes, 16, 8);
  const uint64_t available = bytes.size() - kSiteManifestHeaderSize;
  if (length != available) {
    throw ParseError::AtByte(source, 16,
                             "the header gives a payload of " + std::to_string(length) +
                                 " bytes but the file holds " + std::to_string(available) +
                                 " after the header (truncated or extended)");
  }
  const std::string_view payload = bytes.substr(kSiteManifestHeaderSize);
  if (Crc32c(payload) != crc) {
    throw ParseError::AtByte(source, 24, "payload checksum mismatch (the manifest is damaged)");
  }
  pb::SiteManifest message;
  if (!message.ParseFromArray(payload.data(), static_cast<int>(payload.size()))) {
    throw ParseError::AtByte(source, 24, "the payload is not a valid SiteManifest message");
  }
  if (message.format_version() != version) {
    throw ParseError::AtByte(source, 24,
                             "the payload's format version " +
                                 std::to_string(message.format_version()) +
                                 " differs from the header's " + std::to_string(version));
  }
  return FromProto(message, source);
}

SiteManifest ReadSiteManifest(const std::filesystem::path& directory) {
  const std::filesystem::path path = directory / kSiteManifestFileName;
  return DecodeSiteManifest(ReadFileToString(path), path.string());
}

void WriteSiteManifest(const std::filesystem::path& directory, const SiteManifest& manifest) {
  WriteFileAtomically(directory / kSiteManifestFileName, EncodeSiteManifest(manifest));
}

Map LoadTile(const std::filesystem::path& directory, const SiteManifest& manifest, size_t tile) {
  if (tile >= manifest.tiles.size()) {
    throw InvalidArgumentError("LoadTile: tile " + std::to_string(tile) + " of " +
                               std::to_string(manifest.tiles.size()));
  }
  const SiteTile& entry = manifest.tiles[tile];
  const std::filesystem::path path = directory / entry.file_name;
  std::error_code error;
  const uint64_t bytes = std::filesystem::file_size(path, error);
  if (error) {
    throw IoError("cannot read tile '" + path.string() + "': " + error.message() +
                  " (the site is incomplete; tile it again)");
  }
  if (bytes != entry.file_bytes) {
    throw ParseError::AtByte(path.string(), 0,
                             "the tile has " + std::to_string(bytes) +
                                 " bytes but the site manifest says " +
                                 std::to_string(entry.file_bytes) +
                                 " (the tile was replaced or damaged; tile the site again)");
  }
  Map map = LoadMap(path);
  const uint32_t crc = ComputeMapContentChecksum(map);
  if (crc != entry.content_crc32c || map.size() != entry.num_points ||
      map.keyframes.size() != entry.num_keyframes) {
    char text[128];
    std::snprintf(text, sizeof(text),
                  "content checksum %08x, %zu points, %zu keyframes; the manifest says %08x, %llu, "
                  "%llu",
                  crc, map.size(), map.keyframes.size(), entry.content_crc32c,
                  static_cast<unsigned long long>(entry.num_points),
                  static_cast<unsigned long long>(entry.num_keyframes));
    throw ParseError::AtByte(path.string(), 0,
                             std::string("the tile does not match the site manifest (") + text +
                                 "); tile the site again");
  }
  return map;
}

void TilingOptions::Check() const {
  TileGrid{0, 0, tile_size_m, overlap_m}.Check();
  if (origin && !origin->allFinite()) {
    throw InvalidArgumentError("tiling: the grid origin must be finite");
  }
}

Map ExtractTile(const Map& map, const TileGrid& grid, TileIndex index, uint64_t* core_points,
                uint64_t* core_keyframes) {
  Map tile;
  tile.cameras = map.cameras;
  // Each tile is a self-contained map, geo-referenced like the map it comes from.
  tile.geo_anchor = map.geo_anchor;
  tile.provenance = map.provenance;
  // The points the tile holds, in their order.
  std::vector<uint32_t> new_index(map.size(), kNoKeyframe);
  uint32_t held = 0;
  uint64_t owned = 0;
  for (size_t i = 0; i < map.size(); ++i) {
    const Eigen::Vector3f& p = map.positions[i];
    if (!grid.Holds(index, p.x(), p.y())) continue;
    if (grid.IndexOf(p.x(), p.y()) == index) ++owned;
    new_index[i] = held++;
  }
  // The keyframes whose camera centre the tile owns, and those that see (or are the source of)
  // one of its points: a keyframe in one tile sees points of others, and each tile's keyframe
  // visibility must find them.
  std::vector<bool> sees(map.keyframes.size(), false);
  uint64_t owned_keyframes = 0;
  for (size_t k = 0; k < map.keyframes.size(); ++k) {
    const Eigen::Vector3d centre = map.keyframes[k].cam_from_world.Inverse().translation;
    sees[k] = grid.IndexOf(centre.x(), centre.y()) == index;
    owned_keyframes += sees[k] ? 1 : 0;
    for (const uint32_t point : map.keyframes[k].visible_points) {
      if (sees[k]) break;
      sees[k] = new_index[point] != kNoKeyframe;
    }
  }
  for (size_t i = 0; i < map.size(); ++i) {
    const uint32_t source = map.source_keyframe[i];
    if (new_index[i] != kNoKeyframe && source != kNoKeyframe) sees[source] = true;
  }
  std::vector<uint32_t> kept_keyframe(map.keyframes.size(), kNoKeyframe);
  for (size_t k = 0; k < map.keyframes.size(); ++k) {
    if (!sees[k]) continue;
    kept_keyframe[k] = static_cast<uint32_t>(tile.keyframes.size());
    tile.keyframes.push_back(map.keyframes[k]);
    tile.keyframes.back().visible_points.clear();
  }
  tile.Reserve(held);
  for (size_t i = 0; i < map.size(); ++i) {
    if (new_index[i] == kNoKeyframe) continue;
    const uint32_t source = map.source_keyframe[i];
    tile.AddPoint(map.positions[i], map.gradients[i], map.inverse_depth_sigma[i],
                  map.gradient_magnitude[i],
                  source == kNoKeyframe ? kNoKeyframe : kept_keyframe[source]);
  }
  for (size_t k = 0; k < map.keyframes.size(); ++k) {
    if (kept_keyframe[k] == kNoKeyframe) continue;
    std::vector<uint32_t>& visible = tile.keyframes[kept_keyframe[k]].visible_points;
    for (const uint32_t point : map.keyframes[k].visible_points) {
      if (new_index[point] != kNoKeyframe) visible.push_back(new_index[point]);
    }
  }
  if (map.relocalization) {
    const RelocalizationData& in = *map.relocalization;
    RelocalizationData out;
    out.vocabulary = in.vocabulary;
    std::vector<uint32_t> new_landmark(in.landmarks.size(), kNoKeyframe);
    for (size_t l = 0; l < in.landmarks.size(); ++l) {
      const Eigen::Vector3f& p = in.landmarks[l];
      if (!grid.Holds(index, p.x(), p.y())) continue;
      new_landmark[l] = static_cast<uint32_t>(out.landmarks.size());
      out.landmarks.push_back(p);
    }
    for (size_t k = 0; k < map.keyframes.size(); ++k) {
      if (kept_keyframe[k] == kNoKeyframe) continue;
      const KeyframeFeatures& features = in.keyframes[k];
      KeyframeFeatures kept;
      kept.global_descriptor = features.global_descriptor;
      for (size_t f = 0; f < features.landmarks.size(); ++f) {
        const uint32_t landmark = new_landmark[features.landmarks[f]];
        if (landmark == kNoKeyframe) continue;
        kept.keypoints.push_back(features.keypoints[f]);
        kept.landmarks.push_back(landmark);
        kept.descriptors.insert(
            kept.descriptors.end(),
            features.descriptors.begin() +
                static_cast<std::ptrdiff_t>(f * kRelocalizationDescriptorBytes),
            features.descriptors.begin() +
                static_cast<std::ptrdiff_t>((f + 1) * kRelocalizationDescriptorBytes));
      }
      out.keyframes.push_back(std::move(kept));
    }
    tile.relocalization = std::move(out);
  }
  if (core_points != nullptr) *core_points = owned;
  if (core_keyframes != nullptr) *core_keyframes = owned_keyframes;
  return tile;
}

SiteManifest TileMap(const Map& map, const std::filesystem::path& directory,
                     const TilingOptions& options) {
  options.Check();
  map.Check();
  if (map.size() == 0) {
    throw InvalidArgumentError("tiling: the map has no points; there is nothing to tile");
  }
  const std::string where = "tiling into '" + directory.string() + "': ";
  std::error_code error;
  if (std::filesystem::exists(directory / kSiteManifestFileName, error) && !options.overwrite) {
    throw InvalidArgumentError(where +
                               "the folder already holds a site; give --force to replace it");
  }
  if (std::filesystem::exists(directory, error) &&
      !std::filesystem::is_directory(directory, error)) {
    throw InvalidArgumentError(where + "the path exists and is not a folder");
  }
  std::filesystem::create_directories(directory, error);
  if (error) throw IoError(where + "cannot create the folder: " + error.message());

  TileGrid grid;
  grid.tile_size_m = options.tile_size_m;
  grid.overlap_m = options.overlap_m;
  if (options.origin) {
    grid.origin_x = options.origin->x();
    grid.origin_y = options.origin->y();
  } else {
    const auto [min, max] = BoundingBox(map.positions);
    grid.origin_x = std::floor(min.x() / grid.tile_size_m) * grid.tile_size_m;
    grid.origin_y = std::floor(min.y() / grid.tile_size_m) * grid.tile_size_m;
  }
  grid.Check();

  // Which tiles own points: only those are written.
  std::map<TileIndex, uint64_t> owners;
  for (const Eigen::Vector3f& p : map.positions) ++owners[grid.IndexOf(p.x(), p.y())];

  // A site being replaced stops being one first: a run killed from here on leaves no manifest.
  if (std::filesystem::exists(directory / kSiteManifestFileName, error)) {
    std::filesystem::remove(directory / kSiteManifestFileName, error);
    if (error) throw IoError(where + "cannot remove the old manifest: " + error.message());
    SyncPath(directory);
  }

  SiteManifest manifest;
  manifest.name = options.name.empty() ? directory.filename().string() : options.name;
  if (manifest.name.empty())
    manifest.name = std::filesystem::absolute(directory).parent_path().filename().string();
  // The site's anchor: the one given, else the map's own.
  manifest.geo_anchor = options.geo_anchor;
  if (manifest.geo_anchor.empty() && map.geo_anchor) {
    manifest.geo_anchor = GeoAnchorToProto(*map.geo_anchor).SerializeAsString();
  }
  manifest.grid = grid;
  manifest.source_content_crc32c = ComputeMapContentChecksum(map);
  manifest.provenance.tool = "evloc-mapper tile";
  manifest.provenance.tool_version = ToolVersion();
  manifest.provenance.created_utc = UtcNowIso8601();
  manifest.provenance.command_line = options.command_line;
  manifest.provenance.inputs = map.provenance.inputs;
  for (const auto& [index, count] : owners) {
    SiteTile tile;
    tile.index = index;
    tile.file_name = TileFileName(index);
    tile.core = grid.Core(index);
    tile.padded = grid.Padded(index);
    const Map tile_map =
        ExtractTile(map, grid, index, &tile.num_core_points, &tile.num_core_keyframes);
    const std::filesystem::path path = directory / tile.file_name;
    SaveMap(path, tile_map);
    tile.num_points = tile_map.size();
    tile.num_keyframes = tile_map.keyframes.size();
    tile.file_bytes = std::filesystem::file_size(path, error);
    if (error) throw IoError(where + "cannot stat '" + path.string() + "': " + error.message());
    tile.content_crc32c = ComputeMapContentChecksum(tile_map);
    std::tie(tile.box_min, tile.box_max) = BoundingBox(tile_map.positions);
    manifest.tiles.push_back(std::move(tile));
  }
  manifest.version = SiteVersionOf(manifest.tiles);
  WriteSiteManifest(directory, manifest);
  // Tile files the manifest does not list (an earlier site's, or a failed run's) are removed.
  std::unordered_set<std::string> listed;
  for (const SiteTile& tile : manifest.tiles) listed.insert(tile.file_name);
  for (auto it = std::filesystem::directory_iterator(directory, error);
       !error && it != std::filesystem::directory_iterator(); it.increment(error)) {
    const std::string name = it->path().filename().string();
    if (name.rfind("tile_", 0) == 0 && EndsWith(name, ".evmap") && listed.count(name) == 0 &&
        it->is_regular_file()) {
      std::error_code ignored;
      std::filesystem::remove(it->path(), ignored);
    }
  }
  return manifest;
}

}  // namespace evloc
