#include "mapper/colmap_database.h"

#include <sqlite3.h>

#include <algorithm>
#include <cmath>
#include <cstring>

#include "core/common/error.h"

namespace evloc::mapper {
namespace {

// COLMAP's largest image id plus one (database.cc, kMaxNumImages).
constexpr uint64_t kMaxNumImages = 2147483647;

// A prepared SQLite statement; finalised on destruction.
class Statement {
 public:
  Statement(sqlite3* handle, const std::string& sql, const std::string& what) {
    if (sqlite3_prepare_v2(handle, sql.c_str(), -1, &statement_, nullptr) != SQLITE_OK) {
      throw IoError(what + ": " + sqlite3_errmsg(handle));
    }
  }
  ~Statement() { sqlite3_finalize(statement_); }
  Statement(const Statement&) = delete;
  Statement& operator=(const Statement&) = delete;

  sqlite3_stmt* get() const { return statement_; }

 private:
  sqlite3_stmt* statement_ = nullptr;
};

// An open COLMAP database; closed on destruction.
class Database {
 public:
  Database(const std::filesystem::path& path, bool writable) : path_(path) {
    if (!std::filesystem::exists(path)) {
      throw IoError("COLMAP database " + path.string() + " does not exist");
    }
    const int flags = writable ? SQLITE_OPEN_READWRITE : SQLITE_OPEN_READONLY;
    if (sqlite3_open_v2(path.c_str(), &handle_, flags, nullptr) != SQLITE_OK) {
      const std::string message = handle_ ? sqlite3_errmsg(handle_) : "out of memory";
      sqlite3_close(handle_);
      throw IoError("cannot open COLMAP database " + path.string() + ": " + message);
    }
    sqlite3_busy_timeout(handle_, 10000);
  }
  ~Database() { sqlite3_close(handle_); }
  Database(const Database&) = delete;
  Database& operator=(const Database&) = delete;

  // Runs `sql`, calling `row` for each result row.
  template <typename RowFunction>
  void Query(const std::string& sql, RowFunction row) const {
    const Statement statement(handle_, sql, ReadError());
    int status = SQLITE_ROW;
    while ((status = sqlite3_step(statement.get())) == SQLITE_ROW) row(statement.get());
    if (status != SQLITE_DONE) throw IoError(ReadError() + ": " + sqlite3_errmsg(handle_));
  }

  // Runs a statement without results.
  void Execute(const std::string& sql) const {
    char* message = nullptr;
    if (sqlite3_exec(handle_, sql.c_str(), nullptr, nullptr, &message) != SQLITE_OK) {
      const std::string text = message ? message : "unknown error";
      sqlite3_free(message);
      throw IoError(WriteError() + ": " + text);
    }
  }

  sqlite3* handle() const { return handle_; }
  const std::filesystem::path& path() const { return path_; }
  std::string ReadError() const { return "cannot read COLMAP database " + path_.string(); }
  std::string WriteError() const { return "cannot write COLMAP database " + path_.string(); }

 private:
  std::filesystem::path path_;
  sqlite3* handle_ = nullptr;
};

// A blob column as bytes (empty for NULL).
std::vector<uint8_t> ColumnBytes(sqlite3_stmt* row, int column) {
  const auto* data = static_cast<const uint8_t*>(sqlite3_column_blob(row, column));
  const int size = sqlite3_column_bytes(row, column);
  if (data == nullptr || size <= 0) return {};
  return std::vector<uint8_t>(data, data + size);
}

// Checks that a blob holds rows x cols elements of `element_size` bytes.
void CheckBlobSize(const Database& database, const std::string& table, int64_t key, int64_t rows,
                   int64_t cols, size_t element_size, size_t bytes) {
  if (rows < 0 || cols < 0 ||
      static_cast<uint64_t>(rows) * static_cast<uint64_t>(cols) * element_size != bytes) {
    throw ParseError(database.path().string(), "table " + table + " row " + std::to_string(key),
                     std::to_string(bytes) + " bytes of data for " + std::to_string(rows) + " x " +
                         std::to_string(cols) + " elements of " + std::to_string(element_size) +
                         " bytes: not a COLMAP 3.8 database");
  }
}

// rows x 2 uint32 matches from a blob.
FeatureMatches MatchesFromBlob(const Database& database, const std::string& table,
                               sqlite3_stmt* row, int64_t pair_id) {
  const int64_t rows = sqlite3_column_int64(row, 1);
  const int64_t cols = sqlite3_column_int64(row, 2);
  const std::vector<uint8_t> bytes = ColumnBytes(row, 3);
  if (rows == 0) return {};
  if (cols != 2) {
    throw ParseError(database.path().string(),
                     "table " + table + " pair " + std::to_string(pair_id),
                     std::to_string(cols) + " columns of matches (expected 2)");
  }
  CheckBlobSize(database, table, pair_id, rows, cols, sizeof(uint32_t), bytes.size());
  FeatureMatches matches(static_cast<size_t>(rows));
  for (size_t i = 0; i < matches.size(); ++i) {
    std::memcpy(&matches[i].first, bytes.data() + 8 * i, 4);
    std::memcpy(&matches[i].second, bytes.data() + 8 * i + 4, 4);
  }
  return matches;
}

// A 3x3 float64 row-major blob (zero for NULL).
Eigen::Matrix3d MatrixFromBlob(const Database& database, sqlite3_stmt* row, int column,
                               int64_t pair_id) {
  const std::vector<uint8_t> bytes = ColumnBytes(row, column);
  Eigen::Matrix<double, 3, 3, Eigen::RowMajor> matrix = Eigen::Matrix3d::Zero();
  if (bytes.empty()) return matrix;
  if (bytes.size() != 9 * sizeof(double)) {
    throw ParseError(database.path().string(),
                     "table two_view_geometries pair " + std::to_string(pair_id),
                     "a matrix of " + std::to_string(bytes.size()) + " bytes (expected 72)");
  }
  std::memcpy(matrix.data(), bytes.data(), bytes.size());
  return matrix;
}

// Binds a blob (copied by SQLite); an empty one binds NULL.
void BindBlob(const Database& database, sqlite3_stmt* statement, int index, const void* data,
              size_t bytes) {
  const int status = bytes == 0
                         ? sqlite3_bind_null(statement, index)
                         : sqlite3_bind_blob64(statement, index, data, bytes, SQLITE_TRANSIENT);
  if (status != SQLITE_OK) {
    throw IoError(database.WriteError() + ": " + sqlite3_errmsg(database.handle()));
  }
}

// Inserts (pair_id, rows, 2, matches) and, for two_view_geometries, the config and matrices.
void InsertPair(const Database& database, sqlite3_stmt* statement, uint64_t pair_id,
                const FeatureMatches& matches, const PairGeometry* geometry) {
  sqlite3_reset(statement);
  sqlite3_clear_bindings(statement);
  std::vector<uint32_t> data;
  data.reserve(2 * matches.size());
  for (const auto& [first, second] : matches) data.insert(data.end(), {first, second});
  sqlite3_bind_int64(statement, 1, static_cast<sqlite3_int64>(pair_id));
  sqlite3_bind_int64(statement, 2, static_cast<sqlite3_int64>(matches.size()));
  sqlite3_bind_int64(statement, 3, 2);
  BindBlob(database, statement, 4, data.data(), data.size() * sizeof(uint32_t));
  if (geometry != nullptr) {
    sqlite3_bind_int64(statement, 5, static_cast<int>(geometry->config));
    const bool estimated = geometry->config != TwoViewConfig::kUndefined;
    int index = 6;
    for (const Eigen::Matrix3d* matrix : {&geometry->F, &geometry->E, &geometry->H}) {
      const Eigen::Matrix<double, 3, 3, Eigen::RowMajor> row_major = *matrix;
      BindBlob(database, statement, index++, row_major.data(), estimated ? 9 * sizeof(double) : 0);
    }
    // The relative pose is not computed (COLMAP 3.8's default compute_relative_pose = false
    // writes zeros too).
    const double qvec[4] = {0, 0, 0, 0};
    const double tvec[3] = {0, 0, 0};
    BindBlob(database, statement, 9, qvec, estimated ? sizeof(qvec) : 0);
    BindBlob(database, statement, 10, tvec, estimated ? sizeof(tvec) : 0);
  }
  if (sqlite3_step(statement) != SQLITE_DONE) {
    throw IoError(database.WriteError() + ": " + sqlite3_errmsg(database.handle()));
  }
}

}  // namespace

uint64_t ColmapPairId(uint32_t image_id1, uint32_t image_id2) {
  const uint64_t first = std::min(image_id1, image_id2);
  const uint64_t second = std::max(image_id1, image_id2);
  return first * kMaxNumImages + second;
}

std::vector<ImageFeatures> ReadImageFeatures(const std::filesystem::path& database_path) {
  const Database database(database_path, false);
  std::vector<ImageFeatures> images;
  std::map<uint32_t, size_t> index_of_id;
  std::vector<int64_t> camera_of_image;
  database.Query("SELECT image_id, name, camera_id FROM images ORDER BY name",
                 [&](sqlite3_stmt* row) {
                   ImageFeatures image;
                   image.image_id = static_cast<uint32_t>(sqlite3_column_int64(row, 0));
                   const unsigned char* name = sqlite3_column_text(row, 1);
                   image.name = name ? reinterpret_cast<const char*>(name) : "";
                   index_of_id[image.image_id] = images.size();
                   images.push_back(std::move(image));
                   camera_of_image.push_back(sqlite3_column_int64(row, 2));
                 });
  std::map<int64_t, Eigen::Vector2f> camera_size;
  database.Query("SELECT camera_id, width, height FROM cameras", [&](sqlite3_stmt* row) {
    camera_size[sqlite3_column_int64(row, 0)] =
        Eigen::Vector2f(static_cast<float>(sqlite3_column_int64(row, 1)),
                        static_cast<float>(sqlite3_column_int64(row, 2)));
  });
  std::vector<std::vector<float>> scales(images.size());
  std::vector<bool> has_keypoints(images.size(), false);
  std::vector<bool> has_descriptors(images.size(), false);
  // Calls body(image index, rows, cols, bytes) for each row of a features table (`keypoints` or
  // `descriptors`) whose image is listed, after checking the column count and the blob size.
  const auto for_each_row = [&](const std::string& table, const std::vector<int64_t>& columns,
                                size_t element_size, const auto& body) {
    database.Query("SELECT image_id, rows, cols, data FROM " + table, [&](sqlite3_stmt* row) {
      const int64_t id = sqlite3_column_int64(row, 0);
      const auto found = index_of_id.find(static_cast<uint32_t>(id));
      if (found == index_of_id.end()) return;
      const int64_t rows = sqlite3_column_int64(row, 1);
      const int64_t cols = sqlite3_column_int64(row, 2);
      if (rows != 0 && std::find(columns.begin(), columns.end(), cols) == columns.end()) {
        throw ParseError(database.path().string(), "table " + table + " row " + std::to_string(id),
                         std::to_string(cols) + " columns: not a COLMAP 3.8 database");
      }
      std::vector<uint8_t> bytes = ColumnBytes(row, 3);
      CheckBlobSize(database, table, id, rows, cols, element_size, bytes.size());
      body(found->second, rows, cols, std::move(bytes));
    });
  };
  for_each_row("keypoints", {2, 4, 6}, sizeof(float),
               [&](size_t index, int64_t rows, int64_t cols, std::vector<uint8_t> bytes) {
                 ImageFeatures& image = images[index];
                 image.keypoints.resize(static_cast<size_t>(rows));
                 scales[index].assign(static_cast<size_t>(rows), 0.0f);
                 for (size_t i = 0; i < image.keypoints.size(); ++i) {
                   float values[6] = {0, 0, 0, 0, 0, 0};
                   std::memcpy(values, bytes.data() + i * static_cast<size_t>(cols) * sizeof(float),
                               static_cast<size_t>(cols) * sizeof(float));
                   image.keypoints[i] = Eigen::Vector2f(values[0], values[1]);
                   // 4 columns: x y scale orientation; 6: x y and the affine shape a11 a12 a21 a22.
                   if (cols == 4) scales[index][i] = values[2];
                   if (cols == 6) {
                     scales[index][i] =
                         std::sqrt(std::abs(values[2] * values[5] - values[3] * values[4]));
                   }
                 }
                 has_keypoints[index] = true;
               });
  for_each_row("descriptors", {kSiftDescriptorSize}, 1,
               [&](size_t index, int64_t, int64_t, std::vector<uint8_t> bytes) {
                 images[index].descriptors = std::move(bytes);
                 has_descriptors[index] = true;
               });
  for (size_t i = 0; i < images.size(); ++i) {
    ImageFeatures& image = images[i];
    if (!has_keypoints[i] || !has_descriptors[i]) {
      throw ParseError(database.path().string(), "image " + std::to_string(image.image_id),
                       image.name +
                           " has no keypoints or descriptors row (features not "
                           "extracted)");
    }
    if (image.descriptors.size() != image.keypoints.size() * kSiftDescriptorSize) {
      throw ParseError(database.path().string(), "image " + std::to_string(image.image_id),
                       std::to_string(image.keypoints.size()) + " keypoints but " +
                           std::to_string(image.descriptors.size() / kSiftDescriptorSize) +
                           " descriptors");
    }
    // A keypoint whose centre lies within half its scale of the image border has most of its
    // descriptor window outside the image, and COLMAP 3.8 computes that descriptor from memory
    // outside the image: measured on slider_depth, frame 72's keypoint at y = 179.27 (0.73 px
    // from the border, scale 3.75) had a normal descriptor in one run and an all-zero one in
    // another. Such descriptors are zeroed, so that the matcher (which skips descriptors of small
    // norm) never uses them and two runs match the same features.
    const auto size = camera_size.find(camera_of_image[i]);
    if (size == camera_size.end()) continue;
    for (size_t k = 0; k < image.keypoints.size(); ++k) {
      const Eigen::Vector2f& point = image.keypoints[k];
      const float border = std::min(
          {point.x(), point.y(), size->second.x() - point.x(), size->second.y() - point.y()});
      if (border < 0.5f * scales[i][k]) {
        std::fill_n(
            image.descriptors.begin() + static_cast<std::ptrdiff_t>(k * kSiftDescriptorSize),
            kSiftDescriptorSize, uint8_t{0});
      }
    }
  }
  return images;
}

void WritePairGeometries(const std::filesystem::path& database_path,
                         const std::vector<PairGeometry>& pairs) {
  for (const PairGeometry& pair : pairs) {
    if (!(pair.image_id1 < pair.image_id2)) {
      throw InvalidArgumentError("image pair (" + std::to_string(pair.image_id1) + ", " +
                                 std::to_string(pair.image_id2) +
                                 "): the first image id must be the smaller");
    }
  }
  const Database database(database_path, true);
  database.Execute("BEGIN TRANSACTION");
  try {
    database.Execute("DELETE FROM matches");
    database.Execute("DELETE FROM two_view_geometries");
    const Statement matches(database.handle(),
                            "INSERT INTO matches(pair_id, rows, cols, data) VALUES(?, ?, ?, ?)",
                            database.WriteError());
    const Statement geometries(database.handle(),
                               "INSERT INTO two_view_geometries(pair_id, rows, cols, data, config, "
                               "F, E, H, qvec, tvec) VALUES(?, ?, ?, ?, ?, ?, ?, ?, ?, ?)",
                               database.WriteError());
    for (const PairGeometry& pair : pairs) {
      const uint64_t pair_id = ColmapPairId(pair.image_id1, pair.image_id2);
      InsertPair(database, matches.get(), pair_id, pair.matches, nullptr);
      InsertPair(database, geometries.get(), pair_id, pair.inlier_matches, &pair);
    }
    database.Execute("COMMIT");
  } catch (...) {
    sqlite3_exec(database.handle(), "ROLLBACK", nullptr, nullptr, nullptr);
    throw;
  }
}

std::vector<PairGeometry> ReadPairGeometries(const std::filesystem::path& database_path) {
  const Database database(database_path, false);
  std::map<int64_t, PairGeometry> pairs;
  database.Query(
      "SELECT pair_id, rows, cols, data, config, F, E, H FROM two_view_geometries",
      [&](sqlite3_stmt* row) {
        const int64_t pair_id = sqlite3_column_int64(row, 0);
        PairGeometry& pair = pairs[pair_id];
        pair.image_id1 = static_cast<uint32_t>(static_cast<uint64_t>(pair_id) / kMaxNumImages);
        pair.image_id2 = static_cast<uint32_t>(static_cast<uint64_t>(pair_id) % kMaxNumImages);
        pair.inlier_matches = MatchesFromBlob(database, "two_view_geometries", row, pair_id);
        pair.config = static_cast<TwoViewConfig>(sqlite3_column_int(row, 4));
        pair.F = MatrixFromBlob(database, row, 5, pair_id);
        pair.E = MatrixFromBlob(database, row, 6, pair_id);
        pair.H = MatrixFromBlob(database, row, 7, pair_id);
      });
  database.Query("SELECT pair_id, rows, cols, data FROM matches", [&](sqlite3_stmt* row) {
    const int64_t pair_id = sqlite3_column_int64(row, 0);
    const auto found = pairs.find(pair_id);
    if (found != pairs.end()) {
      found->second.matches = MatchesFromBlob(database, "matches", row, pair_id);
    }
  });
  std::vector<PairGeometry> result;
  for (auto& [pair_id, pair] : pairs) result.push_back(std::move(pair));
  return result;
}

std::map<std::string, uint32_t> ReadDatabaseImageIds(const std::filesystem::path& database_path) {
  const Database database(database_path, false);
  std::map<std::string, uint32_t> ids;
  database.Query("SELECT image_id, name FROM images", [&](sqlite3_stmt* row) {
    const uint32_t id = static_cast<uint32_t>(sqlite3_column_int64(row, 0));
    const unsigned char* name = sqlite3_column_text(row, 1);
    ids[name ? reinterpret_cast<const char*>(name) : ""] = id;
  });
  return ids;
}

std::vector<uint32_t> ReadDatabaseCameraIds(const std::filesystem::path& database_path) {
  const Database database(database_path, false);
  std::vector<uint32_t> ids;
  database.Query("SELECT camera_id FROM cameras ORDER BY camera_id", [&](sqlite3_stmt* row) {
    ids.push_back(static_cast<uint32_t>(sqlite3_column_int64(row, 0)));
  });
  return ids;
}

}  // namespace evloc::mapper
