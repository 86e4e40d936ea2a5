#include "maps/ply.h"

#include <gtest/gtest.h>

#include <cstring>
#include <sstream>
#include <string>

#include "core/common/file_util.h"
#include "core/common/test_data.h"
#include "maps/synthetic_map.h"

namespace evloc {
namespace {

TEST(Ply, BinaryFileReadsBackExactly) {
  const std::filesystem::path directory = testing::MakeTempDir("ply_test");
  CorridorMapOptions options;
  options.num_points = 70000;  // more than one write chunk
  options.num_keyframes = 0;
  const Map map = MakeCorridorMap(options);
  const std::filesystem::path path = directory / "map.ply";
  WritePly(path, map);

  const std::string content = ReadFileToString(path);
  const std::string end_marker = "end_header\n";
  const size_t header_end = content.find(end_marker);
  ASSERT_NE(header_end, std::string::npos);
  std::istringstream header(content.substr(0, header_end));
  std::string line;
  std::vector<std::string> lines;
  while (std::getline(header, line)) lines.push_back(line);
  ASSERT_GE(lines.size(), 9u);
  EXPECT_EQ(lines[0], "ply");
  EXPECT_EQ(lines[1], "format binary_little_endian 1.0");
  std::vector<std::string> properties;
  size_t vertex_count = 0;
  for (const std::string& header_line : lines) {
    if (header_line.rfind("element vertex ", 0) == 0) {
      vertex_count = std::stoul(header_line.substr(15));
    } else if (header_line.rfind("property ", 0) == 0) {
      properties.push_back(header_line);
    }
  }
  EXPECT_EQ(vertex_count, map.size());
  EXPECT_EQ(properties, (std::vector<std::string>{"property float x", "property float y",
                                                  "property float z", "property float nx",
                                                  "property float ny", "property float nz"}));
  const size_t data_begin = header_end + end_marker.size();
  ASSERT_EQ(content.size() - data_begin, map.size() * 6 * sizeof(float));
  for (size_t i = 0; i < map.size(); ++i) {
    float values[6];
    std::memcpy(values, content.data() + data_begin + i * sizeof(values), sizeof(values));
    ASSERT_EQ(Eigen::Vector3f(values[0], values[1], values[2]), map.positions[i]) << i;
    ASSERT_EQ(Eigen::Vector3f(values[3], values[4], values[5]), map.gradients[i]) << i;
  }
  std::filesystem::remove_all(directory);
}

}  // namespace
}  // namespace evloc
