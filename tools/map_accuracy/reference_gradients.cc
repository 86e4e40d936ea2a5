#include "tools/map_accuracy/reference_gradients.h"

#include <string>

#include <nlohmann/json.hpp>

#include "core/common/error.h"
#include "core/common/file_util.h"
#include "tools/sim/ground_truth_map.h"
#include "tools/sim/scene.h"

namespace evloc::mapper {

std::vector<bool> ReferenceGradientDefined(const std::filesystem::path& dataset,
                                           const Map& reference) {
  const std::filesystem::path info_path = dataset / "info.json";
  nlohmann::json info;
  try {
    info = nlohmann::json::parse(ReadFileToString(info_path));
  } catch (const nlohmann::json::exception& error) {
    throw ParseError(info_path.string(), "JSON", error.what());
  }
  const std::string scene_name = info.value("/options/scene"_json_pointer, std::string());
  const sim::Scene scene = scene_name.empty() || scene_name == "default room"
                               ? sim::MakeDefaultRoom()
                               : sim::LoadSceneJson(scene_name);
  const std::vector<sim::GroundTruthEdgePoint> edges =
      sim::SampleGroundTruthEdges(scene, sim::GroundTruthMapOptions());
  if (edges.size() != reference.size()) {
    throw InvalidArgumentError("the scene of " + info_path.string() + " gives " +
                               std::to_string(edges.size()) + " edge points, the gt_map has " +
                               std::to_string(reference.size()));
  }
  std::vector<bool> defined(edges.size());
  for (size_t i = 0; i < edges.size(); ++i) {
    if ((edges[i].position - reference.positions[i].cast<double>()).norm() > 1e-4) {
      throw InvalidArgumentError("edge point " + std::to_string(i) + " of the scene of " +
                                 info_path.string() + " differs from the gt_map's");
    }
    defined[i] = edges[i].kind != sim::EdgeKind::kConvexCrease;
  }
  return defined;
}

}  // namespace evloc::mapper
