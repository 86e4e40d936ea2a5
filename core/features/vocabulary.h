// Global image descriptors for place retrieval: a visual vocabulary (k-means centres of local
// descriptors, trained once per map), the VLAD encoding of an image's descriptors against it,
// and top-k retrieval by cosine similarity. Vocabularies and VLAD vectors convert to and from
// plain float vectors so that a map file can store them (docs/relocalization.md).
#pragma once

#include <cstdint>
#include <vector>

#include <Eigen/Core>
#include <opencv2/core/mat.hpp>

#include "core/features/features.h"

namespace evloc::features {

// Options of Vocabulary::Train.
struct VocabularyOptions {
  // Number of visual words (k-means centres); the VLAD vector has num_words * 128 floats.
  int num_words = 32;
  // At most this many descriptors are clustered; larger sets are subsampled with an even stride.
  int max_training_descriptors = 50000;
  // Lloyd iterations of k-means (after the k-means++ seeding).
  int kmeans_iterations = 25;
  // Seed of the k-means++ seeding: the same descriptors and seed give the same vocabulary.
  uint64_t seed = 20260113;

  // Throws InvalidArgumentError when a field is outside its domain.
  void Check() const;
};

// A hit of Retrieve: a database entry and its cosine similarity to the query.
struct RetrievalHit {
  // Index of the entry in the database.
  int index = 0;
  // Cosine similarity in [-1, 1]; 0 when either vector is zero.
  float similarity = 0;
};

// A visual vocabulary: num_words centres in descriptor space.
class Vocabulary {
 public:
  // An empty vocabulary (no words); Encode on it throws.
  Vocabulary() = default;

  // Clusters descriptors (float rows, CV_32F, one descriptor per row) by k-means with k-means++
  // seeding. Deterministic for a given seed. Throws InvalidArgumentError when there are fewer
  // rows than words, or the matrix is not CV_32F with one channel.
  static Vocabulary Train(const cv::Mat& descriptors, const VocabularyOptions& options);
  // Clusters the descriptors of several images (see the overload above).
  static Vocabulary Train(const std::vector<Features>& images, const VocabularyOptions& options);

  // Rebuilds a vocabulary from ToVector's output. Throws InvalidArgumentError when the sizes do
  // not match or a value is not finite.
  static Vocabulary FromVector(int num_words, int dimension, const std::vector<float>& centres);
  // The centres, row-major (num_words rows of dimension floats).
  std::vector<float> ToVector() const;

  // Number of words.
  int num_words() const { return centres_.rows; }
  // Length of one descriptor.
  int dimension() const { return centres_.cols; }
  // Length of a VLAD vector: num_words * dimension.
  int vlad_size() const { return num_words() * dimension(); }

  // The index of the centre nearest to each descriptor row (ties: the lowest index).
  std::vector<int> Assign(const cv::Mat& descriptors) const;

  // The VLAD vector of a set of descriptors (float rows): per word the sum of the residuals of the
  // descriptors assigned to it, each word's block L2-normalised (intra-normalisation), then the
  // signed square root of every component, then L2 normalisation of the whole vector. An empty
  // set gives the zero vector. Throws InvalidArgumentError when the vocabulary is empty or the
  // descriptor length differs from dimension().
  std::vector<float> EncodeVlad(const cv::Mat& descriptors) const;
  // The VLAD vector of an image's features.
  std::vector<float> EncodeVlad(const Features& features) const;

 private:
  // num_words x dimension, CV_32F.
  cv::Mat centres_;
};

// Cosine similarity of two vectors of equal length; 0 when either is zero. Throws
// InvalidArgumentError when the lengths differ.
float CosineSimilarity(const std::vector<float>& a, const std::vector<float>& b);

// Cosine similarities of every pair of `vectors` (all of one length) as an N x N matrix, from one
// matrix product of the unit vectors; 0 against a zero vector. Throws InvalidArgumentError for
// vectors of unequal lengths or a value that is not finite.
Eigen::MatrixXf CosineSimilarities(const std::vector<std::vector<float>>& vectors);

// For each of the N entries of an N x N similarity matrix (CosineSimilarities), the indices of
// its k most similar other entries, most similar first (ties: lower index first); fewer when
// N - 1 < k.
std::vector<std::vector<size_t>> MostSimilar(const Eigen::MatrixXf& similarity, size_t k);

// The k database entries most similar to the query, most similar first (ties: lower index
// first); fewer when the database is smaller. Throws InvalidArgumentError when k < 1 or a
// database vector's length differs from the query's.
std::vector<RetrievalHit> Retrieve(const std::vector<float>& query,
                                   const std::vector<std::vector<float>>& database, int k);

}  // namespace evloc::features
