// evloc-mapper-accuracy: measures a built map against a synthetic dataset's exact scene
// (gt_map/ and the rendered depth maps; docs/mapper.md, "Accuracy on synthetic sequences"), or
// against the edges of the real keyframe images it was built from (--images).
// Prints one JSON object on stdout; exit code 2 for a bad command line, 1 for an error.

#include <algorithm>
#include <filesystem>
#include <iostream>
#include <sstream>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "core/camera/camera.h"
#include "core/common/cli.h"
#include "core/common/cli_app.h"
#include "core/common/error.h"
#include "core/common/file_util.h"
#include "maps/map.h"
#include "maps/map_directory.h"
#include "tools/map_accuracy/map_accuracy.h"
#include "tools/map_accuracy/reference_gradients.h"

namespace {

namespace fs = std::filesystem;
using evloc::mapper::DepthView;

// What the command line asks for.
struct AccuracyCommand {
  // The map directory or .evmap file (--map).
  fs::path map_path;
  // The evloc-sim dataset (--dataset).
  fs::path dataset;
  // The image folder of the build (--images).
  fs::path image_dir;
  // Per-point CSV output (--points-csv), empty for none.
  fs::path points_csv;
  // Every N-th depth map (--depth-stride).
  int stride = 1;
  // Measure options (--within).
  evloc::mapper::MapAccuracyOptions options;
  // Print the usage (--help).
  bool help = false;
};

// The command line over `command`.
std::unique_ptr<evloc::CommandLine> DeclareAccuracyCommandLine(AccuracyCommand* command) {
  auto line = std::make_unique<evloc::CommandLine>(
      "evloc-mapper-accuracy", "--map MAPDIR --dataset DIR [options]\n--map MAPDIR --images DIR",
      "Measures a map against an evloc-sim dataset: depth error against the rendered depth maps "
      "(nearest frame by camera centre), distance to the exact edges of DIR/gt_map and gradient "
      "angles (also without the convex creases, whose image gradient depends on the "
      "background).\nWith --images instead: the distance in pixels from each keyframe's "
      "projected visible points to the nearest Canny edge (40/100) of its image (real data "
      "without a ground-truth scene). Prints one JSON object.");
  line->Add("--map", "MAPDIR", "map directory or .evmap file", &command->map_path)
      .Add("--dataset", "DIR",
           "evloc-sim dataset (calib.yaml, depth.txt, groundtruth.txt, gt_map/)", &command->dataset)
      .Add("--images", "DIR", "the image folder given to `evloc-mapper build --images`",
           &command->image_dir)
      .Add("--within", "METRES", "threshold of the \"within\" fractions (default 0.02)",
           &command->options.within_m)
      .Add("--depth-stride", "N", "use every N-th depth map (default 1)", &command->stride)
      .Add("--points-csv", "FILE",
           "also write one line per map point: x y z gx gy gz depth_error_m edge_distance_m "
           "gradient_angle_deg image_gradient_angle_deg reference_index",
           &command->points_csv)
      .Footer("Exit codes: 0 success, 1 failure, 2 bad command line.");
  return line;
}

// Parses the arguments after the program name; throws evloc::Error for a bad command line.
AccuracyCommand ParseAccuracyCommandLine(const std::vector<std::string>& arguments) {
  AccuracyCommand command = evloc::ParseDeclaredCommandLine(&DeclareAccuracyCommandLine, arguments);
  if (command.help) return command;
  if (command.map_path.empty() || command.dataset.empty() == command.image_dir.empty()) {
    throw evloc::InvalidArgumentError("--map and one of --dataset or --images are required");
  }
  if (command.stride < 1) throw evloc::InvalidArgumentError("--depth-stride must be at least 1");
  command.options.Check();
  return command;
}

// Runs the measurement and prints its JSON; returns the exit code.
int RunAccuracyCommand(const AccuracyCommand& command) {
  const evloc::Map map = evloc::LoadMap(evloc::ResolveMapFile(command.map_path));
  if (!command.image_dir.empty()) {
    const std::vector<double> distances =
        evloc::mapper::KeyframeEdgeDistances(map, command.image_dir);
    if (distances.empty())
      throw evloc::InvalidArgumentError("no map point projects into a keyframe");
    const auto quantile = [&](double q) {
      return distances[static_cast<size_t>(q * static_cast<double>(distances.size() - 1))];
    };
    const size_t within_1px = static_cast<size_t>(
        std::upper_bound(distances.begin(), distances.end(), 1.0) - distances.begin());
    nlohmann::json json;
    json["points"] = map.size();
    json["keyframes"] = map.keyframes.size();
    json["edge_projections"] = distances.size();
    json["median_edge_distance_px"] = quantile(0.5);
    json["p75_edge_distance_px"] = quantile(0.75);
    json["p90_edge_distance_px"] = quantile(0.9);
    json["within_1px_fraction"] = static_cast<double>(within_1px) / distances.size();
    std::cout << json.dump(2) << "\n";
    return 0;
  }
  const evloc::Map reference = evloc::LoadMap(command.dataset / "gt_map" / evloc::kMapFileName);
  const std::vector<DepthView> views =
      evloc::mapper::ReadDatasetDepthViews(command.dataset, command.stride);
  // Convex creases have no image-defined gradient; without the scene, every point counts.
  std::vector<bool> gradient_defined;
  std::string gradient_defined_note = "convex creases excluded";
  try {
    gradient_defined = evloc::mapper::ReferenceGradientDefined(command.dataset, reference);
  } catch (const evloc::Error& error) {
    gradient_defined_note = std::string("no edge kinds (") + error.what() + "): all points";
  }
  std::vector<evloc::mapper::PointAccuracy> per_point;
  const evloc::mapper::MapAccuracy accuracy = evloc::mapper::MeasureMapAccuracy(
      map, reference, views, command.options, command.points_csv.empty() ? nullptr : &per_point,
      gradient_defined);
  if (!command.points_csv.empty()) {
    std::ostringstream csv;
    csv.precision(7);
    csv << "x y z gx gy gz depth_error_m edge_distance_m gradient_angle_deg "
           "image_gradient_angle_deg reference_index\n";
    for (size_t i = 0; i < per_point.size(); ++i) {
      const Eigen::Vector3f& p = map.positions[i];
      const Eigen::Vector3f& g = map.gradients[i];
      const evloc::mapper::PointAccuracy& a = per_point[i];
      csv << p.x() << ' ' << p.y() << ' ' << p.z() << ' ' << g.x() << ' ' << g.y() << ' ' << g.z()
          << ' ' << a.depth_error_m << ' ' << a.edge_distance_m << ' ' << a.gradient_angle_deg
          << ' ' << a.image_gradient_angle_deg << ' ' << a.reference_index << '\n';
    }
    evloc::WriteFileAtomically(command.points_csv, csv.str());
  }
  nlohmann::json json;
  json["points"] = accuracy.num_points;
  json["reference_points"] = reference.size();
  json["depth_views"] = views.size();
  json["depth_compared_points"] = accuracy.num_depth_compared;
  json["depth_compared_in_source_view"] = accuracy.num_depth_in_source_view;
  json["median_depth_error_m"] = accuracy.median_depth_error_m;
  json["median_signed_depth_error_m"] = accuracy.median_signed_depth_error_m;
  json["depth_within_fraction"] = accuracy.depth_within_fraction;
  json["median_edge_distance_m"] = accuracy.median_edge_distance_m;
  json["edge_within_fraction"] = accuracy.edge_within_fraction;
  json["median_gradient_angle_deg"] = accuracy.median_gradient_angle_deg;
  json["gradient_within_10deg_fraction"] = accuracy.gradient_within_10deg_fraction;
  json["gradient_opposite_fraction"] = accuracy.gradient_opposite_fraction;
  json["median_image_gradient_angle_deg"] = accuracy.median_image_gradient_angle_deg;
  json["gradient_defined_points"] = accuracy.num_gradient_defined;
  json["gradient_defined_note"] = gradient_defined_note;
  json["median_gradient_angle_defined_deg"] = accuracy.median_gradient_angle_defined_deg;
  json["gradient_within_10deg_defined_fraction"] = accuracy.gradient_within_10deg_defined_fraction;
  json["gradient_opposite_defined_fraction"] = accuracy.gradient_opposite_defined_fraction;
  json["within_m"] = command.options.within_m;
  std::cout << json.dump(2) << "\n";
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  return evloc::RunCommandTool(
      "evloc-mapper-accuracy", argc, argv, ParseAccuracyCommandLine,
      [] { return evloc::HelpOfDeclaredCommandLine(&DeclareAccuracyCommandLine); },
      RunAccuracyCommand);
}
