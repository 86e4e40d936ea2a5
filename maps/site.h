// A site: a large map served as tiles (docs/map-format.md, "Sites"). A site is a folder holding a
// manifest (`site.manifest`, proto/evloc/site.proto behind a small checksummed header) and one
// self-contained `.evmap` per tile: the points of the tile's padded square, the keyframes (and
// their relocalization features) whose camera centre lies in its core square. The grid lies in
// the x-y plane of a z-up map frame. TileMap splits a built map into a site (evloc-mapper tile);
// LoadTile reads one tile and checks it against the manifest.
#pragma once

#include <Eigen/Core>
#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "maps/map.h"

namespace evloc {

// File name of the manifest inside a site folder.
inline constexpr const char* kSiteManifestFileName = "site.manifest";
// Format version of the manifests WriteSiteManifest writes (and the only one read).
inline constexpr uint32_t kSiteFormatVersion = 1;
// Size of the manifest's header: magic "EVLOCSIT", u32 version, u32 CRC32C of the payload, u64
// payload length (little-endian).
inline constexpr size_t kSiteManifestHeaderSize = 24;

// The grid index of a tile.
struct TileIndex {
  int32_t ix = 0;
  int32_t iy = 0;
  bool operator==(const TileIndex& other) const { return ix == other.ix && iy == other.iy; }
  // Orders by (iy, ix), the manifest's order.
  bool operator<(const TileIndex& other) const {
    return iy != other.iy ? iy < other.iy : ix < other.ix;
  }
};

// An axis-aligned rectangle in the grid plane, metres.
struct TileRectangle {
  double min_x = 0;
  double min_y = 0;
  double max_x = 0;
  double max_y = 0;
  // Distance from (x, y) to the rectangle (0 inside), metres.
  double DistanceTo(double x, double y) const;
};

// The square tile grid in the x-y plane of the map frame (z up).
struct TileGrid {
  // Corner (minimum x, minimum y) of tile (0, 0), metres.
  double origin_x = 0;
  double origin_y = 0;
  // Edge of a tile's core square, metres.
  double tile_size_m = 50;
  // Growth of the padded square beyond the core on every side, metres, in [0, tile_size_m).
  double overlap_m = 10;

  // The tile whose (half-open) core square holds (x, y).
  TileIndex IndexOf(double x, double y) const;
  // The core square of `index`.
  TileRectangle Core(TileIndex index) const;
  // The core square grown by overlap_m on every side.
  TileRectangle Padded(TileIndex index) const;
  // True when tile `index` stores a point at (x, y): its core holds it (IndexOf) or its padded
  // square does (half-open like the core). The tiler and the tiled map source use this one test.
  bool Holds(TileIndex index, double x, double y) const;
  // Throws InvalidArgumentError unless the origin is finite, tile_size_m is finite and > 0 and
  // overlap_m is finite and in [0, tile_size_m).
  void Check() const;
};

// What the manifest says about one tile.
struct SiteTile {
  // Grid index.
  TileIndex index;
  // File name of its .evmap in the site folder (one path component).
  std::string file_name;
  // Core and padded squares (as the grid gives them).
  TileRectangle core;
  TileRectangle padded;
  // Points of the file, and of them those whose owner is this tile.
  uint64_t num_points = 0;
  uint64_t num_core_points = 0;
  // Keyframes of the file, and of them those whose camera centre the tile owns.
  uint64_t num_keyframes = 0;
  uint64_t num_core_keyframes = 0;
  // Size of the file, bytes.
  uint64_t file_bytes = 0;
  // Content checksum of the tile map (docs/map-format.md, "Checksums").
  uint32_t content_crc32c = 0;
  // Bounding box of the tile file's points, metres.
  Eigen::Vector3f box_min = Eigen::Vector3f::Zero();
  Eigen::Vector3f box_max = Eigen::Vector3f::Zero();
};

// The manifest of a site.
struct SiteManifest {
  // Format version (kSiteFormatVersion).
  uint32_t format_version = kSiteFormatVersion;
  // Site name (for people).
  std::string name;
  // Site version: SiteVersionOf(tiles), 8 lowercase hex digits.
  std::string version;
  // The serialized evloc.map_format.GeoAnchor message (proto/evloc/map.proto), carried through
  // unchanged; empty when the site has none.
  std::string geo_anchor;
  // The grid.
  TileGrid grid;
  // The tiles, sorted by index (TileIndex::operator<), unique.
  std::vector<SiteTile> tiles;
  // Content checksum of the map the site was tiled from (0 when unknown).
  uint32_t source_content_crc32c = 0;
  // How the site was made.
  MapProvenance provenance;

  // Position of `index` in `tiles`, or nullopt.
  std::optional<size_t> Find(TileIndex index) const;
  // Throws InvalidArgumentError naming the first problem unless: the version is supported, the
  // grid is valid, the tiles are sorted and unique, every file name is one plain path component
  // ending in ".evmap", every core and padded square is the grid's, num_core_points <=
  // num_points, num_core_keyframes <= num_keyframes, finite bounding boxes with min <= max,
  // `version` equals SiteVersionOf(tiles), and a geo anchor, when stored, is valid
  // (SiteGeoAnchor).
  void Check() const;
};

// The site's geo anchor (the manifest's serialized GeoAnchor, decoded and checked), or nullopt
// when it has none. Throws InvalidArgumentError naming the site when the stored anchor is not a
// valid GeoAnchor.
std::optional<GeoAnchor> SiteGeoAnchor(const SiteManifest& manifest);

// What describes a site as a map (the service's ListMaps): its unique points (the tiles' core
// points), keyframes (each once: by camera centre), the union of the tiles' bounding boxes, the
// site version's number as the content checksum, has_relocalization false (not summarised per
// tile), the geo anchor (SiteGeoAnchor: throws like it); format_version is the manifest's.
MapInfo SummarizeSite(const SiteManifest& manifest);

// The version of a site with these tiles: CRC32C over each tile's ix, iy (i32) and content
// checksum (u32), little-endian, as 8 lowercase hex digits.
std::string SiteVersionOf(const std::vector<SiteTile>& tiles);

// True when `directory` holds a site manifest.
bool IsSiteDirectory(const std::filesystem::path& directory);

// Encodes a manifest as the bytes of a site.manifest file (header and payload). Calls Check().
std::string EncodeSiteManifest(const SiteManifest& manifest);

// Decodes the bytes of a site.manifest file (`source` names it in errors). Throws ParseError
// naming the source and what is wrong (magic, version, length, checksum, protobuf, or a failed
// SiteManifest::Check()).
SiteManifest DecodeSiteManifest(std::string_view bytes, const std::string& source);

// Reads and checks DIRECTORY/site.manifest. Throws IoError when it cannot be read and ParseError
// when it is invalid.
SiteManifest ReadSiteManifest(const std::filesystem::path& directory);

// Writes DIRECTORY/site.manifest atomically (WriteFileAtomically). Throws InvalidArgumentError
// for an invalid manifest, IoError when writing fails.
void WriteSiteManifest(const std::filesystem::path& directory, const SiteManifest& manifest);

// Loads tile `tile` (a position in manifest.tiles) of the site in `directory` with LoadMap's
// checks, then checks it against the manifest (file size, content checksum, point and keyframe
// counts). Throws IoError or ParseError naming the tile file.
Map LoadTile(const std::filesystem::path& directory, const SiteManifest& manifest, size_t tile);

// How TileMap cuts a map.
struct TilingOptions {
  // Edge of a tile's core square, metres.
  double tile_size_m = 50;
  // Growth of the padded squares, metres, in [0, tile_size_m).
  double overlap_m = 10;
  // Grid origin; nullopt: the multiple of tile_size_m at or below the points' minimum x and y.
  std::optional<Eigen::Vector2d> origin;
  // Site name written into the manifest (the folder name when empty).
  std::string name;
  // Serialized GeoAnchor to carry into the manifest (empty: the map's own anchor, if it has one).
  std::string geo_anchor;
  // Replace the site of a folder that already holds one; otherwise refuse.
  bool overwrite = false;
  // The command line, for the provenance.
  std::string command_line;

  // Throws InvalidArgumentError unless the sizes are valid (TileGrid::Check) and the origin is
  // finite.
  void Check() const;
};

// The tile `index` of `map` cut with `grid`: the points the tile holds (TileGrid::Holds), in
// their original order; the keyframes whose camera centre lies in the core square or that see
// (or are the source of) one of the tile's points, their visible points restricted to the tile's;
// every camera; each point's source keyframe when that keyframe is kept (kNoKeyframe otherwise);
// and, when the map has relocalization data, the landmarks the tile holds, the vocabulary, and the
// kept keyframes' features that see a kept landmark. The provenance is the map's. `core_points` and
// `core_keyframes` (when given) get how many of the points and keyframes the tile owns.
Map ExtractTile(const Map& map, const TileGrid& grid, TileIndex index,
                uint64_t* core_points = nullptr, uint64_t* core_keyframes = nullptr);

// Splits `map` into a site in `directory` (created when missing): one tile file per grid square
// that owns at least one point, then the manifest, written last and atomically, so that a killed
// run leaves no site (an existing site being replaced loses its manifest first). Tile files
// (tile_*.evmap) the new manifest does not list (an earlier site's, a failed run's) are removed
// at the end. Throws
// InvalidArgumentError for invalid options, an invalid map, a map without points, or an existing
// site without `overwrite`; IoError when writing fails.
SiteManifest TileMap(const Map& map, const std::filesystem::path& directory,
                     const TilingOptions& options);

}  // namespace evloc
