#include "mapper/chunked_build.h"

#include <gtest/gtest.h>

#include <cmath>
#include <fstream>
#include <iostream>
#include <numeric>
#include <random>
#include <set>

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "core/common/error.h"
#include "core/common/file_util.h"
#include "core/common/test_data.h"
#include "mapper/build_command.h"
#include "mapper/pose_alignment.h"

namespace evloc::mapper {
namespace {

namespace fs = std::filesystem;

std::vector<Eigen::Vector3d> GridPositions(int columns, int rows, double spacing) {
  std::vector<Eigen::Vector3d> positions;
  for (int y = 0; y < rows; ++y) {
    for (int x = 0; x < columns; ++x) positions.emplace_back(x * spacing, y * spacing, 1.5);
  }
  return positions;
}

// The same method and chunks, core and members.
void ExpectSamePlan(const ChunkPlan& a, const ChunkPlan& b) {
  EXPECT_EQ(a.method, b.method);
  ASSERT_EQ(a.chunks.size(), b.chunks.size());
  for (size_t c = 0; c < a.chunks.size(); ++c) {
    EXPECT_EQ(a.chunks[c].core, b.chunks[c].core) << "chunk " << c;
    EXPECT_EQ(a.chunks[c].members, b.chunks[c].members) << "chunk " << c;
  }
}

TEST(ChunkedBuild, PlanByPositionCoversEveryPhotoOnceWithOverlapWithinTheDistance) {
  const std::vector<Eigen::Vector3d> positions = GridPositions(30, 20, 2.0);  // 600 photos
  ChunkingOptions options;
  options.chunk_size = 70;
  options.overlap_m = 4.0;
  const ChunkPlan plan = PlanChunks(positions.size(), &positions, options);
  EXPECT_EQ(plan.method, "position");
  // 600 halved until <= 70: 16 parts of 37 or 38.
  EXPECT_EQ(plan.chunks.size(), 16u);
  std::vector<int> owners(positions.size(), 0);
  for (const ChunkPlanEntry& chunk : plan.chunks) {
    EXPECT_LE(chunk.core.size(), options.chunk_size);
    EXPECT_GE(chunk.core.size(), 30u);
    EXPECT_TRUE(std::is_sorted(chunk.core.begin(), chunk.core.end()));
    EXPECT_TRUE(std::is_sorted(chunk.members.begin(), chunk.members.end()));
    const std::set<size_t> core(chunk.core.begin(), chunk.core.end());
    for (const size_t index : chunk.core) ++owners[index];
    size_t overlap = 0;
    for (const size_t member : chunk.members) {
      if (core.contains(member)) continue;
      ++overlap;
      double nearest = 1e9;
      for (const size_t index : chunk.core) {
        nearest = std::min(nearest, (positions[member] - positions[index]).norm());
      }
      EXPECT_LE(nearest, options.overlap_m + 1e-12);
    }
    EXPECT_GT(overlap, 0u);
    // Every photo within the distance of the core is a member.
    const std::set<size_t> members(chunk.members.begin(), chunk.members.end());
    for (size_t j = 0; j < positions.size(); ++j) {
      for (const size_t index : chunk.core) {
        if ((positions[j] - positions[index]).norm() <= options.overlap_m) {
          EXPECT_TRUE(members.contains(j)) << j;
          break;
        }
      }
    }
  }
  for (const int owner : owners) EXPECT_EQ(owner, 1);
  // Deterministic.
  ExpectSamePlan(PlanChunks(positions.size(), &positions, options), plan);
}

TEST(ChunkedBuild, PlanBySequenceAddsTheNeighbouringPhotos) {
  ChunkingOptions options;
  options.chunk_size = 10;
  options.overlap_photos = 3;
  const ChunkPlan plan = PlanChunks(25, nullptr, options);
  EXPECT_EQ(plan.method, "sequence");
  ASSERT_EQ(plan.chunks.size(), 3u);
  EXPECT_EQ(plan.chunks[0].core.front(), 0u);
  EXPECT_EQ(plan.chunks[0].core.back(), 9u);
  EXPECT_EQ(plan.chunks[0].members.front(), 0u);
  EXPECT_EQ(plan.chunks[0].members.back(), 12u);
  EXPECT_EQ(plan.chunks[1].members.front(), 7u);
  EXPECT_EQ(plan.chunks[1].members.back(), 22u);
  EXPECT_EQ(plan.chunks[2].core.size(), 5u);
  EXPECT_EQ(plan.chunks[2].members.front(), 17u);
  EXPECT_EQ(plan.chunks[2].members.back(), 24u);
}

// Global descriptors of photos at `positions` (2D): random Fourier features of the position, so
// that two photos' cosine similarity falls with their distance like exp(-d^2 / (2 sigma^2)), plus
// noise, as image retrieval's similarity falls with the distance between viewpoints.
std::vector<std::vector<float>> RetrievalDescriptorsAt(
    const std::vector<Eigen::Vector2d>& positions, double sigma, uint32_t seed) {
  std::mt19937 random(seed);
  std::normal_distribution<double> frequency(0.0, 1.0 / sigma);
  std::uniform_real_distribution<double> phase(0.0, 2 * M_PI);
  std::normal_distribution<double> noise(0.0, 0.05);
  constexpr int kFeatures = 256;
  std::vector<Eigen::Vector2d> frequencies;
  std::vector<double> phases;
  for (int k = 0; k < kFeatures; ++k) {
    frequencies.emplace_back(frequency(random), frequency(random));
    phases.push_back(phase(random));
  }
  std::vector<std::vector<float>> descriptors;
  for (const Eigen::Vector2d& position : positions) {
    std::vector<float> descriptor;
    for (int k = 0; k < kFeatures; ++k) {
      descriptor.push_back(
          static_cast<float>(std::cos(frequencies[k].dot(position) + phases[k]) + noise(random)));
    }
    descriptors.push_back(std::move(descriptor));
  }
  return descriptors;
}

TEST(ChunkedBuild, PlanByRetrievalCutsUnorderedPhotosIntoCompactLinkedChunks) {
  // 600 photos on a 30 x 20 grid (1 m apart), in a shuffled order: neither the order nor any
  // position is given, only descriptors whose similarity falls over about 1.5 m.
  std::vector<Eigen::Vector2d> grid;
  for (int y = 0; y < 20; ++y) {
    for (int x = 0; x < 30; ++x) grid.emplace_back(x, y);
  }
  std::vector<size_t> order(grid.size());
  std::iota(order.begin(), order.end(), size_t{0});
  std::shuffle(order.begin(), order.end(), std::mt19937(7));
  std::vector<Eigen::Vector2d> positions;
  for (const size_t i : order) positions.push_back(grid[i]);
  const std::vector<std::vector<float>> descriptors = RetrievalDescriptorsAt(positions, 1.5, 3);
  ChunkingOptions options;
  options.chunk_size = 80;
  options.overlap_photos = 10;
  const ChunkPlan plan = PlanChunksByRetrieval(descriptors, options);
  EXPECT_EQ(plan.method, "retrieval");
  // ceil(600 / (0.85 * 80)) = 9 seeds.
  EXPECT_EQ(plan.chunks.size(), 9u);
  std::vector<int> owners(positions.size(), 0);
  double worst_spread = 0.0;
  double mean_spread = 0.0;
  for (const ChunkPlanEntry& chunk : plan.chunks) {
    ASSERT_FALSE(chunk.core.empty());
    EXPECT_LE(chunk.core.size(), options.chunk_size);
    EXPECT_TRUE(std::is_sorted(chunk.core.begin(), chunk.core.end()));
    EXPECT_TRUE(std::is_sorted(chunk.members.begin(), chunk.members.end()));
    EXPECT_EQ(chunk.members.size(), chunk.core.size() + 2 * options.overlap_photos);
    for (const size_t index : chunk.core) ++owners[index];
    // Compact: the core's RMS distance to its centroid, against sqrt(area / 6) = 3.3 m for a
    // square of 66 photos (an ideal cut) and 10.4 m for a cut blind to the similarity (the whole
    // grid). Measured: mean 4.0 m, worst 6.1 m (a strip along the grid's edge).
    Eigen::Vector2d centroid = Eigen::Vector2d::Zero();
    for (const size_t index : chunk.core) centroid += positions[index];
    centroid /= static_cast<double>(chunk.core.size());
    double spread = 0.0;
    for (const size_t index : chunk.core) spread += (positions[index] - centroid).squaredNorm();
    spread = std::sqrt(spread / static_cast<double>(chunk.core.size()));
    worst_spread = std::max(worst_spread, spread);
    mean_spread += spread / static_cast<double>(plan.chunks.size());
    // The overlap lies beside the core: within 2.5 m of one of its photos.
    const std::set<size_t> core(chunk.core.begin(), chunk.core.end());
    for (const size_t member : chunk.members) {
      if (core.contains(member)) continue;
      double nearest = 1e9;
      for (const size_t index : chunk.core) {
        nearest = std::min(nearest, (positions[member] - positions[index]).norm());
      }
      EXPECT_LE(nearest, 2.5) << "overlap photo " << member;
    }
  }
  std::cout << "core spread: mean " << mean_spread << " m, worst " << worst_spread << " m\n";
  EXPECT_LT(mean_spread, 4.5);
  EXPECT_LT(worst_spread, 7.0);
  for (const int count : owners) EXPECT_EQ(count, 1);
  // The chunks are linked: every chunk shares at least 3 photos with another, and the links join
  // them all (what AlignChunks needs).
  std::vector<std::set<size_t>> members;
  for (const ChunkPlanEntry& chunk : plan.chunks) {
    members.emplace_back(chunk.members.begin(), chunk.members.end());
  }
  std::vector<char> reached(plan.chunks.size(), 0);
  std::vector<size_t> stack{0};
  reached[0] = 1;
  while (!stack.empty()) {
    const size_t a = stack.back();
    stack.pop_back();
    for (size_t b = 0; b < plan.chunks.size(); ++b) {
      if (reached[b]) continue;
      size_t shared = 0;
      for (const size_t photo : members[a]) shared += members[b].contains(photo) ? 1 : 0;
      if (shared >= 3) {
        reached[b] = 1;
        stack.push_back(b);
      }
    }
  }
  for (size_t c = 0; c < plan.chunks.size(); ++c) EXPECT_TRUE(reached[c]) << "chunk " << c;
  // Deterministic.
  ExpectSamePlan(PlanChunksByRetrieval(descriptors, options), plan);
}

TEST(ChunkedBuild, PlanByRetrievalRefusesBadDescriptorsAndNamesTheMethods) {
  ChunkingOptions options;
  EXPECT_THROW(PlanChunksByRetrieval({}, options), InvalidArgumentError);
  EXPECT_THROW(PlanChunksByRetrieval({{1.0f, 0.0f}, {1.0f}}, options), InvalidArgumentError);
  EXPECT_THROW(PlanChunksByRetrieval({{1.0f, std::nanf("")}}, options), InvalidArgumentError);
  options.retrieval_neighbours = 0;
  EXPECT_THROW(PlanChunksByRetrieval({{1.0f}}, options), InvalidArgumentError);
  // Fewer photos than a chunk, one without features (a zero descriptor): one chunk of all.
  options.retrieval_neighbours = 10;
  const ChunkPlan plan = PlanChunksByRetrieval({{1.0f, 0.0f}, {0.0f, 0.0f}, {0.5f, 0.5f}}, options);
  ASSERT_EQ(plan.chunks.size(), 1u);
  EXPECT_EQ(plan.chunks[0].core, (std::vector<size_t>{0, 1, 2}));
  for (const ChunkMethod method : {ChunkMethod::kAuto, ChunkMethod::kPosition,
                                   ChunkMethod::kSequence, ChunkMethod::kRetrieval}) {
    EXPECT_EQ(ParseChunkMethod(ChunkMethodName(method)), method);
  }
  EXPECT_THROW(ParseChunkMethod("vlad"), InvalidArgumentError);
}

TEST(ChunkedBuild, APlanReadsBackAndABrokenOneIsRefused) {
  ChunkingOptions options;
  options.chunk_size = 10;
  options.overlap_photos = 2;
  const ChunkPlan plan = PlanChunks(25, nullptr, options);
  std::vector<std::string> names;
  for (int i = 0; i < 25; ++i) names.push_back("folder/photo " + std::to_string(i) + ".png");
  const std::string text = ChunkPlanToJson(plan, names, "0a1b2c3d");
  const StoredChunkPlan stored = ParseChunkPlan(text, names, "plan.json");
  EXPECT_EQ(stored.inputs, "0a1b2c3d");
  ExpectSamePlan(stored.plan, plan);
  const auto refused = [&](const std::string& broken, const std::string& message) {
    try {
      ParseChunkPlan(broken, names, "ws/plan.json");
      ADD_FAILURE() << "accepted: " << broken.substr(0, 80);
    } catch (const ParseError& error) {
      EXPECT_NE(std::string(error.what()).find("ws/plan.json"), std::string::npos);
      EXPECT_NE(std::string(error.what()).find(message), std::string::npos) << error.what();
    }
  };
  refused(text.substr(0, text.size() / 2), "not JSON");
  refused("[]", "expected an object");
  refused(R"({"method":4e+44444444444444444444444444446444})", "not JSON");  // the fuzzer's find
  // Another photo set: a name that is not an input, a photo left out.
  std::vector<std::string> fewer(names.begin(), names.end() - 1);
  EXPECT_THROW(ParseChunkPlan(text, fewer, "plan.json"), ParseError);
  std::vector<std::string> more = names;
  more.push_back("new.png");
  try {
    ParseChunkPlan(text, more, "plan.json");
    ADD_FAILURE() << "accepted a plan without new.png";
  } catch (const ParseError& error) {
    EXPECT_NE(std::string(error.what()).find("new.png is in no chunk's core"), std::string::npos);
  }
  // A photo in two cores; a core photo that is not a member; an empty core.
  ChunkPlan twice = plan;
  twice.chunks[1].core.insert(twice.chunks[1].core.begin(), 0);
  twice.chunks[1].members.insert(twice.chunks[1].members.begin(), 0);
  refused(ChunkPlanToJson(twice, names, "x"), "in two chunks' cores");
  ChunkPlan outside = plan;
  outside.chunks[0].members.pop_back();
  outside.chunks[0].members.pop_back();
  outside.chunks[0].members.pop_back();
  refused(ChunkPlanToJson(outside, names, "x"), "a core photo is not a member");
  refused(R"({"method":"retrieval","inputs":"x","chunks":[{"core":[],"members":[]}]})",
          "has no core photo");
  refused(R"({"method":"retrieval","inputs":"x","chunks":[{"core":[1],"members":[]}]})",
          "holds a non-string");
}

TEST(ChunkedBuild, PlanRefusesBadInput) {
  ChunkingOptions options;
  EXPECT_THROW(PlanChunks(0, nullptr, options), InvalidArgumentError);
  options.chunk_size = 4;
  EXPECT_THROW(PlanChunks(10, nullptr, options), InvalidArgumentError);
  options.chunk_size = 10;
  options.overlap_m = -1;
  EXPECT_THROW(PlanChunks(10, nullptr, options), InvalidArgumentError);
  options.overlap_m = 1;
  std::vector<Eigen::Vector3d> positions(9, Eigen::Vector3d::Zero());
  EXPECT_THROW(PlanChunks(10, &positions, options), InvalidArgumentError);
  positions.resize(10, Eigen::Vector3d::Zero());
  positions[3].x() = std::nan("");
  EXPECT_THROW(PlanChunks(10, &positions, options), InvalidArgumentError);
}

// A camera path along a curve, world_from_cam, looking sideways.
std::vector<Rigid3d> CurvedPath(size_t count) {
  std::vector<Rigid3d> poses;
  for (size_t i = 0; i < count; ++i) {
    const double s = static_cast<double>(i) * 0.5;
    Rigid3d pose;
    pose.translation = Eigen::Vector3d(s, 0.02 * s * s, 1.5 + 0.3 * std::sin(0.1 * s));
    pose.rotation = Eigen::AngleAxisd(0.02 * s, Eigen::Vector3d::UnitZ()) *
                    Eigen::AngleAxisd(-M_PI / 2, Eigen::Vector3d::UnitX());
    poses.push_back(pose);
  }
  return poses;
}

Sim3d RandomSim(std::mt19937* random) {
  std::uniform_real_distribution<double> angle(-M_PI, M_PI);
  std::uniform_real_distribution<double> offset(-20, 20);
  std::uniform_real_distribution<double> log_scale(-1.0, 1.0);
  Sim3d sim;
  sim.rotation = Eigen::AngleAxisd(angle(*random), Eigen::Vector3d(0.3, -0.5, 1).normalized());
  sim.translation = Eigen::Vector3d(offset(*random), offset(*random), offset(*random));
  sim.scale = std::exp(log_scale(*random));
  return sim;
}

TEST(ChunkedBuild, AlignChunksRecoversTheChunksFramesFromSharedPhotos) {
  const std::vector<Rigid3d> truth = CurvedPath(200);
  std::mt19937 random(7);
  std::normal_distribution<double> noise(0.0, 0.01);  // 1 cm, 0.01 rad scale of the noise
  // Five chunks of 40 photos each with 8 photos of overlap on either side, each in its own frame.
  std::vector<std::map<std::string, Rigid3d>> chunks;
  std::vector<Sim3d> chunk_from_world;
  for (size_t c = 0; c < 5; ++c) {
    chunk_from_world.push_back(RandomSim(&random));
    std::map<std::string, Rigid3d> poses;
    const size_t begin = c * 40 >= 8 ? c * 40 - 8 : 0;
    const size_t end = std::min<size_t>(200, c * 40 + 48);
    for (size_t i = begin; i < end; ++i) {
      Rigid3d noisy = truth[i];
      noisy.translation += Eigen::Vector3d(noise(random), noise(random), noise(random));
      noisy.rotation = noisy.rotation *
                       ExpSO3(0.1 * Eigen::Vector3d(noise(random), noise(random), noise(random)));
      poses["photo_" + std::to_string(i)] = chunk_from_world[c].TransformPose(noisy);
    }
    chunks.push_back(std::move(poses));
  }
  const ChunkAlignment alignment = AlignChunks(chunks);
  EXPECT_EQ(alignment.num_linked_pairs, 4u);
  EXPECT_GT(alignment.num_shared_observations, 50u);
  // The common frame is chunk 0's: align the merged centres to the truth and measure.
  std::vector<Rigid3d> merged;
  std::vector<Rigid3d> reference;
  for (size_t c = 0; c < chunks.size(); ++c) {
    for (size_t i = c * 40; i < c * 40 + 40; ++i) {
      merged.push_back(
          alignment.common_from_chunk[c].TransformPose(chunks[c].at("photo_" + std::to_string(i))));
      reference.push_back(truth[i]);
    }
  }
  const PoseAlignment to_truth = AlignPoses(merged, reference);
  // The noise is 1 cm per axis (1.7 cm per centre): the merged centres stay within it, with no
  // drift along the five chunks.
  EXPECT_LT(to_truth.centre_rms, 0.025);
  EXPECT_LT(to_truth.centre_max, 0.08);
  EXPECT_LT(alignment.adjusted_rms, 0.04);
  EXPECT_LE(alignment.adjusted_rms, alignment.initial_rms + 1e-9);
}

TEST(ChunkedBuild, AChunkThatDoesNotFitTheReferenceOnItsOwnIsFound) {
  const std::vector<Rigid3d> truth = CurvedPath(90);
  std::mt19937 random(5);
  std::map<std::string, Rigid3d> reference;
  for (size_t i = 0; i < truth.size(); ++i) reference["photo_" + std::to_string(i)] = truth[i];
  // Three chunks of 30 photos, each in its own frame; chunk 1 is a wrong reconstruction (its
  // second half folded back onto its first, as a repeated structure folds a COLMAP model);
  // chunk 2 has only 2 photos with a reference pose.
  std::vector<std::map<std::string, Rigid3d>> chunks(3);
  for (size_t c = 0; c < 3; ++c) {
    const Sim3d frame = RandomSim(&random);
    for (size_t i = c * 30; i < c * 30 + 30; ++i) {
      Rigid3d pose = truth[i];
      if (c == 1 && i >= 45) pose = truth[90 - i];
      chunks[c]["photo_" + std::to_string(i)] = frame.TransformPose(pose);
    }
  }
  std::map<std::string, Rigid3d> few = reference;
  for (size_t i = 62; i < 90; ++i) few.erase("photo_" + std::to_string(i));
  const std::vector<ChunkReferenceFit> fits = FitChunksToReference(chunks, few, AlignmentLimits());
  ASSERT_EQ(fits.size(), 3u);
  EXPECT_TRUE(fits[0].fits);
  EXPECT_LT(fits[0].centre_rms, 1e-6);
  EXPECT_FALSE(fits[1].fits);
  EXPECT_GT(fits[1].centre_rms, 1.0);
  EXPECT_FALSE(fits[2].fits);
  EXPECT_TRUE(std::isnan(fits[2].centre_rms));
  // With every reference pose, chunk 2 fits.
  EXPECT_TRUE(FitChunksToReference(chunks, reference, AlignmentLimits())[2].fits);
}

TEST(ChunkedBuild, AlignChunksNamesAChunkWithoutSharedPhotos) {
  const std::vector<Rigid3d> truth = CurvedPath(30);
  std::vector<std::map<std::string, Rigid3d>> chunks(3);
  for (size_t i = 0; i < 30; ++i) {
    const std::string name = "photo_" + std::to_string(i);
    if (i < 12) chunks[0][name] = truth[i];
    if (i >= 9 && i < 20) chunks[1][name] = truth[i];
    if (i >= 21) chunks[2][name] = truth[i];
  }
  try {
    AlignChunks(chunks);
    FAIL() << "expected an error";
  } catch (const InvalidArgumentError& error) {
    EXPECT_NE(std::string(error.what()).find("chunks 2 share fewer than 3"), std::string::npos)
        << error.what();
  }
}

TEST(ChunkedBuild, ChunkResultReadsBackAndRefusesBrokenFolders) {
  const fs::path directory = evloc::testing::MakeTempDir("chunk_result");
  Map map;
  Camera camera;
  camera.model = CameraModel::kPinhole;
  camera.width = 64;
  camera.height = 48;
  camera.fx = camera.fy = 50;
  camera.cx = 31.5;
  camera.cy = 23.5;
  map.cameras.push_back(camera);
  Keyframe keyframe;
  keyframe.image_name = "a.png";
  keyframe.visible_points = {0};
  map.keyframes.push_back(keyframe);
  map.AddPoint(Eigen::Vector3f(0, 0, 2), Eigen::Vector3f(1, 0, 0), 0.01f, 0.5f, 0);
  SaveMap(directory / "map.evmap", map);
  WriteFileAtomically(directory / "poses.txt",
                      "# comment\na.png 0 0 0 0 0 0 1\nb.png 1 2 3 0 0 0.7071067811865476 "
                      "0.7071067811865476\n");
  // Without inputs.txt the chunk is not finished.
  EXPECT_THROW(ReadChunkResult(directory), ParseError);
  WriteFileAtomically(directory / "inputs.txt", "0123abcd\n");
  const ChunkResult result = ReadChunkResult(directory);
  EXPECT_EQ(result.inputs_fingerprint, "0123abcd");
  ASSERT_EQ(result.world_from_cams.size(), 2u);
  EXPECT_NEAR(result.world_from_cams.at("b.png").translation.z(), 3.0, 1e-12);
  EXPECT_EQ(result.map.size(), 1u);
  // A pose line with a bad quaternion, a missing pose of a keyframe, a duplicated name.
  for (const std::string& poses :
       {std::string("a.png 0 0 0 0 0 0 2\n"), std::string("b.png 0 0 0 0 0 0 1\n"),
        std::string("a.png 0 0 0 0 0 0 1\na.png 0 0 0 0 0 0 1\n"), std::string("a.png 0 0\n")}) {
    WriteFileAtomically(directory / "poses.txt", poses);
    EXPECT_THROW(ReadChunkResult(directory), ParseError) << poses;
  }
}

TEST(ChunkedBuild, MemoryModelGrowsWithPhotosAndPixels) {
  EXPECT_LT(EstimatedChunkPeakBytes(100, 640, 480), EstimatedChunkPeakBytes(200, 640, 480));
  EXPECT_LT(EstimatedChunkPeakBytes(100, 240, 180), EstimatedChunkPeakBytes(100, 640, 480));
}

// Photos with known poses along a line, for the checks that come before any reconstruction.
fs::path WriteSmallPhotoSet(const fs::path& directory, size_t count) {
  fs::create_directories(directory / "images");
  std::ofstream poses(directory / "poses.txt");
  for (size_t i = 0; i < count; ++i) {
    cv::Mat image(48, 64, CV_8U, cv::Scalar(0));
    cv::circle(image, cv::Point(10 + static_cast<int>(i % 40), 24), 6, cv::Scalar(200), cv::FILLED);
    const std::string name = "photo_" + std::to_string(1000 + i) + ".png";
    EXPECT_TRUE(cv::imwrite((directory / "images" / name).string(), image));
    poses << name << " " << i * 0.5 << " 0 1.5 0 0 0 1\n";
  }
  return directory;
}

TEST(ChunkedBuild, AChunkBeyondTheMemoryBudgetIsRefusedBeforeAnyWork) {
  const fs::path directory = WriteSmallPhotoSet(evloc::testing::MakeTempDir("chunk_budget"), 40);
  const BuildCommandLine command_line = ParseBuildCommandLine(
      {"build", "--images", (directory / "images").string(), "--out", (directory / "site").string(),
       "--camera", "pinhole:50,50,31.5,23.5", "--known-poses", (directory / "poses.txt").string(),
       "--chunked", "--chunk-size", "20", "--memory-budget", "100M"});
  ASSERT_TRUE(command_line.chunked);
  try {
    BuildChunkedSite(command_line.chunked_options);
    FAIL() << "expected an error";
  } catch (const InvalidArgumentError& error) {
    const std::string message = error.what();
    EXPECT_NE(message.find("more than --memory-budget"), std::string::npos) << message;
    EXPECT_NE(message.find("--chunk-size"), std::string::npos) << message;
  }
  EXPECT_FALSE(fs::exists(directory / "site"));
  EXPECT_FALSE(fs::exists(directory / "site.chunks"));
}

TEST(ChunkedBuild, FlagsAndTheirChecks) {
  const fs::path directory = WriteSmallPhotoSet(evloc::testing::MakeTempDir("chunk_flags"), 10);
  const std::vector<std::string> base = {"build",
                                         "--images",
                                         (directory / "images").string(),
                                         "--out",
                                         (directory / "site").string(),
                                         "--camera",
                                         "pinhole:50,50,31.5,23.5"};
  auto with = [&](std::vector<std::string> extra) {
    std::vector<std::string> arguments = base;
    arguments.insert(arguments.end(), extra.begin(), extra.end());
    return arguments;
  };
  const BuildCommandLine plain = ParseBuildCommandLine(base);
  EXPECT_FALSE(plain.chunked);  // 10 photos: not chunked unless asked
  const BuildCommandLine parsed = ParseBuildCommandLine(
      with({"--chunked", "--chunk-size", "120", "--chunk-overlap", "7.5", "--workers", "3",
            "--memory-budget", "6G", "--tile-size", "40", "--tile-overlap", "5",
            "--chunk-workspace", (directory / "ws").string()}));
  EXPECT_TRUE(parsed.chunked);
  EXPECT_EQ(parsed.chunked_options.chunking.chunk_size, 120u);
  EXPECT_DOUBLE_EQ(parsed.chunked_options.chunking.overlap_m, 7.5);
  EXPECT_EQ(parsed.chunked_options.workers, 3);
  EXPECT_EQ(*parsed.chunked_options.memory_budget_bytes, 6ull << 30);
  EXPECT_DOUBLE_EQ(parsed.chunked_options.tile_size_m, 40.0);
  EXPECT_EQ(parsed.chunked_options.build.image_dir, directory / "images");
  EXPECT_TRUE(ParseBuildCommandLine(with({"--chunk-index", "2"})).chunked);
  EXPECT_TRUE(ParseBuildCommandLine(with({"--merge-only"})).chunked_options.merge_only);
  EXPECT_THROW(ParseBuildCommandLine(with({"--chunked", "--workers", "0"})), InvalidArgumentError);
  EXPECT_THROW(ParseBuildCommandLine(with({"--chunked", "--chunk-size", "3"})),
               InvalidArgumentError);
  EXPECT_THROW(ParseBuildCommandLine(with({"--chunk-index", "1", "--merge-only"})),
               InvalidArgumentError);
  EXPECT_THROW(ParseBuildCommandLine(with({"--chunked", "--tile-overlap", "60"})),
               InvalidArgumentError);
  EXPECT_THROW(ParseBuildCommandLine(with({"--chunked", "--memory-budget", "lots"})),
               InvalidArgumentError);
}

}  // namespace
}  // namespace evloc::mapper
