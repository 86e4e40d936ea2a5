#include "mapper/build_command.h"

#include <iomanip>
#include <iostream>
#include <sstream>

#include <opencv2/imgcodecs.hpp>

#include "core/common/cli.h"
#include "core/common/error.h"

namespace evloc::mapper {
namespace {

// Renders progress lines on stderr.
class StderrProgress : public ProgressListener {
 public:
  void OnProgress(const ProgressUpdate& update) override {
    std::ostringstream line;
    line << "[" << std::fixed << std::setprecision(1) << std::setw(7) << update.elapsed_seconds
         << " s] " << update.stage << " " << update.done << "/" << update.total;
    std::cerr << line.str() << std::endl;
  }
};

// The chunked build of a parsed command line; worker processes run this program again with the
// same arguments and `--chunk-index K`.
int RunChunkedBuild(const BuildCommandLine& command_line, StderrProgress* progress) {
  ChunkedBuildOptions options = command_line.chunked_options;
  if (options.workers > 1 && !options.only_chunk && !options.merge_only && !options.plan_only) {
    std::error_code error;
    const std::filesystem::path self = std::filesystem::read_symlink("/proc/self/exe", error);
    if (error) throw IoError("cannot find this program to start workers: " + error.message());
    options.worker_command = {self.string(), "build"};
    for (const std::string& argument : command_line.arguments) {
      options.worker_command.push_back(argument);
    }
    options.worker_command.push_back("--quiet");
  }
  const ChunkedBuildReport report =
      BuildChunkedSite(options, command_line.quiet ? nullptr : progress);
  if (options.plan_only) {
    std::cout << report.chunk_sizes.size() << " chunks by " << report.method << "\n";
    return kExitSuccess;
  }
  if (options.only_chunk) {
    std::cout << "chunk " << *options.only_chunk
              << (report.reused_chunks.empty() ? " computed" : " already finished") << "\n";
    return kExitSuccess;
  }
  const MapBuildReport& build = report.build;
  for (const std::string& note : report.build.calibration_notes) {
    std::cerr << "evloc-mapper build: note: " << note << "\n";
  }
  std::cout << "site written to " << options.build.output_dir.string() << ": " << report.num_tiles
            << " tiles (version " << report.site_version << "), " << build.num_points << " points, "
            << build.num_keyframes << " keyframes, " << build.num_registered << "/"
            << build.num_images << " images registered, " << report.chunk_sizes.size()
            << " chunks by " << report.method << " (" << report.computed_chunks.size()
            << " computed, " << report.reused_chunks.size() << " reused)";
  if (build.alignment_rms_m) {
    std::cout << ", alignment RMS " << *build.alignment_rms_m << " m (scale "
              << *build.alignment_scale << ")";
  }
  std::cout << "\n";
  if (!build.alignment_warning.empty()) {
    std::cerr << "evloc-mapper build: WARNING: --accept-bad-alignment: " << build.alignment_warning
              << "; the site is probably wrong (report.json: alignment.warning)\n";
  }
  return kExitSuccess;
}

}  // namespace

Camera ParseCameraFlag(const std::string& value, int width, int height) {
  const size_t colon = value.find(':');
  if (colon == std::string::npos) {
    throw InvalidArgumentError(
        "--camera: expected MODEL:p1,p2,... (e.g. pinhole:fx,fy,cx,cy), got '" + value + "'");
  }
  Camera camera;
  camera.model = ParseCameraModel(value.substr(0, colon));
  std::vector<double> params;
  std::istringstream stream(value.substr(colon + 1));
  std::string token;
  while (std::getline(stream, token, ',')) params.push_back(ParseDoubleFlag("--camera", token));
  const size_t expected = 4 + NumDistortionCoefficients(camera.model);
  if (params.size() != expected) {
    throw InvalidArgumentError("--camera: model " + CameraModelName(camera.model) + " takes " +
                               std::to_string(expected) + " parameters (fx,fy,cx,cy then " +
                               "distortion), got " + std::to_string(params.size()));
  }
  camera.fx = params[0];
  camera.fy = params[1];
  camera.cx = params[2];
  camera.cy = params[3];
  camera.distortion.assign(params.begin() + 4, params.end());
  camera.width = width;
  camera.height = height;
  return camera;
}

std::string BuildCommandUsage() {
  return R"(Usage: evloc-mapper build --images DIR --out MAPDIR [options]

Builds a semi-dense edge map from images (docs/mapper.md).

Required:
  --images DIR             folder of the input images
  --out MAPDIR             map folder to create (must not exist or be empty)
Inputs:
  --images-list FILE       `t_s path` per image (ECD images.txt); default: all images, by name
  --camera MODEL:PARAMS    fixed intrinsics, evloc convention (pixel centres at integers):
                           pinhole:fx,fy,cx,cy | radtan:fx,fy,cx,cy,k1,k2,p1,p2,k3 |
                           equidistant:fx,fy,cx,cy,k1,k2,k3,k4
  --calib FILE[#CAM]       fixed intrinsics from a calibration file, format detected
                           (docs/camera.md): evloc YAML, Kalibr camchain (#cam1), ROS
                           camera_info, OpenCV YAML/XML, COLMAP cameras.txt (#ID), ECD calib.txt
  --known-poses FILE       world_from_cam per image: TUM `t tx ty tz qx qy qz qw` (needs
                           --images-list) or `IMAGE_NAME tx ty tz qx qy qz qw`; COLMAP only
                           triangulates (needs --camera or --calib)
  --align-to FILE          reference poses (same layouts): Sim(3) alignment of the model;
                           refused when the residuals show a wrong model (limits below)
  --max-alignment-residual F  largest camera-centre RMS after --align-to, as a fraction of the
                           reference camera path's RMS spread (default 0.1)
  --max-alignment-rotation DEG  largest camera-orientation RMS after --align-to (default 5)
  --accept-bad-alignment   build the map anyway beyond those limits, with a warning
COLMAP:
  --matcher M              sequential | exhaustive | retrieval (each photo with its 25 most
                           similar) | auto (default: sequential for a timed --images-list
                           (video), else exhaustive up to 50 images, else sequential; in a
                           chunked build retrieval for chunks cut by retrieval)
  --colmap PATH            COLMAP executable (default: colmap in PATH)
  --colmap-workspace DIR   workspace kept for re-runs (default: MAPDIR.colmap-workspace)
  --threads N              threads for matching, COLMAP and the semi-dense stage (default 2);
                           the map is the same for any N
  --fast-nondeterministic  COLMAP's matcher, and COLMAP feature extraction and mapping on
                           --threads threads (default: evloc's deterministic matcher, one
                           thread and a fixed seed for COLMAP, docs/mapper.md)
  --max-features N         SIFT features per image (default 8192)
Map:
  --max-keyframes N        at most N keyframes (default: no limit)
  --min-keyframes N        at least N keyframes when there are N images (default 12)
  --neighbours N           stereo neighbours per keyframe (default 6)
  --min-confirmations K    keyframes that must confirm a point (default 2)
  --voxel-size METRES      duplicate-merge voxel (default: 1 pixel at the median depth)
  --no-relocalization      skip the relocalization data (landmarks, keyframe features,
                           vocabulary; format v2): a smaller map that cannot relocalize until
                           `evloc-mapper upgrade` adds it
Geo-reference (docs/geo.md; one source at most):
  --geo-anchor LAT,LON,ALT[,HEADING]  the map frame is the ENU frame at this WGS84 point
                           (ellipsoid height), its +y axis at HEADING degrees from north
                           (default 0)
  --geo-points FILE        WGS84 positions of keyframe images or map points (docs/geo.md);
                           the map is aligned to them robustly
  --geo-exif               the GNSS tags in the photos' EXIF data; the camera centres are
                           aligned to them robustly
  --geo-inlier-threshold M  a point agrees with the alignment within M metres (default 10)
Chunked build (docs/mapper.md, "Chunked build"; automatic above 1000 photos):
  --chunked                cut the photos into overlapping chunks, build each, align (Sim(3)
                           and a global adjustment) and merge them; MAPDIR becomes a site of
                           tiles
  --chunk-by METHOD        auto (default: position with --known-poses or --align-to, else
                           sequence for a timed --images-list, else retrieval) | position |
                           sequence (input order) | retrieval (image similarity; each photo
                           of a chunk matched with its 25 most similar)
  --chunk-size N           core photos per chunk (default 250)
  --chunk-overlap M        photos within M metres of a chunk join it (default 6)
  --chunk-overlap-photos N by input order: N photos on each side join a chunk; by retrieval
                           the 2N photos most similar to the chunk (default 20)
  --chunk-workspace DIR    finished chunks and their COLMAP workspaces, kept for a restart
                           (default: MAPDIR.chunks)
  --workers N              chunks computed at once, each by a worker process (default 1: in
                           this process)
  --memory-budget BYTES    peak memory of the build (K, M, G suffixes): refused up front when
                           one chunk cannot fit; fewer workers when they do not fit together
  --chunk-index K          compute chunk K only (a worker, a pod of an Indexed Job)
  --plan-only              write the plan (CHUNK_WORKSPACE/plan.json), print the chunk count
                           and stop
  --merge-only             merge the finished chunks into the site (every chunk must be done)
  --tile-size M            the site's tile edge (default 50)
  --tile-overlap M         the site's tile overlap (default 10)
Output:
  --quiet                  no progress output
  --help                   this text
)";
}

BuildCommandLine ParseBuildCommandLine(const std::vector<std::string>& arguments) {
  BuildCommandLine command_line;
  MapBuilderOptions& options = command_line.options;
  ChunkedBuildOptions& chunked = command_line.chunked_options;
  command_line.arguments.assign(arguments.begin() + (arguments.empty() ? 0 : 1), arguments.end());
  std::optional<std::string> camera_flag;
  std::string recorded = "evloc-mapper build";
  for (size_t i = 1; i < arguments.size(); ++i) {
    const std::string& flag = arguments[i];
    recorded += " " + flag;
    if (flag == "--quiet") {
      command_line.quiet = true;
      continue;
    }
    if (flag == "--accept-bad-alignment") {
      options.accept_bad_alignment = true;
      continue;
    }
    if (flag == "--no-relocalization") {
      options.relocalization = false;
      continue;
    }
    if (flag == "--geo-exif") {
      options.geo.exif = true;
      continue;
    }
    if (flag == "--chunked") {
      command_line.chunked = true;
      continue;
    }
    if (flag == "--merge-only") {
      command_line.chunked = true;
      command_line.chunked_options.merge_only = true;
      continue;
    }
    if (flag == "--plan-only") {
      command_line.chunked = true;
      command_line.chunked_options.plan_only = true;
      continue;
    }
    if (flag == "--fast-nondeterministic") {
      options.colmap.deterministic = false;
      continue;
    }
    if (flag == "--help" || flag == "-h") {
      command_line.help = true;
      continue;
    }
    if (flag.rfind("--", 0) != 0) {
      throw InvalidArgumentError("unexpected argument '" + flag + "'");
    }
    if (i + 1 >= arguments.size()) throw InvalidArgumentError(flag + " needs a value");
    const std::string value = arguments[++i];
    recorded += " " + value;
    if (flag == "--images") {
      options.image_dir = value;
    } else if (flag == "--out") {
      options.output_dir = value;
    } else if (flag == "--images-list") {
      options.image_list = value;
    } else if (flag == "--camera") {
      camera_flag = value;
    } else if (flag == "--calib") {
      options.calibration_file = value;
    } else if (flag == "--known-poses") {
      options.known_poses = value;
    } else if (flag == "--align-to") {
      options.align_to = value;
    } else if (flag == "--max-alignment-residual") {
      options.alignment_limits.max_centre_rms_fraction = ParseDoubleFlag(flag, value);
    } else if (flag == "--max-alignment-rotation") {
      options.alignment_limits.max_rotation_rms_deg = ParseDoubleFlag(flag, value);
    } else if (flag == "--matcher") {
      options.colmap.matcher = ParseMatcherType(value);
    } else if (flag == "--colmap") {
      options.colmap.executable = value;
    } else if (flag == "--colmap-workspace") {
      options.colmap_workspace = value;
    } else if (flag == "--threads") {
      options.colmap.num_threads = ParseIntFlag(flag, value);
      options.semidense.num_threads = options.colmap.num_threads;
    } else if (flag == "--max-features") {
      options.colmap.max_num_features = ParseIntFlag(flag, value);
    } else if (flag == "--max-keyframes") {
      options.keyframes.max_keyframes = ParseIntFlag(flag, value);
    } else if (flag == "--min-keyframes") {
      options.keyframes.min_keyframes = ParseIntFlag(flag, value);
    } else if (flag == "--neighbours") {
      options.keyframes.num_neighbours = ParseIntFlag(flag, value);
    } else if (flag == "--min-confirmations") {
      options.semidense.min_keyframe_confirmations = ParseIntFlag(flag, value);
    } else if (flag == "--geo-anchor") {
      options.geo.given = ParseGeoAnchorFlag(flag, value);
    } else if (flag == "--geo-points") {
      options.geo.points_file = value;
    } else if (flag == "--geo-inlier-threshold") {
      options.geo.alignment.inlier_threshold_m = ParseDoubleFlag(flag, value);
    } else if (flag == "--voxel-size") {
      options.merge.voxel_size = ParseDoubleFlag(flag, value);
    } else if (flag == "--chunk-by") {
      chunked.chunking.method = ParseChunkMethod(value);
    } else if (flag == "--chunk-size") {
      chunked.chunking.chunk_size = static_cast<size_t>(ParseUnsignedFlag(flag, value));
    } else if (flag == "--chunk-overlap") {
      chunked.chunking.overlap_m = ParseDoubleFlag(flag, value);
    } else if (flag == "--chunk-overlap-photos") {
      chunked.chunking.overlap_photos = static_cast<size_t>(ParseUnsignedFlag(flag, value));
    } else if (flag == "--chunk-workspace") {
      chunked.chunk_workspace = value;
    } else if (flag == "--workers") {
      chunked.workers = ParseIntFlag(flag, value);
    } else if (flag == "--memory-budget") {
      chunked.memory_budget_bytes = ParseByteSizeFlag(flag, value);
    } else if (flag == "--chunk-index") {
      chunked.only_chunk = static_cast<size_t>(ParseUnsignedFlag(flag, value));
      command_line.chunked = true;
    } else if (flag == "--tile-size") {
      chunked.tile_size_m = ParseDoubleFlag(flag, value);
    } else if (flag == "--tile-overlap") {
      chunked.tile_overlap_m = ParseDoubleFlag(flag, value);
    } else {
      throw InvalidArgumentError("unknown flag '" + flag + "' (see --help)");
    }
  }
  options.command_line = recorded;
  if (command_line.help) return command_line;
  if (options.image_dir.empty()) throw InvalidArgumentError("--images DIR is required");
  if (options.output_dir.empty()) throw InvalidArgumentError("--out MAPDIR is required");
  if (!command_line.chunked && !camera_flag) {
    // A bad image folder or list is the build's error (exit 1), not the command line's: count
    // only what can be listed.
    try {
      command_line.chunked =
          ListInputImages(options.image_dir, options.image_list).size() > kChunkedBuildAbovePhotos;
    } catch (const Error&) {
    }
  }
  if (camera_flag) {
    // The camera size is the images' size.
    const std::vector<InputImage> images = ListInputImages(options.image_dir, options.image_list);
    const cv::Mat first =
        cv::imread((options.image_dir / images[0].name).string(), cv::IMREAD_UNCHANGED);
    if (first.empty()) {
      throw InvalidArgumentError("cannot read image " +
                                 (options.image_dir / images[0].name).string());
    }
    options.camera = ParseCameraFlag(*camera_flag, first.cols, first.rows);
    command_line.chunked = command_line.chunked || images.size() > kChunkedBuildAbovePhotos;
  }
  chunked.build = options;
  if (command_line.chunked) chunked.Check();
  return command_line;
}

int RunBuildCommand(int argc, char** argv) {
  const std::vector<std::string> arguments(argv, argv + argc);
  return RunGuarded("evloc-mapper build", std::cerr, [&] {
    const BuildCommandLine command_line = ParseCommandLine(ParseBuildCommandLine, arguments);
    if (command_line.help) {
      std::cout << BuildCommandUsage();
      return kExitSuccess;
    }
    StderrProgress progress;
    if (command_line.chunked) return RunChunkedBuild(command_line, &progress);
    const MapBuildReport report =
        BuildMap(command_line.options, command_line.quiet ? nullptr : &progress);
    std::cout << "map written to " << command_line.options.output_dir.string() << ": "
              << report.num_points << " points, " << report.num_keyframes << " keyframes, "
              << report.num_registered << "/" << report.num_images << " images registered";
    if (report.alignment_rms_m) {
      std::cout << ", alignment RMS " << *report.alignment_rms_m << " m (scale "
                << *report.alignment_scale << ")";
    }
    if (report.relocalization) {
      std::cout << ", relocalization: " << report.relocalization->num_landmarks << " landmarks, "
                << report.relocalization->num_features_kept << " keyframe features, "
                << report.relocalization->bytes_added << " bytes";
    }
    std::cout << "\n";
    if (report.geo_anchor)
      std::cout << FormatGeoReference(*report.geo_anchor, report.geo_alignment, report.geo_inputs);
    for (const std::string& note : report.calibration_notes) {
      std::cerr << "evloc-mapper build: note: " << note << "\n";
    }
    if (!report.relocalization_warning.empty()) {
      // Printed even with --quiet: the map cannot relocalize.
      std::cerr << "evloc-mapper build: WARNING: the map has no relocalization data: "
                << report.relocalization_warning << " (report.json: relocalization_warning)\n";
    }
    if (!report.alignment_warning.empty()) {
      // Printed even with --quiet: the map was built from a model that does not fit --align-to.
      std::cerr << "evloc-mapper build: WARNING: --accept-bad-alignment: "
                << report.alignment_warning
                << "; the map is probably wrong (report.json: alignment.warning)\n";
    }
    return kExitSuccess;
  });
}

}  // namespace evloc::mapper
