#include "core/features/vocabulary.h"

#include <algorithm>
#include <cmath>
#include <string>

#include <opencv2/core.hpp>

#include "core/common/error.h"

namespace evloc::features {
namespace {

// Scales v to unit L2 norm; leaves a zero vector unchanged.
void NormalizeL2(float* v, int size) {
  double squared = 0;
  for (int i = 0; i < size; ++i) squared += static_cast<double>(v[i]) * v[i];
  if (squared <= 0) return;
  const float scale = static_cast<float>(1.0 / std::sqrt(squared));
  for (int i = 0; i < size; ++i) v[i] *= scale;
}

// Throws unless `descriptors` is a single-channel float matrix with `dimension` columns (any
// number of rows; an empty matrix passes).
void CheckDescriptorMatrix(const cv::Mat& descriptors, int dimension, const char* caller) {
  if (descriptors.empty()) return;
  if (descriptors.type() != CV_32FC1 || descriptors.cols != dimension) {
    throw InvalidArgumentError(std::string(caller) + ": descriptors must be CV_32F rows of " +
                               std::to_string(dimension) + " floats, got type " +
                               std::to_string(descriptors.type()) + " with " +
                               std::to_string(descriptors.cols) + " columns");
  }
}

}  // namespace

void VocabularyOptions::Check() const {
  if (num_words < 1) {
    throw InvalidArgumentError("VocabularyOptions: num_words must be at least 1, got " +
                               std::to_string(num_words));
  }
  if (max_training_descriptors < num_words) {
    throw InvalidArgumentError(
        "VocabularyOptions: max_training_descriptors must be at least num_words");
  }
  if (kmeans_iterations < 1) {
    throw InvalidArgumentError("VocabularyOptions: kmeans_iterations must be at least 1");
  }
}

Vocabulary Vocabulary::Train(const cv::Mat& descriptors, const VocabularyOptions& options) {
  options.Check();
  if (descriptors.empty() || descriptors.type() != CV_32FC1) {
    throw InvalidArgumentError("Vocabulary::Train: descriptors must be a non-empty CV_32F matrix");
  }
  if (descriptors.rows < options.num_words) {
    throw InvalidArgumentError("Vocabulary::Train: " + std::to_string(descriptors.rows) +
                               " descriptors cannot make " + std::to_string(options.num_words) +
                               " words");
  }
  cv::Mat samples;
  if (descriptors.rows <= options.max_training_descriptors) {
    samples = descriptors.isContinuous() ? descriptors : descriptors.clone();
  } else {
    samples.create(options.max_training_descriptors, descriptors.cols, CV_32F);
    const double stride = static_cast<double>(descriptors.rows) / samples.rows;
    for (int i = 0; i < samples.rows; ++i) {
      descriptors.row(static_cast<int>(i * stride)).copyTo(samples.row(i));
    }
  }
  // cv::kmeans draws its k-means++ seeds from the calling thread's cv::theRNG(): seed it, and
  // give the caller's generator its state back afterwards.
  cv::RNG& rng = cv::theRNG();
  const uint64_t saved_state = rng.state;
  rng.state = options.seed;
  cv::Mat labels;
  Vocabulary vocabulary;
  cv::kmeans(samples, options.num_words, labels,
             cv::TermCriteria(cv::TermCriteria::MAX_ITER, options.kmeans_iterations, 0), 1,
             cv::KMEANS_PP_CENTERS, vocabulary.centres_);
  rng.state = saved_state;
  return vocabulary;
}

Vocabulary Vocabulary::Train(const std::vector<Features>& images,
                             const VocabularyOptions& options) {
  std::vector<cv::Mat> blocks;
  for (const Features& features : images) {
    if (features.size() > 0) blocks.push_back(features.DescriptorsAsFloat());
  }
  cv::Mat all;
  if (!blocks.empty()) cv::vconcat(blocks, all);
  return Train(all, options);
}

Vocabulary Vocabulary::FromVector(int num_words, int dimension, const std::vector<float>& centres) {
  if (num_words < 1 || dimension < 1 ||
      centres.size() != static_cast<size_t>(num_words) * static_cast<size_t>(dimension)) {
    throw InvalidArgumentError("Vocabulary::FromVector: " + std::to_string(centres.size()) +
                               " values do not make " + std::to_string(num_words) + " words of " +
                               std::to_string(dimension) + " floats");
  }
  for (const float value : centres) {
    if (!std::isfinite(value)) {
      throw InvalidArgumentError("Vocabulary::FromVector: a centre has a non-finite value");
    }
  }
  Vocabulary vocabulary;
  vocabulary.centres_ = cv::Mat(num_words, dimension, CV_32F);
  std::copy(centres.begin(), centres.end(), vocabulary.centres_.ptr<float>());
  return vocabulary;
}

std::vector<float> Vocabulary::ToVector() const {
  if (centres_.empty()) return {};
  return std::vector<float>(centres_.ptr<float>(), centres_.ptr<float>() + centres_.total());
}

std::vector<int> Vocabulary::Assign(const cv::Mat& descriptors) const {
  if (centres_.empty()) throw InvalidArgumentError("Vocabulary: the vocabulary is empty");
  CheckDescriptorMatrix(descriptors, dimension(), "Vocabulary::Assign");
  std::vector<int> words(descriptors.rows, 0);
  if (descriptors.empty()) return words;
  // |d - c|^2 = |d|^2 - 2 d.c + |c|^2; the |d|^2 term does not change the nearest centre.
  cv::Mat dot_products;
  cv::gemm(descriptors, centres_, 1.0, cv::noArray(), 0.0, dot_products, cv::GEMM_2_T);
  std::vector<float> centre_norms(num_words());
  for (int w = 0; w < num_words(); ++w) {
    centre_norms[w] = static_cast<float>(centres_.row(w).dot(centres_.row(w)));
  }
  for (int i = 0; i < descriptors.rows; ++i) {
    const float* dots = dot_products.ptr<float>(i);
    float best = centre_norms[0] - 2 * dots[0];
    for (int w = 1; w < num_words(); ++w) {
      const float distance = centre_norms[w] - 2 * dots[w];
      if (distance < best) {
        best = distance;
        words[i] = w;
      }
    }
  }
  return words;
}

std::vector<float> Vocabulary::EncodeVlad(const cv::Mat& descriptors) const {
  const std::vector<int> words = Assign(descriptors);
  const int d = dimension();
  std::vector<float> vlad(static_cast<size_t>(vlad_size()), 0.0f);
  for (int i = 0; i < descriptors.rows; ++i) {
    const float* descriptor = descriptors.ptr<float>(i);
    const float* centre = centres_.ptr<float>(words[i]);
    float* block = vlad.data() + static_cast<size_t>(words[i]) * d;
    for (int k = 0; k < d; ++k) block[k] += descriptor[k] - centre[k];
  }
  for (int w = 0; w < num_words(); ++w) NormalizeL2(vlad.data() + static_cast<size_t>(w) * d, d);
  for (float& value : vlad) value = std::copysign(std::sqrt(std::abs(value)), value);
  NormalizeL2(vlad.data(), vlad_size());
  return vlad;
}

std::vector<float> Vocabulary::EncodeVlad(const Features& features) const {
  return EncodeVlad(features.DescriptorsAsFloat());
}

Eigen::MatrixXf CosineSimilarities(const std::vector<std::vector<float>>& vectors) {
  const size_t n = vectors.size();
  const size_t dimension = n == 0 ? 0 : vectors[0].size();
  Eigen::MatrixXf unit(dimension, n);
  for (size_t i = 0; i < n; ++i) {
    if (vectors[i].size() != dimension) {
      throw InvalidArgumentError("CosineSimilarities: vectors of " + std::to_string(dimension) +
                                 " and " + std::to_string(vectors[i].size()) + " values");
    }
    const Eigen::Map<const Eigen::VectorXf> v(vectors[i].data(),
                                              static_cast<Eigen::Index>(dimension));
    if (!v.allFinite()) {
      throw InvalidArgumentError("CosineSimilarities: vector " + std::to_string(i) +
                                 " holds a value that is not finite");
    }
    const float norm = v.norm();
    if (norm > 0.0f) {
      unit.col(static_cast<Eigen::Index>(i)) = v / norm;
    } else {
      unit.col(static_cast<Eigen::Index>(i)).setZero();
    }
  }
  return unit.transpose() * unit;
}

std::vector<std::vector<size_t>> MostSimilar(const Eigen::MatrixXf& similarity, size_t k) {
  const size_t n = static_cast<size_t>(similarity.rows());
  const size_t count = n == 0 ? 0 : std::min(k, n - 1);
  std::vector<std::vector<size_t>> result(n);
  std::vector<size_t> others;
  for (size_t i = 0; i < n; ++i) {
    others.clear();
    for (size_t j = 0; j < n; ++j) {
      if (j != i) others.push_back(j);
    }
    const auto row = similarity.row(static_cast<Eigen::Index>(i));
    std::partial_sort(others.begin(), others.begin() + static_cast<std::ptrdiff_t>(count),
                      others.end(), [&](size_t a, size_t b) {
                        const float sa = row(static_cast<Eigen::Index>(a));
                        const float sb = row(static_cast<Eigen::Index>(b));
                        return sa != sb ? sa > sb : a < b;
                      });
    result[i].assign(others.begin(), others.begin() + static_cast<std::ptrdiff_t>(count));
  }
  return result;
}

float CosineSimilarity(const std::vector<float>& a, const std::vector<float>& b) {
  if (a.size() != b.size()) {
    throw InvalidArgumentError("CosineSimilarity: vectors of " + std::to_string(a.size()) +
                               " and " + std::to_string(b.size()) + " values");
  }
  double dot = 0, norm_a = 0, norm_b = 0;
  for (size_t i = 0; i < a.size(); ++i) {
    dot += static_cast<double>(a[i]) * b[i];
    norm_a += static_cast<double>(a[i]) * a[i];
    norm_b += static_cast<double>(b[i]) * b[i];
  }
  if (norm_a <= 0 || norm_b <= 0) return 0.0f;
  return static_cast<float>(dot / std::sqrt(norm_a * norm_b));
}

std::vector<RetrievalHit> Retrieve(const std::vector<float>& query,
                                   const std::vector<std::vector<float>>& database, int k) {
  if (k < 1) throw InvalidArgumentError("Retrieve: k must be at least 1, got " + std::to_string(k));
  std::vector<RetrievalHit> hits;
  hits.reserve(database.size());
  for (size_t i = 0; i < database.size(); ++i) {
    hits.push_back({static_cast<int>(i), CosineSimilarity(query, database[i])});
  }
  const size_t kept = std::min(hits.size(), static_cast<size_t>(k));
  std::partial_sort(hits.begin(), hits.begin() + kept, hits.end(),
                    [](const RetrievalHit& a, const RetrievalHit& b) {
                      return a.similarity > b.similarity ||
                             (a.similarity == b.similarity && a.index < b.index);
                    });
  hits.resize(kept);
  return hits;
}

}  // namespace evloc::features
