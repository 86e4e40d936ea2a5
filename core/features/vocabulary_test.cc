#include "core/features/vocabulary.h"

#include <algorithm>
#include <cmath>
#include <numeric>
#include <string>
#include <vector>

#include <gtest/gtest.h>
#include <opencv2/core.hpp>

#include "core/common/error.h"
#include "core/common/test_data.h"
#include "core/dataset/testing/middlebury.h"
#include "core/features/testing/synthetic_images.h"

namespace evloc::features {
namespace {

using testing::SmallHomography;
using testing::SyntheticTexture;
using testing::Warp;

// Random descriptors around `clusters` well separated centres (a stand-in for real descriptors).
cv::Mat ClusteredDescriptors(int clusters, int per_cluster, uint64_t seed) {
  cv::RNG rng(seed);
  cv::Mat centres(clusters, kDescriptorSize, CV_32F);
  rng.fill(centres, cv::RNG::UNIFORM, 0, 100);
  cv::Mat descriptors(clusters * per_cluster, kDescriptorSize, CV_32F);
  rng.fill(descriptors, cv::RNG::NORMAL, 0, 3);
  for (int i = 0; i < descriptors.rows; ++i) descriptors.row(i) += centres.row(i % clusters);
  return descriptors;
}

TEST(RelocVocabulary, TrainingIsDeterministicAndLeavesTheThreadRngAlone) {
  const cv::Mat descriptors = ClusteredDescriptors(16, 50, 1);
  VocabularyOptions options;
  options.num_words = 16;
  cv::theRNG().state = 12345;
  const Vocabulary a = Vocabulary::Train(descriptors, options);
  EXPECT_EQ(cv::theRNG().state, 12345u);
  const Vocabulary b = Vocabulary::Train(descriptors, options);
  EXPECT_EQ(a.ToVector(), b.ToVector());
  EXPECT_EQ(a.num_words(), 16);
  EXPECT_EQ(a.dimension(), kDescriptorSize);
  // Well separated clusters: every cluster gets its own word.
  const std::vector<int> words = a.Assign(descriptors);
  for (int cluster = 0; cluster < 16; ++cluster) {
    for (int i = cluster; i < descriptors.rows; i += 16) EXPECT_EQ(words[i], words[cluster]);
  }
  std::vector<int> first_words(words.begin(), words.begin() + 16);
  std::sort(first_words.begin(), first_words.end());
  EXPECT_EQ(std::unique(first_words.begin(), first_words.end()), first_words.end());
}

TEST(RelocVocabulary, VladIsUnitLengthAndSurvivesSerialisation) {
  const cv::Mat descriptors = ClusteredDescriptors(8, 40, 2);
  VocabularyOptions options;
  options.num_words = 8;
  const Vocabulary vocabulary = Vocabulary::Train(descriptors, options);
  const std::vector<float> vlad = vocabulary.EncodeVlad(descriptors.rowRange(0, 100));
  ASSERT_EQ(static_cast<int>(vlad.size()), vocabulary.vlad_size());
  EXPECT_EQ(vocabulary.vlad_size(), 8 * kDescriptorSize);
  double squared = 0;
  for (const float value : vlad) squared += value * value;
  EXPECT_NEAR(squared, 1.0, 1e-5);

  const Vocabulary restored = Vocabulary::FromVector(8, kDescriptorSize, vocabulary.ToVector());
  EXPECT_EQ(restored.EncodeVlad(descriptors.rowRange(0, 100)), vlad);
  // No descriptors: the zero vector, similar to nothing.
  const std::vector<float> empty = vocabulary.EncodeVlad(cv::Mat());
  EXPECT_EQ(empty, std::vector<float>(vlad.size(), 0.0f));
  EXPECT_EQ(CosineSimilarity(empty, vlad), 0.0f);
  EXPECT_NEAR(CosineSimilarity(vlad, vlad), 1.0f, 1e-6);
}

TEST(RelocVocabulary, ThrowsOnProgrammerErrors) {
  VocabularyOptions options;
  options.num_words = 0;
  EXPECT_THROW(options.Check(), InvalidArgumentError);
  options = VocabularyOptions();
  EXPECT_THROW(Vocabulary::Train(ClusteredDescriptors(2, 5, 3), options), InvalidArgumentError);
  EXPECT_THROW(Vocabulary::FromVector(2, 3, std::vector<float>(5)), InvalidArgumentError);
  EXPECT_THROW(Vocabulary::FromVector(1, 2, {1.0f, NAN}), InvalidArgumentError);
  EXPECT_THROW(Vocabulary().EncodeVlad(ClusteredDescriptors(1, 1, 4)), InvalidArgumentError);
  const Vocabulary small = Vocabulary::FromVector(1, 2, {1.0f, 2.0f});
  EXPECT_THROW(small.EncodeVlad(ClusteredDescriptors(1, 1, 4)), InvalidArgumentError);
  EXPECT_THROW(Retrieve({1.0f}, {{1.0f}}, 0), InvalidArgumentError);
  EXPECT_THROW(Retrieve({1.0f}, {{1.0f, 2.0f}}, 1), InvalidArgumentError);
}

TEST(RelocVocabulary, RetrieveRanksByCosineSimilarity) {
  const std::vector<std::vector<float>> database = {
      {1, 0, 0}, {0, 1, 0}, {0.8f, 0.6f, 0}, {0, 0, 0}, {0.8f, 0.6f, 0}};
  const std::vector<RetrievalHit> hits = Retrieve({2, 1, 0}, database, 3);
  ASSERT_EQ(hits.size(), 3u);
  EXPECT_EQ(hits[0].index, 2);  // Ties keep the lower index first.
  EXPECT_EQ(hits[1].index, 4);
  EXPECT_EQ(hits[2].index, 0);
  EXPECT_NEAR(hits[0].similarity, 2.2 / std::sqrt(5.0), 1e-6);
  EXPECT_EQ(Retrieve({2, 1, 0}, database, 10).size(), database.size());
}

TEST(RelocVocabulary, CosineSimilaritiesAndMostSimilar) {
  const std::vector<std::vector<float>> vectors = {
      {1, 0, 0}, {0, 2, 0}, {0.8f, 0.6f, 0}, {0, 0, 0}, {0.8f, 0.6f, 0}};
  const Eigen::MatrixXf similarity = CosineSimilarities(vectors);
  ASSERT_EQ(similarity.rows(), 5);
  for (int i = 0; i < 5; ++i) {
    for (int j = 0; j < 5; ++j) {
      EXPECT_NEAR(similarity(i, j), CosineSimilarity(vectors[i], vectors[j]), 1e-6) << i << j;
    }
  }
  const std::vector<std::vector<size_t>> nearest = MostSimilar(similarity, 2);
  ASSERT_EQ(nearest.size(), 5u);
  EXPECT_EQ(nearest[0], (std::vector<size_t>{2, 4}));  // ties: the lower index first
  EXPECT_EQ(nearest[2], (std::vector<size_t>{4, 0}));
  EXPECT_EQ(nearest[3], (std::vector<size_t>{0, 1}));  // a zero vector: all 0, by index
  EXPECT_EQ(MostSimilar(similarity, 10)[1].size(), 4u);
  EXPECT_TRUE(MostSimilar(CosineSimilarities({}), 3).empty());
  EXPECT_THROW(CosineSimilarities({{1, 0}, {1}}), InvalidArgumentError);
  EXPECT_THROW(CosineSimilarities({{1, std::nanf("")}}), InvalidArgumentError);
}

// Features of every image.
std::vector<Features> ExtractAll(const std::vector<cv::Mat>& images) {
  std::vector<Features> features;
  for (const cv::Mat& image : images) features.push_back(ExtractFeatures(image, FeatureOptions()));
  return features;
}

// A vocabulary trained on the images' features, and the images' VLAD vectors.
std::pair<Vocabulary, std::vector<std::vector<float>>> BuildDatabase(
    const std::vector<cv::Mat>& images) {
  const std::vector<Features> features = ExtractAll(images);
  const Vocabulary vocabulary = Vocabulary::Train(features, VocabularyOptions());
  std::vector<std::vector<float>> database;
  for (const Features& image_features : features) {
    database.push_back(vocabulary.EncodeVlad(image_features));
  }
  return {vocabulary, database};
}

TEST(RelocVocabulary, SyntheticPlacesRetrieveThemselvesFromWarpedViews) {
  // Eight "places" (textures), each seen again through a homography with noise.
  constexpr int kPlaces = 8;
  std::vector<cv::Mat> database_images, query_images;
  for (int place = 0; place < kPlaces; ++place) {
    database_images.push_back(SyntheticTexture(480, 360, 100 + place));
    query_images.push_back(Warp(database_images.back(),
                                SmallHomography(database_images.back().size(), 8.0 * (place - 4),
                                                0.9 + 0.03 * place, 10, -6),
                                2.0, place));
  }
  const auto [vocabulary, database] = BuildDatabase(database_images);
  for (int place = 0; place < kPlaces; ++place) {
    const std::vector<RetrievalHit> hits = Retrieve(
        vocabulary.EncodeVlad(ExtractFeatures(query_images[place], FeatureOptions())), database, 2);
    // Measured: 0.42-0.52 for the place itself, at most 0.07 for any other.
    EXPECT_EQ(hits[0].index, place);
    EXPECT_GT(hits[0].similarity, hits[1].similarity + 0.2) << "place " << place;
  }
}

float Mean(const std::vector<float>& values) {
  return std::accumulate(values.begin(), values.end(), 0.0f) / values.size();
}

// Camera centre of a Middlebury view, world coordinates.
Eigen::Vector3d Centre(const evloc::testing::MiddleburyView& view) {
  return view.cam_from_world.Inverse().translation;
}

TEST(RelocVocabulary, HeldOutTempleViewsRetrieveANeighbourAndOutscoreAnotherScene) {
  EVLOC_REQUIRE_SHARED_DATA(parameters, "middlebury/templeSparseRing/templeSR_par.txt");
  const auto views = evloc::testing::ReadMiddleburyParameters(parameters);
  ASSERT_EQ(views.size(), 16u);
  // The map: every second view; the queries: the views in between.
  std::vector<int> database_views, query_views;
  for (int i = 0; i < 16; ++i) (i % 2 == 0 ? database_views : query_views).push_back(i);
  std::vector<cv::Mat> database_images;
  for (const int i : database_views) {
    database_images.push_back(testing::ReadGrey(parameters.parent_path() / views[i].name));
  }
  const auto [vocabulary, database] = BuildDatabase(database_images);
  std::vector<float> best_temple_similarities;
  for (const int query : query_views) {
    // The two map views nearest to the query's camera centre are its neighbours.
    std::vector<int> by_distance(database_views.size());
    std::iota(by_distance.begin(), by_distance.end(), 0);
    std::sort(by_distance.begin(), by_distance.end(), [&](int a, int b) {
      return (Centre(views[database_views[a]]) - Centre(views[query])).norm() <
             (Centre(views[database_views[b]]) - Centre(views[query])).norm();
    });
    const cv::Mat image = testing::ReadGrey(parameters.parent_path() / views[query].name);
    const std::vector<RetrievalHit> hits =
        Retrieve(vocabulary.EncodeVlad(ExtractFeatures(image, FeatureOptions())), database, 3);
    bool found = false;
    for (const RetrievalHit& hit : hits) {
      found = found || hit.index == by_distance[0] || hit.index == by_distance[1];
    }
    EXPECT_TRUE(found) << views[query].name;
    best_temple_similarities.push_back(hits[0].similarity);
  }

  const auto fountain = evloc::testing::SharedDataFile("strecha/fountain-P11/images");
  if (!fountain) {
    GTEST_SKIP() << evloc::testing::MissingDataReason("strecha/fountain-P11/images")
                 << " (the other-scene half of this test)";
  }
  std::vector<float> best_other_similarities;
  for (const char* name : {"0000.jpg", "0003.jpg", "0005.jpg", "0008.jpg"}) {
    const cv::Mat image = testing::ReadGrey(*fountain / name, 640);
    const std::vector<RetrievalHit> hits =
        Retrieve(vocabulary.EncodeVlad(ExtractFeatures(image, FeatureOptions())), database, 1);
    best_other_similarities.push_back(hits[0].similarity);
  }
  // Measured: the best similarity of a temple query is 0.15-0.37 (mean 0.25), of a fountain
  // photo 0.05-0.10 (mean 0.08).
  EXPECT_LT(*std::max_element(best_other_similarities.begin(), best_other_similarities.end()),
            *std::min_element(best_temple_similarities.begin(), best_temple_similarities.end()));
  EXPECT_LT(Mean(best_other_similarities), 0.5 * Mean(best_temple_similarities));
}

TEST(RelocVocabulary, HeldOutFountainViewsRetrieveANeighbour) {
  EVLOC_REQUIRE_SHARED_DATA(directory, "strecha/fountain-P11/images");
  // The eleven photos follow one arc in order: the map takes the even ones, and each odd photo's
  // neighbours on the arc are the two even photos beside it.
  std::vector<cv::Mat> database_images;
  for (int i = 0; i <= 10; i += 2) {
    database_images.push_back(testing::ReadGrey(directory / cv::format("%04d.jpg", i), 768));
  }
  const auto [vocabulary, database] = BuildDatabase(database_images);
  for (int query = 1; query <= 9; query += 2) {
    const cv::Mat image = testing::ReadGrey(directory / cv::format("%04d.jpg", query), 768);
    const std::vector<RetrievalHit> hits =
        Retrieve(vocabulary.EncodeVlad(ExtractFeatures(image, FeatureOptions())), database, 3);
    const auto is_neighbour = [&](const RetrievalHit& hit) {
      return std::abs(2 * hit.index - query) == 1;
    };
    EXPECT_TRUE(std::any_of(hits.begin(), hits.end(), is_neighbour)) << "photo " << query;
    // Measured: the best hit is a neighbour for every odd photo (and so is the second).
    EXPECT_TRUE(is_neighbour(hits[0])) << "photo " << query;
  }
}

}  // namespace
}  // namespace evloc::features
