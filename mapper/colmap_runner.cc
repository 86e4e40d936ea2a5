#include "mapper/colmap_runner.h"

#include <fcntl.h>
#include <sys/prctl.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <csignal>
#include <cstdlib>
#include <cstring>
#include <deque>
#include <fstream>
#include <optional>
#include <sstream>
#include <thread>

#include "core/common/error.h"
#include "core/common/file_util.h"
#include "mapper/colmap_model.h"
#include "mapper/feature_matching.h"

extern char** environ;

namespace evloc::mapper {
namespace {

// The last `count` lines of a text file (empty when unreadable).
std::string TailOfFile(const std::filesystem::path& path, size_t count) {
  std::ifstream stream(path);
  std::deque<std::string> lines;
  std::string line;
  while (std::getline(stream, line)) {
    if (line.empty()) continue;
    lines.push_back(line);
    if (lines.size() > count) lines.pop_front();
  }
  std::string text;
  for (const std::string& kept : lines) text += "\n  " + kept;
  return text;
}

bool IsExecutableFile(const std::filesystem::path& path) {
  std::error_code error;
  return std::filesystem::is_regular_file(path, error) && ::access(path.c_str(), X_OK) == 0;
}

void CreateDirectories(const std::filesystem::path& path) {
  std::error_code error;
  std::filesystem::create_directories(path, error);
  if (error) throw IoError("cannot create directory " + path.string() + ": " + error.message());
}

}  // namespace

MatcherType ParseMatcherType(const std::string& name) {
  if (name == "auto") return MatcherType::kAuto;
  if (name == "sequential") return MatcherType::kSequential;
  if (name == "exhaustive") return MatcherType::kExhaustive;
  if (name == "retrieval") return MatcherType::kRetrieval;
  throw InvalidArgumentError("unknown matcher '" + name +
                             "' (expected sequential, exhaustive, retrieval or auto)");
}

std::string MatcherTypeName(MatcherType type) {
  switch (type) {
    case MatcherType::kAuto:
      return "auto";
    case MatcherType::kSequential:
      return "sequential";
    case MatcherType::kExhaustive:
      return "exhaustive";
    case MatcherType::kRetrieval:
      return "retrieval";
  }
  return "auto";
}

void ColmapOptions::Check() const {
  if (executable.empty()) throw InvalidArgumentError("COLMAP executable must not be empty");
  if (num_threads < 1) throw InvalidArgumentError("COLMAP num_threads must be at least 1");
  if (random_seed < 0) throw InvalidArgumentError("COLMAP random_seed must be >= 0");
  if (exhaustive_max_images < 2) {
    throw InvalidArgumentError("COLMAP exhaustive_max_images must be at least 2");
  }
  if (sequential_overlap < 1) {
    throw InvalidArgumentError("COLMAP sequential_overlap must be at least 1");
  }
  if (retrieval_neighbours < 1) {
    throw InvalidArgumentError("the retrieval matcher's neighbours must be at least 1");
  }
  if (matcher == MatcherType::kRetrieval && !deterministic) {
    throw InvalidArgumentError(
        "--matcher retrieval is evloc's matcher (COLMAP's vocab_tree_matcher needs a vocabulary "
        "file Debian does not ship): drop --fast-nondeterministic");
  }
  if (max_num_features < 100) {
    throw InvalidArgumentError("COLMAP max_num_features must be at least 100");
  }
  if (abs_pose_min_num_inliers < 4) {
    throw InvalidArgumentError("COLMAP abs_pose_min_num_inliers must be at least 4");
  }
  if (!(abs_pose_min_inlier_ratio > 0.0 && abs_pose_min_inlier_ratio <= 1.0)) {
    throw InvalidArgumentError("COLMAP abs_pose_min_inlier_ratio must be in (0, 1]");
  }
  if (min_num_matches < 4) throw InvalidArgumentError("COLMAP min_num_matches must be at least 4");
  for (size_t i = 0; i < fixed_camera_refinement_px.size(); ++i) {
    const double bound = fixed_camera_refinement_px[i];
    if (!(bound >= 0.1 && bound <= 100.0)) {
      throw InvalidArgumentError("COLMAP fixed_camera_refinement_px must be in [0.1, 100] pixels");
    }
    if (i > 0 && !(bound < fixed_camera_refinement_px[i - 1])) {
      throw InvalidArgumentError("COLMAP fixed_camera_refinement_px must be decreasing");
    }
  }
  if (camera) camera->Check();
}

std::filesystem::path FindExecutable(const std::string& executable) {
  if (executable.find('/') != std::string::npos) {
    if (!IsExecutableFile(executable)) {
      throw IoError("COLMAP executable " + executable + " does not exist or is not executable");
    }
    return std::filesystem::absolute(executable);
  }
  const char* path_variable = std::getenv("PATH");
  std::istringstream directories(path_variable ? path_variable : "");
  std::string directory;
  while (std::getline(directories, directory, ':')) {
    if (directory.empty()) continue;
    const std::filesystem::path candidate = std::filesystem::path(directory) / executable;
    if (IsExecutableFile(candidate)) return candidate;
  }
  throw IoError("'" + executable +
                "' was not found in PATH: install COLMAP 3.8 (apt-get install colmap) or pass "
                "the executable's path with --colmap");
}

void RunLoggedCommand(const std::vector<std::string>& arguments,
                      const std::filesystem::path& log_path, const CommandWatch* watch) {
  if (arguments.empty()) throw InvalidArgumentError("RunLoggedCommand: no program given");
  std::vector<char*> argv;
  for (const std::string& argument : arguments) argv.push_back(const_cast<char*>(argument.c_str()));
  argv.push_back(nullptr);

  std::string command_line;
  for (const std::string& argument : arguments)
    command_line += (command_line.empty() ? "" : " ") + argument;
  {
    std::ofstream log(log_path, std::ios::app);
    log << "$ " << command_line << "\n";
    if (!log) throw IoError("cannot write the log file " + log_path.string());
  }
  // Opened before the fork: the child only duplicates descriptors and execs.
  const int input = ::open("/dev/null", O_RDONLY | O_CLOEXEC);
  const int output = ::open(log_path.c_str(), O_WRONLY | O_CREAT | O_APPEND | O_CLOEXEC, 0644);
  if (input < 0 || output < 0) {
    if (input >= 0) ::close(input);
    if (output >= 0) ::close(output);
    throw IoError("cannot open the log file " + log_path.string());
  }
  const pid_t parent = ::getpid();
  const pid_t pid = ::fork();
  if (pid == 0) {
    // The child dies with the thread that started it: a killed build (a resumable chunked build,
    // docs/mapper.md) leaves no COLMAP behind writing into the workspace a restart reuses.
    ::prctl(PR_SET_PDEATHSIG, SIGKILL);
    if (::getppid() != parent) ::_exit(127);
    ::dup2(input, STDIN_FILENO);
    ::dup2(output, STDOUT_FILENO);
    ::dup2(output, STDERR_FILENO);
    ::execve(argv[0], argv.data(), environ);
    ::_exit(127);
  }
  const int fork_error = errno;
  ::close(input);
  ::close(output);
  if (pid < 0) {
    throw IoError("cannot start " + arguments[0] + ": " + std::strerror(fork_error));
  }
  int status = 0;
  if (watch == nullptr) {
    while (::waitpid(pid, &status, 0) < 0) {
      if (errno != EINTR) throw IoError("waiting for " + arguments[0] + " failed");
    }
  } else {
    using Clock = std::chrono::steady_clock;
    std::optional<Clock::time_point> done_at;
    auto next_check = Clock::now();
    while (true) {
      const pid_t waited = ::waitpid(pid, &status, WNOHANG);
      if (waited == pid) break;
      if (waited < 0 && errno != EINTR) throw IoError("waiting for " + arguments[0] + " failed");
      const auto now = Clock::now();
      if (now >= next_check) {
        next_check = now + std::chrono::seconds(1);
        if (!done_at && watch->done()) done_at = now;
      }
      if (done_at && now - *done_at > watch->exit_grace) {
        ::kill(pid, SIGKILL);
        while (::waitpid(pid, &status, 0) < 0 && errno == EINTR) {
        }
        const std::string message =
            "`" + command_line + "` had done its work but did not exit within " +
            std::to_string(watch->exit_grace.count()) + " ms; it was stopped";
        std::ofstream(log_path, std::ios::app) << "evloc: " << message << "\n";
        throw CommandHungError("command " + message + "; see " + log_path.string());
      }
      std::this_thread::sleep_for(std::chrono::milliseconds(50));
    }
  }
  if (WIFEXITED(status) && WEXITSTATUS(status) == 0) return;
  const std::string how = WIFEXITED(status)
                              ? "exited with status " + std::to_string(WEXITSTATUS(status))
                              : "was killed by signal " + std::to_string(WTERMSIG(status));
  throw IoError("command `" + command_line + "` " + how + "; see " + log_path.string() +
                ", which ends with:" + TailOfFile(log_path, 6));
}

std::string ColmapVersion(const ColmapOptions& options) {
  const std::filesystem::path executable = FindExecutable(options.executable);
  char log_template[] = "/tmp/evloc-colmap-version-XXXXXX";
  const int descriptor = ::mkstemp(log_template);
  if (descriptor < 0) throw IoError("cannot create a temporary file in /tmp");
  ::close(descriptor);
  const std::filesystem::path log_path(log_template);
  try {
    RunLoggedCommand({executable.string(), "help"}, log_path);
  } catch (...) {
    std::filesystem::remove(log_path);
    throw;
  }
  std::ifstream stream(log_path);
  std::string line;
  std::string version;
  while (std::getline(stream, line)) {
    if (line.rfind("COLMAP", 0) == 0) {
      version = line;
      break;
    }
  }
  std::filesystem::remove(log_path);
  if (version.empty()) throw IoError(executable.string() + " help did not print a COLMAP version");
  return version;
}

ColmapRunner::ColmapRunner(ColmapOptions options, std::filesystem::path workspace,
                           std::filesystem::path image_dir)
    : options_(std::move(options)),
      workspace_(std::move(workspace)),
      image_dir_(std::move(image_dir)) {
  options_.Check();
  executable_ = FindExecutable(options_.executable);
}

void ColmapRunner::Run(const std::string& command, const std::vector<std::string>& arguments,
                       const CommandWatch* watch) const {
  CreateDirectories(LogDir());
  std::vector<std::string> full = {executable_.string(), command};
  full.insert(full.end(), arguments.begin(), arguments.end());
  full.insert(full.end(), {"--random_seed", std::to_string(options_.random_seed)});
  RunLoggedCommand(full, LogDir() / (command + ".log"), watch);
}

void ColmapRunner::ExtractFeatures(const std::vector<std::string>& image_names) const {
  CreateDirectories(workspace_);
  const std::filesystem::path list_path = workspace_ / "image_list.txt";
  std::string list;
  for (const std::string& name : image_names) list += name + "\n";
  WriteFileAtomically(list_path, list);
  std::vector<std::string> arguments = {"--database_path",
                                        DatabasePath().string(),
                                        "--image_path",
                                        image_dir_.string(),
                                        "--image_list_path",
                                        list_path.string(),
                                        "--ImageReader.single_camera",
                                        "1",
                                        "--SiftExtraction.use_gpu",
                                        "0",
                                        "--SiftExtraction.num_threads",
                                        std::to_string(options_.OrderedStageThreads()),
                                        "--SiftExtraction.max_num_features",
                                        std::to_string(options_.max_num_features)};
  if (options_.camera) {
    const ColmapCamera colmap_camera = ColmapCameraFromCamera(*options_.camera, 1);
    arguments.insert(arguments.end(),
                     {"--ImageReader.camera_model", colmap_camera.model_name,
                      "--ImageReader.camera_params", FormatColmapParams(colmap_camera.params)});
  } else {
    arguments.insert(arguments.end(), {"--ImageReader.camera_model", "SIMPLE_RADIAL"});
  }
  // COLMAP 3.8's feature_extractor sometimes hangs after its last image (seen in this project's
  // test suite on 2026-11-28: every thread waiting, its feature writer on an empty queue, the log
  // ending at "Processed file [N/N]"). Such a run is stopped 30 s after that line and run again:
  // the database keeps what was committed, and COLMAP skips the images it already holds.
  const std::filesystem::path log = LogDir() / "feature_extractor.log";
  const std::string last = "Processed file [" + std::to_string(image_names.size()) + "/" +
                           std::to_string(image_names.size()) + "]";
  for (int attempt = 1;; ++attempt) {
    std::error_code no_log;
    const uint64_t start =
        std::filesystem::exists(log, no_log) ? std::filesystem::file_size(log) : 0;
    CommandWatch watch;
    watch.done = [&log, &last, start] {
      const std::string text = ReadFileToString(log);
      return text.find(last, start) != std::string::npos;  // npos too when start > size
    };
    try {
      Run("feature_extractor", arguments, &watch);
      return;
    } catch (const CommandHungError&) {
      if (attempt == 3) throw;
    }
  }
}

MatcherType ColmapRunner::EffectiveMatcher(size_t num_images) const {
  if (options_.matcher != MatcherType::kAuto) return options_.matcher;
  return num_images <= static_cast<size_t>(options_.exhaustive_max_images)
             ? MatcherType::kExhaustive
             : MatcherType::kSequential;
}

void ColmapRunner::MatchFeatures(size_t num_images) const {
  const MatcherType matcher = EffectiveMatcher(num_images);
  const bool exhaustive = matcher == MatcherType::kExhaustive;
  if (options_.deterministic) {
    CreateDirectories(LogDir());
    FeatureMatchingOptions matching;
    matching.num_threads = options_.num_threads;
    PairChoice choice;
    if (matcher == MatcherType::kSequential)
      choice.sequential_overlap = options_.sequential_overlap;
    if (matcher == MatcherType::kRetrieval) {
      choice.retrieval_neighbours = options_.retrieval_neighbours;
    }
    const DatabaseMatchingSummary summary =
        MatchDatabase(DatabasePath(), choice, options_.camera, matching);
    std::ofstream log(LogDir() / "evloc_matcher.log", std::ios::app);
    log << "evloc matcher (" << MatcherTypeName(matcher) << ", "
        << (options_.camera ? "E, F and H" : "F and H") << "): " << summary.num_images
        << " images, " << summary.num_pairs << " pairs, " << summary.num_matches << " matches, "
        << summary.num_verified_pairs << " verified pairs, " << summary.num_inlier_matches
        << " inlier matches\n";
    if (!log) throw IoError("cannot write " + (LogDir() / "evloc_matcher.log").string());
    return;
  }
  const std::vector<std::string> common = {"--database_path",
                                           DatabasePath().string(),
                                           "--SiftMatching.use_gpu",
                                           "0",
                                           "--SiftMatching.num_threads",
                                           std::to_string(options_.num_threads)};
  if (exhaustive) {
    Run("exhaustive_matcher", common);
  } else {
    std::vector<std::string> arguments = common;
    arguments.insert(arguments.end(),
                     {"--SequentialMatching.overlap", std::to_string(options_.sequential_overlap),
                      "--SequentialMatching.loop_detection", "0"});
    Run("sequential_matcher", arguments);
  }
}

void ColmapRunner::Map(const std::filesystem::path& output_dir) const {
  CreateDirectories(output_dir);
  std::vector<std::string> arguments = {"--database_path",
                                        DatabasePath().string(),
                                        "--image_path",
                                        image_dir_.string(),
                                        "--output_path",
                                        output_dir.string(),
                                        "--Mapper.num_threads",
                                        std::to_string(options_.OrderedStageThreads()),
                                        "--Mapper.abs_pose_min_num_inliers",
                                        std::to_string(options_.abs_pose_min_num_inliers),
                                        "--Mapper.abs_pose_min_inlier_ratio",
                                        std::to_string(options_.abs_pose_min_inlier_ratio),
                                        "--Mapper.min_num_matches",
                                        std::to_string(options_.min_num_matches)};
  if (options_.camera) {
    arguments.insert(arguments.end(),
                     {"--Mapper.ba_refine_focal_length", "0", "--Mapper.ba_refine_principal_point",
                      "0", "--Mapper.ba_refine_extra_params", "0"});
  }
  Run("mapper", arguments);
}

void ColmapRunner::RefineModel(const std::filesystem::path& input_model,
                               const std::filesystem::path& output_model) const {
  std::filesystem::path current = input_model;
  const size_t passes = options_.fixed_camera_refinement_px.size();
  for (size_t pass = 0; pass < passes; ++pass) {
    const std::string suffix = std::to_string(pass + 1);
    const std::filesystem::path filtered = output_model.string() + ".filtered" + suffix;
    const std::filesystem::path adjusted =
        pass + 1 == passes ? output_model
                           : std::filesystem::path(output_model.string() + ".adjusted" + suffix);
    CreateDirectories(filtered);
    CreateDirectories(adjusted);
    Run("point_filtering",
        {"--input_path", current.string(), "--output_path", filtered.string(), "--max_reproj_error",
         std::to_string(options_.fixed_camera_refinement_px[pass])});
    Run("bundle_adjuster",
        {"--input_path", filtered.string(), "--output_path", adjusted.string(),
         "--BundleAdjustment.refine_focal_length", "0", "--BundleAdjustment.refine_principal_point",
         "0", "--BundleAdjustment.refine_extra_params", "0"});
    current = adjusted;
  }
}

void ColmapRunner::Triangulate(const std::filesystem::path& input_model,
                               const std::filesystem::path& output_model) const {
  CreateDirectories(output_model);
  Run("point_triangulator",
      {"--database_path", DatabasePath().string(), "--image_path", image_dir_.string(),
       "--input_path", input_model.string(), "--output_path", output_model.string(),
       "--Mapper.ba_refine_focal_length", "0", "--Mapper.ba_refine_principal_point", "0",
       "--Mapper.ba_refine_extra_params", "0", "--Mapper.num_threads",
       std::to_string(options_.OrderedStageThreads())});
}

void ColmapRunner::ConvertToText(const std::filesystem::path& input_model,
                                 const std::filesystem::path& output_dir) const {
  CreateDirectories(output_dir);
  Run("model_converter", {"--input_path", input_model.string(), "--output_path",
                          output_dir.string(), "--output_type", "TXT"});
}

}  // namespace evloc::mapper
