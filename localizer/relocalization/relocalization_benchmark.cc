// Timings of the relocalization building blocks (figures in docs/relocalization.md):
//   taskset -c 1 build/localizer/relocalization/evloc_relocalization_benchmark
//     --benchmark_repetitions=5 --benchmark_report_aggregates_only=true   (one command line)
#include <benchmark/benchmark.h>

#include <vector>

#include <opencv2/core.hpp>

#include "core/features/features.h"
#include "core/features/testing/synthetic_images.h"
#include "core/features/vocabulary.h"
#include "localizer/relocalization/absolute_pose.h"
#include "localizer/relocalization/synthetic_scene_test_util.h"

namespace evloc::relocalization {
namespace {

// One absolute pose: state.range(0) correspondences, 0.5 px noise, 30 % outliers; with the
// refinement and covariance when state.range(1) is 1, the RANSAC alone when 0.
void BM_EstimateAbsolutePose(benchmark::State& state) {
  const Camera camera = testing::DistortedCamera();
  const testing::Scene scene =
      testing::MakeScene(camera, static_cast<int>(state.range(0)), 0.5, 0.3, 1);
  AbsolutePoseOptions options;
  options.refine = state.range(1) == 1;
  for (auto _ : state) {
    AbsolutePoseResult result =
        EstimateAbsolutePose(camera, scene.pixels, scene.points_in_world, options);
    benchmark::DoNotOptimize(result);
  }
}
BENCHMARK(BM_EstimateAbsolutePose)
    ->Args({200, 1})
    ->Args({1000, 1})
    ->Args({200, 0})
    ->Args({1000, 0})
    ->Unit(benchmark::kMillisecond);

// SIFT on a 640 x 480 synthetic texture, 2000 keypoints kept.
void BM_ExtractFeatures(benchmark::State& state) {
  const cv::Mat image = features::testing::SyntheticTexture(640, 480, 1, 600);
  for (auto _ : state) {
    features::Features features = features::ExtractFeatures(image, features::FeatureOptions());
    benchmark::DoNotOptimize(features);
  }
  state.counters["keypoints"] = features::ExtractFeatures(image, features::FeatureOptions()).size();
}
BENCHMARK(BM_ExtractFeatures)->Unit(benchmark::kMillisecond);

// Mutual ratio-test matching of two such images' features.
void BM_MatchFeatures(benchmark::State& state) {
  const cv::Mat image = features::testing::SyntheticTexture(640, 480, 1, 600);
  const features::Features a = features::ExtractFeatures(image, features::FeatureOptions());
  const features::Features b = features::ExtractFeatures(
      features::testing::Warp(
          image, features::testing::SmallHomography(image.size(), 5, 1.05, 3, 2), 2.0, 1),
      features::FeatureOptions());
  for (auto _ : state) {
    std::vector<features::FeatureMatch> matches =
        features::MatchFeatures(a, b, features::MatchOptions());
    benchmark::DoNotOptimize(matches);
  }
}
BENCHMARK(BM_MatchFeatures)->Unit(benchmark::kMillisecond);

// Random descriptors in the value range of root-SIFT rows.
cv::Mat RandomDescriptors(int count) {
  cv::Mat descriptors(count, features::kDescriptorSize, CV_32F);
  cv::RNG rng(3);
  rng.fill(descriptors, cv::RNG::UNIFORM, 0, 60);
  return descriptors;
}

// k-means of state.range(0) descriptors into the default 32 words (a map's one-off cost).
void BM_TrainVocabulary(benchmark::State& state) {
  const cv::Mat descriptors = RandomDescriptors(static_cast<int>(state.range(0)));
  for (auto _ : state) {
    features::Vocabulary vocabulary =
        features::Vocabulary::Train(descriptors, features::VocabularyOptions());
    benchmark::DoNotOptimize(vocabulary);
  }
}
BENCHMARK(BM_TrainVocabulary)->Arg(50000)->Unit(benchmark::kMillisecond)->Iterations(1);

// VLAD of one image's 2000 descriptors.
void BM_EncodeVlad(benchmark::State& state) {
  const features::Vocabulary vocabulary =
      features::Vocabulary::Train(RandomDescriptors(5000), features::VocabularyOptions());
  const cv::Mat descriptors = RandomDescriptors(2000);
  for (auto _ : state) {
    std::vector<float> vlad = vocabulary.EncodeVlad(descriptors);
    benchmark::DoNotOptimize(vlad);
  }
  state.counters["vlad_bytes"] = vocabulary.vlad_size() * sizeof(float);
}
BENCHMARK(BM_EncodeVlad)->Unit(benchmark::kMillisecond);

// Top-5 retrieval among state.range(0) keyframes' VLAD vectors.
void BM_Retrieve(benchmark::State& state) {
  const features::Vocabulary vocabulary =
      features::Vocabulary::Train(RandomDescriptors(5000), features::VocabularyOptions());
  std::vector<std::vector<float>> database;
  cv::RNG rng(4);
  for (int i = 0; i < state.range(0); ++i) {
    cv::Mat descriptors(200, features::kDescriptorSize, CV_32F);
    rng.fill(descriptors, cv::RNG::UNIFORM, 0, 60);
    database.push_back(vocabulary.EncodeVlad(descriptors));
  }
  const std::vector<float> query = database.front();
  for (auto _ : state) {
    std::vector<features::RetrievalHit> hits = features::Retrieve(query, database, 5);
    benchmark::DoNotOptimize(hits);
  }
}
BENCHMARK(BM_Retrieve)->Arg(300)->Arg(1000)->Unit(benchmark::kMicrosecond);

}  // namespace
}  // namespace evloc::relocalization

BENCHMARK_MAIN();
