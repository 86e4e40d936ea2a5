// The chunked build of `evloc-mapper build --chunked` (docs/mapper.md, "Chunked build"): a large
// photo set is split into overlapping chunks (by camera position when poses are known or given as
// a reference, by input order for a timed sequence, by image retrieval otherwise), each chunk is
// reconstructed (COLMAP, or the known poses triangulated) and turned into a semi-dense map of its
// core keyframes, the chunks are aligned by Sim(3) from the images they share and adjusted together
// (Ceres), merged, and written as a site of tiles (maps/site.h).
//
// Each finished chunk is a folder `chunk_NNNN/` of the chunk workspace (map.evmap, poses.txt,
// inputs.txt, report.json), staged and renamed into place: a killed build restarts from its
// finished chunks, whose recorded inputs fingerprint must match. Chunks run in-process one after
// the other, or in worker processes (the same command with `--chunk-index K`), or as the pods of
// a Kubernetes Indexed Job followed by a `--merge-only` Job (deploy/k8s/mapper).
#pragma once

#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <limits>
#include <map>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include <Eigen/Core>

#include "core/geometry/rigid3.h"
#include "mapper/build_inputs.h"
#include "mapper/build_report.h"
#include "mapper/map_builder.h"
#include "mapper/pose_alignment.h"
#include "maps/map.h"

namespace evloc::mapper {

// How the photos are cut: kAuto takes the first that applies of position (every photo has a
// known or reference pose), sequence (every photo has a time) and retrieval.
enum class ChunkMethod { kAuto, kPosition, kSequence, kRetrieval };

// "auto", "position", "sequence", "retrieval"; ParseChunkMethod throws InvalidArgumentError for
// another name.
std::string ChunkMethodName(ChunkMethod method);
ChunkMethod ParseChunkMethod(const std::string& name);

// How the photo set is cut into chunks.
struct ChunkingOptions {
  // The cut; a method the inputs cannot serve (position without poses, sequence without times)
  // is refused by BuildChunkedSite.
  ChunkMethod method = ChunkMethod::kAuto;
  // Largest number of core photos of a chunk (photos the chunk owns; the overlap comes on top).
  size_t chunk_size = 250;
  // By position: the photos of other chunks whose camera centre lies within this distance of one
  // of the chunk's core centres join it as overlap, metres (reference units).
  double overlap_m = 6.0;
  // By input order: the photos before and after the chunk's core that join it as overlap. By
  // retrieval: twice as many, the photos outside the core most similar to one of its photos.
  size_t overlap_photos = 20;
  // By retrieval: the most similar photos each photo links to; a chunk grows along these links.
  size_t retrieval_neighbours = 10;

  // Throws InvalidArgumentError for chunk_size < 8, a negative or non-finite overlap_m,
  // retrieval_neighbours < 1.
  void Check() const;
};

// One chunk of the plan.
struct ChunkPlanEntry {
  // Indices into the input images of the photos the chunk owns, increasing.
  std::vector<size_t> core;
  // Indices of every photo the chunk reconstructs: its core and its overlap, increasing.
  std::vector<size_t> members;
};

// The chunks of a build.
struct ChunkPlan {
  // "position" (camera centres of the known or reference poses), "sequence" (input order) or
  // "retrieval" (image similarity).
  std::string method;
  // The chunks; every input photo is in the core of exactly one.
  std::vector<ChunkPlanEntry> chunks;
};

// Cuts `num_images` photos into chunks. With `positions` (one per photo): recursive halving of
// the camera centres at the median of their widest axis until each part holds at most
// options.chunk_size photos, each part grown by the photos within options.overlap_m of it.
// Without: consecutive runs of chunk_size photos in input order, each grown by overlap_photos on
// both sides. Deterministic. Throws InvalidArgumentError for bad options, no photos, or positions
// of another count or not finite.
ChunkPlan PlanChunks(size_t num_images, const std::vector<Eigen::Vector3d>* positions,
                     const ChunkingOptions& options);

// Cuts photos without positions or times by their image similarity: `descriptors` holds one
// global descriptor per photo (VLAD, compared by cosine similarity). Seeds, one per chunk
// (ceil(N / (0.85 chunk_size)) of them, so that the chunks' growth has room), are chosen by
// farthest-point sampling (each next seed the photo least similar to every seed so far, the
// first the photo least similar to all); the chunks then grow best-first along the links of each
// photo to its options.retrieval_neighbours most similar photos, the most similar link first,
// each chunk up to options.chunk_size core photos; a photo no link reaches joins the chunk with
// room that holds its most similar photo. Each chunk's overlap is the 2 * overlap_photos photos
// outside its core most similar to one of its core photos. Deterministic (ties: lower index).
// Throws InvalidArgumentError for bad options, no photos, or descriptors of unequal lengths or
// not finite.
ChunkPlan PlanChunksByRetrieval(const std::vector<std::vector<float>>& descriptors,
                                const ChunkingOptions& options);

// plan.json of the chunk workspace: the method, `inputs` (a fingerprint of what the plan was cut
// from, see BuildChunkedSite) and each chunk's core and member photos by name (`names`: the input
// photos, in input order).
std::string ChunkPlanToJson(const ChunkPlan& plan, const std::vector<std::string>& names,
                            const std::string& inputs);

// A plan read back from plan.json, and the fingerprint it records.
struct StoredChunkPlan {
  ChunkPlan plan;
  std::string inputs;
};

// Reads plan.json back over the input photos `names`. Throws ParseError naming `source` for
// malformed JSON, a missing or mistyped field, a name that is not an input photo, a photo in no
// core or in two, a core photo that is not a member, or a chunk without core photos.
StoredChunkPlan ParseChunkPlan(std::string_view text, const std::vector<std::string>& names,
                               const std::string& source);

// One chunk against the reference poses on its own.
struct ChunkReferenceFit {
  // Centre RMS of the chunk's registered photos after their own Sim(3) onto the reference
  // (AlignPoses), reference units; NaN when fewer than 3 have a reference pose or their centres
  // coincide.
  double centre_rms = std::numeric_limits<double>::quiet_NaN();
  // Whether that fit is within `limits` (false without a figure).
  bool fits = false;
};

// Fits each chunk's poses (world_from_cam by image name, in the chunk's frame) to the reference
// poses of the same names on its own.
std::vector<ChunkReferenceFit> FitChunksToReference(
    const std::vector<std::map<std::string, Rigid3d>>& chunk_poses,
    const std::map<std::string, Rigid3d>& reference, const AlignmentLimits& limits);

// Options of the chunked build.
struct ChunkedBuildOptions {
  // The build of each chunk and of the whole (images, camera, poses, COLMAP, semi-dense, merge,
  // relocalization, geo-reference); output_dir is the site folder to create.
  MapBuilderOptions build;
  // How the photos are cut.
  ChunkingOptions chunking;
  // The finished chunks and their COLMAP workspaces; std::nullopt: `<output_dir>.chunks`.
  std::optional<std::filesystem::path> chunk_workspace;
  // Chunks computed at the same time, each by a worker process (worker_command) or, without
  // one, in this process one after the other.
  int workers = 1;
  // The command that computes one chunk in another process; the chunk's index is appended as
  // `--chunk-index K`. Empty: chunks run in this process.
  std::vector<std::string> worker_command;
  // Compute only this chunk (an Indexed Job's pod, a worker process) and stop.
  std::optional<size_t> only_chunk;
  // Compute nothing: write the plan (plan.json in the chunk workspace) and stop (the chunk count
  // an Indexed Job needs).
  bool plan_only = false;
  // Compute no chunk: merge the finished ones (all must be there) into the site.
  bool merge_only = false;
  // Peak memory the build may use, bytes (all workers together); std::nullopt: no bound.
  std::optional<uint64_t> memory_budget_bytes;
  // The site's tiles: core square edge and overlap, metres.
  double tile_size_m = 50.0;
  double tile_overlap_m = 10.0;

  // Throws InvalidArgumentError on a bad or inconsistent value.
  void Check() const;
};

// The memory a chunk of `num_photos` photos of `width` x `height` pixels is expected to need at
// its peak, bytes (the model of docs/mapper.md, "Memory", fitted to the measured peak RSS).
uint64_t EstimatedChunkPeakBytes(size_t num_photos, int width, int height);

// A finished chunk, as read back from its folder.
struct ChunkResult {
  // The chunk's semi-dense map of its core keyframes, in the chunk's frame.
  Map map;
  // world_from_cam in the chunk's frame of every photo the chunk registered, by image name.
  std::map<std::string, Rigid3d> world_from_cams;
  // The fingerprint of the chunk's inputs (inputs.txt).
  std::string inputs_fingerprint;
};

// Folder name of chunk `index` inside the chunk workspace ("chunk_0007").
std::string ChunkFolderName(size_t index);

// Parses a chunk's poses.txt: `IMAGE_NAME tx ty tz qx qy qz qw` lines (world_from_cam, the
// pose-text rule of docs/dataset-format.md), `#` comments and empty lines skipped, each name once.
// Throws ParseError naming `source` and the line.
std::map<std::string, Rigid3d> ParseChunkPoses(std::string_view text, const std::string& source);

// Reads the finished chunk folder `directory` (map.evmap with LoadMap's checks, poses.txt as
// `IMAGE_NAME tx ty tz qx qy qz qw` lines, inputs.txt). Throws IoError / ParseError naming the
// file.
ChunkResult ReadChunkResult(const std::filesystem::path& directory);

// The Sim(3) of each chunk into the common frame and how well the chunks agree.
struct ChunkAlignment {
  // common_from_chunk per chunk.
  std::vector<Sim3d> common_from_chunk;
  // Pairs of chunks that share at least 3 registered photos.
  size_t num_linked_pairs = 0;
  // Photo centres seen by two chunks: RMS and largest distance between their two positions in
  // the common frame, after the initial chain and after the global adjustment (common units).
  double initial_rms = 0.0;
  double adjusted_rms = 0.0;
  double adjusted_max = 0.0;
  // Shared photo observations used by the adjustment.
  size_t num_shared_observations = 0;
};

// Aligns the chunks: chunk 0 fixes the frame; every other chunk gets the Sim(3) (AlignPoses on
// the centres and orientations of the photos it shares with an already aligned chunk, breadth
// first), then one Ceres adjustment of all chunks' Sim(3) minimises the disagreement of every
// shared photo's centre and orientation (Huber loss). Throws InvalidArgumentError naming the
// chunks that share fewer than 3 photos with the others.
ChunkAlignment AlignChunks(const std::vector<std::map<std::string, Rigid3d>>& chunk_poses);

// What BuildChunkedSite did.
struct ChunkedBuildReport {
  // The merged build's figures (images, registered, keyframes, points, alignment, timings with
  // peak memory per stage, ...).
  MapBuildReport build;
  // The plan's method and chunk sizes (core, members).
  std::string method;
  std::vector<std::pair<size_t, size_t>> chunk_sizes;
  // Chunks computed by this run, and reused from the chunk workspace.
  std::vector<size_t> computed_chunks;
  std::vector<size_t> reused_chunks;
  // Per chunk: its own report's peak RSS (including COLMAP's) and wall seconds; 0 when reused
  // without a report.
  std::vector<uint64_t> chunk_peak_rss_bytes;
  std::vector<double> chunk_seconds;
  // With --align-to, per chunk: FitChunksToReference (a chunk that does not fit on its own is a
  // wrong reconstruction, which the merged alignment's error names).
  std::vector<double> chunk_reference_rms_m;
  std::vector<char> chunk_fits_reference;
  // The chunks' alignment (estimated poses), or nullopt (known poses: the chunks share the
  // world frame).
  std::optional<ChunkAlignment> alignment;
  // Tiles written and the site version.
  size_t num_tiles = 0;
  std::string site_version;
  // Whether the site was written (false with only_chunk).
  bool site_written = false;
};

// The report as JSON (report.json of the site folder).
std::string ChunkedBuildReportToJson(const ChunkedBuildReport& report);

// Runs the chunked build (see the file comment). Throws InvalidArgumentError for bad options or
// inputs, a chunk the memory budget cannot hold (naming it, its estimate and the chunk size that
// fits), missing chunks with merge_only; IoError when a worker or COLMAP fails or a file cannot be
// written. The site folder is written last (tiles, then the manifest).
ChunkedBuildReport BuildChunkedSite(const ChunkedBuildOptions& options,
                                    ProgressListener* progress = nullptr);

}  // namespace evloc::mapper
