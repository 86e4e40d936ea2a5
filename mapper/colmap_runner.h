// Runs the COLMAP 3.8 command line (CPU only) for the mapper: feature extraction, matching,
// incremental mapping, triangulation with known poses and conversion to the TXT layout
// (docs/mapper.md, "COLMAP"). Every command's output goes to a log file; nothing is
// printed.
#pragma once

#include <chrono>
#include <cstdint>
#include <filesystem>
#include <functional>
#include <map>
#include <optional>
#include <string>
#include <vector>

#include "core/camera/camera.h"
#include "core/common/error.h"
#include "mapper/colmap_database.h"

namespace evloc::mapper {

// How image pairs are chosen for feature matching.
enum class MatcherType {
  // Exhaustive for small sets (ColmapOptions::exhaustive_max_images), sequential otherwise
  // (BuildMap also picks sequential for a timed image list, i.e. a video).
  kAuto,
  // Every image against the next ones in name order (video-like sequences).
  kSequential,
  // Every pair (small unordered sets).
  kExhaustive,
  // Each image with its most similar images by image retrieval (RetrievalPairs; large unordered
  // sets, and chunks whose photos' order does not follow their places); evloc's matcher only.
  kRetrieval,
};

// Parses "auto", "sequential", "exhaustive" or "retrieval"; throws InvalidArgumentError otherwise.
MatcherType ParseMatcherType(const std::string& name);

// The name ParseMatcherType accepts for `type`.
std::string MatcherTypeName(MatcherType type);

// Options of the COLMAP runs.
struct ColmapOptions {
  // The COLMAP executable: a path, or a name looked up in PATH.
  std::string executable = "colmap";
  // Threads for extraction, matching and mapping (with `deterministic`: evloc's matching only).
  int num_threads = 2;
  // Reproducible runs (the default, docs/mapper.md "Reproducible maps"): evloc's matcher
  // (mapper/feature_matching.h) replaces COLMAP's, every command gets --random_seed, and
  // feature extraction (whose threads number the images in the order they
  // finish), mapping and triangulation run on one thread (COLMAP 3.8's bundle_adjuster has no
  // thread option). false: COLMAP's matcher and num_threads everywhere
  // (--fast-nondeterministic).
  bool deterministic = true;
  // The seed passed as --random_seed to every COLMAP command.
  int random_seed = 0;
  // Pair selection for matching.
  MatcherType matcher = MatcherType::kAuto;
  // With kAuto, exhaustive matching up to this many images, sequential above.
  int exhaustive_max_images = 50;
  // Sequential matching: how many following images each image is matched with.
  int sequential_overlap = 10;
  // Retrieval matching: how many most similar images each image is matched with.
  int retrieval_neighbours = 25;
  // Maximum number of SIFT features per image.
  int max_num_features = 8192;
  // mapper: minimum inliers to register an image (COLMAP's default 30 leaves images of weakly
  // textured objects such as the Middlebury temple unregistered).
  int abs_pose_min_num_inliers = 15;
  // mapper: minimum inlier ratio to register an image (COLMAP's default 0.25).
  double abs_pose_min_inlier_ratio = 0.1;
  // mapper: minimum matches for an image pair to be used (COLMAP's default 15).
  int min_num_matches = 10;
  // With fixed intrinsics (`camera` set), the estimated model is refined after mapping
  // (RefineModel), one pass per bound: observations whose reprojection error exceeds the bound
  // (pixels) are dropped (point_filtering), then a global bundle adjustment. With calibrated
  // intrinsics the inliers reproject within a few tenths of a pixel, so COLMAP's 4 px keeps
  // mismatches that bend weakly constrained poses; the tighter bound is applied to a model already
  // adjusted without the worst of them. Measured (docs/mapper.md): templeSparseRing worst camera
  // position 1.40 % of the object distance unrefined, 1.15 % with one 1 px pass, 0.29 % with
  // {0.5, 0.3}; the 90-frame room circle 11.2 / 8.5 / 5.2 mm RMS (centre alignment). Applied
  // during mapping instead, a tight bound rejects observations of the not yet adjusted early model
  // and broke the circle. Decreasing, each in [0.1, 100]. With estimated intrinsics COLMAP's
  // result is kept as it is.
  std::vector<double> fixed_camera_refinement_px = {0.5, 0.3};
  // Fixed intrinsics shared by every image; std::nullopt lets COLMAP estimate one camera
  // (SIMPLE_RADIAL) shared by all images.
  std::optional<Camera> camera;

  // Throws InvalidArgumentError on a bad value.
  void Check() const;
  // Threads of the stages whose results depend on their thread count: 1 when deterministic.
  int OrderedStageThreads() const { return deterministic ? 1 : num_threads; }
};

// The absolute path of `executable` (kept as given when it contains a '/', else looked up in
// PATH). Throws IoError naming the executable when it cannot be found or is not executable.
std::filesystem::path FindExecutable(const std::string& executable);

// The first line of `colmap help` (e.g. "COLMAP 3.8 -- Structure-from-Motion and Multi-View
// Stereo"), the version recorded in reports. Throws IoError when COLMAP cannot be run.
std::string ColmapVersion(const ColmapOptions& options);

// What RunLoggedCommand watches while a command runs: a command whose work is done (`done`,
// asked about once a second, returns true) but that has not exited `exit_grace` later is taken
// as hung, killed, and reported as CommandHungError. COLMAP 3.8's feature_extractor sometimes
// never exits after its last image (its feature writer thread waits on an empty queue).
struct CommandWatch {
  std::function<bool()> done;
  std::chrono::milliseconds exit_grace{30000};
};

// A command that RunLoggedCommand killed because it did not exit once its work was done.
class CommandHungError : public IoError {
 public:
  using IoError::IoError;
};

// Runs `arguments` (arguments[0] is the program) with stdout and stderr appended to `log_path`
// and waits for it. Throws IoError when the program cannot be started, or exits non-zero or by a
// signal; the message names the command and the log file and quotes the log's last lines. With
// `watch`, throws CommandHungError (after a line in the log) for a command that hung.
void RunLoggedCommand(const std::vector<std::string>& arguments,
                      const std::filesystem::path& log_path, const CommandWatch* watch = nullptr);

// The COLMAP commands used by the mapper, on one workspace. Each writes into the workspace and
// appends to `<workspace>/logs/<command>.log`.
class ColmapRunner {
 public:
  // `workspace` holds database.db, the models and the logs; `image_dir` is COLMAP's image_path.
  // Checks the options and finds the executable (throws like FindExecutable).
  ColmapRunner(ColmapOptions options, std::filesystem::path workspace,
               std::filesystem::path image_dir);

  // The database path.
  std::filesystem::path DatabasePath() const { return workspace_ / "database.db"; }
  // The folder of the logs.
  std::filesystem::path LogDir() const { return workspace_ / "logs"; }

  // feature_extractor on `image_names` (relative to the image folder): one camera for all
  // images, fixed to options.camera when given.
  void ExtractFeatures(const std::vector<std::string>& image_names) const;
  // Matches the features of the database, pairs chosen by EffectiveMatcher: deterministic,
  // evloc's matcher (MatchDatabase, options.num_threads threads, a summary appended to
  // logs/evloc_matcher.log); otherwise COLMAP's sequential_matcher or exhaustive_matcher.
  void MatchFeatures(size_t num_images) const;
  // The effective matcher for `num_images` images (kAuto resolved).
  MatcherType EffectiveMatcher(size_t num_images) const;
  // mapper into `<output_dir>/0, 1, ...`; intrinsics are not refined when options.camera is set.
  void Map(const std::filesystem::path& output_dir) const;
  // For each bound k of options.fixed_camera_refinement_px: point_filtering (reprojection error
  // above the bound) into `<output_model>.filteredK`, then bundle_adjuster with fixed intrinsics
  // (into `<output_model>.adjustedK`, the last pass into `output_model`).
  void RefineModel(const std::filesystem::path& input_model,
                   const std::filesystem::path& output_model) const;
  // point_triangulator: triangulates points for the fixed poses of `input_model` (TXT or BIN)
  // into `output_model`; poses are not moved.
  void Triangulate(const std::filesystem::path& input_model,
                   const std::filesystem::path& output_model) const;
  // model_converter --output_type TXT.
  void ConvertToText(const std::filesystem::path& input_model,
                     const std::filesystem::path& output_dir) const;

 private:
  // Runs `colmap <command> <arguments...>` logging to LogDir()/<command>.log.
  void Run(const std::string& command, const std::vector<std::string>& arguments,
           const CommandWatch* watch = nullptr) const;

  ColmapOptions options_;
  std::filesystem::path executable_;
  std::filesystem::path workspace_;
  std::filesystem::path image_dir_;
};

}  // namespace evloc::mapper
