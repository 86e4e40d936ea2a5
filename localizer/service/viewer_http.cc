#include "localizer/service/viewer_http.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstring>
#include <limits>
#include <map>
#include <thread>
#include <vector>

#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>

#include "core/common/cli.h"
#include "core/common/error.h"
#include "localizer/service/client_text.h"

namespace evloc::service {
namespace {

using Clock = std::chrono::steady_clock;
using nlohmann::json;

// JSON text; bytes that are not UTF-8 (a client's query echoed in an error) become U+FFFD
// instead of throwing.
std::string Dump(const json& value) {
  return value.dump(-1, ' ', false, json::error_handler_t::replace);
}

void SendError(httplib::Response& response, int status, const std::string& message) {
  response.status = status;
  response.set_content(Dump(json{{"error", message}}) + "\n", "application/json");
}

void SendJson(httplib::Response& response, const json& body) {
  response.set_header("Cache-Control", "no-store");
  response.set_content(Dump(body), "application/json");
}

json Vector(const Eigen::Vector3d& v) { return json::array({v.x(), v.y(), v.z()}); }

// x, y, z, w of a pose's rotation.
json Quaternion(const Eigen::Quaterniond& q) { return json::array({q.x(), q.y(), q.z(), q.w()}); }

// The bearer token of a request ("" when none).
std::string BearerToken(const httplib::Request& request) {
  const std::string header = request.get_header_value("Authorization");
  static constexpr char kPrefix[] = "Bearer ";
  if (header.rfind(kPrefix, 0) != 0) return "";
  return header.substr(sizeof(kPrefix) - 1);
}

// A query parameter as a number in [low, high], or `fallback` when absent; throws
// InvalidArgumentError naming it for anything else.
double NumberParameter(const httplib::Request& request, const char* name, double fallback,
                       double low, double high) {
  if (!request.has_param(name)) return fallback;
  const double value = ParseDoubleFlag(name, request.get_param_value(name));
  if (!(value >= low && value <= high)) {
    throw InvalidArgumentError(std::string(name) + " must lie in [" + std::to_string(low) + ", " +
                               std::to_string(high) + "]");
  }
  return value;
}

json SessionJson(const ViewerSessionView& view) {
  json session = {
      {"id", view.id}, {"map", view.map_name}, {"client", view.client_name}, {"poses", view.poses}};
  if (view.latest) {
    session["status"] = tracking::TrackingStatusName(view.latest->status);
    session["t_s"] = static_cast<double>(view.latest->t_ns) * 1e-9;
    session["position"] = Vector(view.latest->world_from_cam.translation);
    session["rotation"] = Quaternion(view.latest->world_from_cam.rotation);
  } else {
    session["status"] = "STARTING";
  }
  return session;
}

}  // namespace

void ViewerOptions::Check() const {
  ParseIpv4ListenAddress(address, "--viewer");
  if (max_clients < 1 || max_clients > 256) {
    throw InvalidArgumentError("--viewer-max-clients must be 1 .. 256, got " +
                               std::to_string(max_clients));
  }
  if (!(max_rate_hz >= 1 && max_rate_hz <= 120)) {
    throw InvalidArgumentError("--viewer-rate must be 1 .. 120 Hz, got " +
                               std::to_string(max_rate_hz));
  }
  if (max_points < 1) throw InvalidArgumentError("viewer: max_points must be positive");
  if (!(surface_timeout_s > 0)) {
    throw InvalidArgumentError("viewer: the surface timeout must be positive");
  }
}

ViewerServer::ViewerServer(const ViewerOptions& options, ViewerBoard& board, MapRegistry& registry,
                           TokenFile* tokens)
    : options_(options), board_(board), registry_(registry), tokens_(tokens) {
  options_.Check();
  HttpServerOptions http;
  http.address = options_.address;
  http.flag = "--viewer";
  http.request_deadline_s = 5.0;
  http.write_timeout_s = 5.0;
  // Event streams hold a connection each; two more serve the page, the maps and the pictures.
  http.max_connections = options_.max_clients + 4;
  http.tls = options_.tls;
  http_ =
      std::make_unique<HttpServer>(http, [this](httplib::Server& server) { AddRoutes(server); });
}

ViewerServer::~ViewerServer() {
  // The event streams end at their next tick; then the HTTP server joins its threads.
  stopping_ = true;
  http_.reset();
}

void ViewerServer::AddRoutes(httplib::Server& server) {
  // Authorization of /api/ routes: with tokens, a known bearer token; `map` (when not empty)
  // must be allowed to it. Answers 401 / 403 and returns false otherwise.
  const auto authorized = [this](const httplib::Request& request, httplib::Response& response,
                                 const std::string& map) {
    if (tokens_ == nullptr) return true;
    const std::string token = BearerToken(request);
    if (token.empty() || !tokens_->Knows(token)) {
      response.set_header("WWW-Authenticate", "Bearer");
      SendError(response, 401,
                "this viewer needs a bearer token (evloc-localizer --auth-tokens): open the page "
                "as /#token=TOKEN");
      return false;
    }
    if (!map.empty() && !tokens_->Allows(token, map)) {
      SendError(response, 403, "the token may not use map '" + map + "'");
      return false;
    }
    return true;
  };
  // True when the request's token may see `map` (always without tokens).
  const auto may_see = [this](const httplib::Request& request, const std::string& map) {
    return tokens_ == nullptr || tokens_->Allows(BearerToken(request), map);
  };

  const auto serve_asset = [](const httplib::Request& request, httplib::Response& response) {
    const ViewerAsset* asset = FindViewerAsset(request.path == "/" ? "/index.html" : request.path);
    if (asset == nullptr) {
      SendError(response, 404, "no such file");
      return;
    }
    response.set_content(reinterpret_cast<const char*>(asset->data), asset->size,
                         asset->content_type);
  };
  server.Get("/", serve_asset);
  server.Get(R"(/(index\.html|app\.js|vendor/[A-Za-z0-9._-]+))", serve_asset);

  server.Get("/api/maps", [this, authorized, may_see](const httplib::Request& request,
                                                      httplib::Response& response) {
    if (!authorized(request, response, "")) return;
    json maps = json::array();
    for (const std::string& name : registry_.ListNames()) {
      if (may_see(request, name)) maps.push_back(name);
    }
    SendJson(response, {{"maps", maps}});
  });

  server.Get(R"(/api/maps/([A-Za-z0-9._-]{1,200}))",
             [this, authorized](const httplib::Request& request, httplib::Response& response) {
               const std::string name = request.matches[1];
               if (!authorized(request, response, name)) return;
               std::shared_ptr<const LoadedMap> map;
               try {
                 map = registry_.Get(name);
               } catch (const std::exception& error) {
                 SendError(response, 404, ScrubServerPaths(error.what(), {}));
                 return;
               }
               json keyframes = json::array();
               for (const Keyframe& keyframe : map->map.keyframes) {
                 const Rigid3d world_from_cam = keyframe.cam_from_world.Inverse();
                 keyframes.push_back({{"position", Vector(world_from_cam.translation)},
                                      {"rotation", Quaternion(world_from_cam.rotation)}});
               }
               json tiles = json::array();
               if (map->site) {
                 for (const SiteTile& tile : map->site->manifest.tiles) {
                   tiles.push_back({{"ix", tile.index.ix},
                                    {"iy", tile.index.iy},
                                    {"min", {tile.core.min_x, tile.core.min_y, tile.box_min.z()}},
                                    {"max", {tile.core.max_x, tile.core.max_y, tile.box_max.z()}},
                                    {"points", tile.num_points},
                                    {"keyframes", tile.num_keyframes}});
                 }
               }
               SendJson(response, {{"name", map->name},
                                   {"version", map->version},
                                   {"site", static_cast<bool>(map->site)},
                                   {"points", map->map.size()},
                                   {"box_min", Vector(map->info.bounding_box_min.cast<double>())},
                                   {"box_max", Vector(map->info.bounding_box_max.cast<double>())},
                                   {"keyframes", keyframes},
                                   {"tiles", tiles}});
             });

  server.Get(R"(/api/maps/([A-Za-z0-9._-]{1,200})/points)", [this, authorized](
                                                                const httplib::Request& request,
                                                                httplib::Response& response) {
    const std::string name = request.matches[1];
    if (!authorized(request, response, name)) return;
    int64_t most = options_.max_points;
    try {
      most = static_cast<int64_t>(NumberParameter(request, "max", static_cast<double>(most), 1,
                                                  static_cast<double>(options_.max_points)));
    } catch (const InvalidArgumentError& error) {
      SendError(response, 400, error.what());
      return;
    }
    std::shared_ptr<const LoadedMap> loaded;
    try {
      loaded = registry_.Get(name);
    } catch (const std::exception& error) {
      SendError(response, 404, ScrubServerPaths(error.what(), {}));
      return;
    }
    const Map& map = loaded->map;
    const size_t total = map.size();
    const size_t stride =
        std::max<size_t>(1, (total + static_cast<size_t>(most) - 1) / static_cast<size_t>(most));
    std::vector<float> values;
    values.reserve((total / stride + 1) * kViewerFloatsPerPoint);
    std::vector<Rigid3d> cams_from_world;
    for (const Keyframe& keyframe : map.keyframes)
      cams_from_world.push_back(keyframe.cam_from_world);
    for (size_t i = 0; i < total; i += stride) {
      const Eigen::Vector3f& p = map.positions[i];
      const Eigen::Vector3f& g = map.gradients[i];
      float depth = std::numeric_limits<float>::quiet_NaN();
      const uint32_t source = i < map.source_keyframe.size() ? map.source_keyframe[i] : kNoKeyframe;
      if (source < cams_from_world.size()) {
        depth = static_cast<float>((cams_from_world[source] * p.cast<double>()).z());
      }
      values.insert(values.end(), {p.x(), p.y(), p.z(), depth, g.x(), g.y(), g.z()});
    }
    response.set_header("X-Points-Total", std::to_string(total));
    response.set_header("Cache-Control", "no-store");
    response.set_content(reinterpret_cast<const char*>(values.data()),
                         values.size() * sizeof(float), "application/octet-stream");
  });

  server.Get("/api/sessions", [this, authorized, may_see](const httplib::Request& request,
                                                          httplib::Response& response) {
    if (!authorized(request, response, "")) return;
    json sessions = json::array();
    for (const auto& session : board_.Sessions()) {
      if (!may_see(request, session->map_name())) continue;
      const ViewerSessionView view = session->View(true);
      json entry = SessionJson(view);
      json trail = json::array();
      for (const Eigen::Vector3d& position : view.trail) trail.push_back(Vector(position));
      entry["trail"] = std::move(trail);
      sessions.push_back(std::move(entry));
    }
    SendJson(response, {{"sessions", sessions}});
  });

  server.Get(
      R"(/api/sessions/([0-9]{1,19})/surface\.png)",
      [this, authorized](const httplib::Request& request, httplib::Response& response) {
        if (!authorized(request, response, "")) return;
        const std::shared_ptr<ViewerSession> session =
            board_.Find(std::strtoull(request.matches[1].str().c_str(), nullptr, 10));
        if (!session || !authorized(request, response, session->map_name())) {
          if (!session) SendError(response, 404, "no such session");
          return;
        }
        const cv::Mat picture = session->RequestSurface(
            std::chrono::milliseconds(static_cast<int64_t>(options_.surface_timeout_s * 1000)));
        if (picture.empty()) {
          SendError(response, 503,
                    "the session tracked nothing in " + std::to_string(options_.surface_timeout_s) +
                        " s (or ended); try again");
          return;
        }
        std::vector<uint8_t> png;
        cv::imencode(".png", picture, png);
        response.set_header("Cache-Control", "no-store");
        response.set_content(reinterpret_cast<const char*>(png.data()), png.size(), "image/png");
      });

  server.Get("/api/events", [this, authorized](const httplib::Request& request,
                                               httplib::Response& response) {
    if (!authorized(request, response, "")) return;
    double rate_hz = options_.max_rate_hz;
    try {
      rate_hz = NumberParameter(request, "rate", rate_hz, 0.1, options_.max_rate_hz);
    } catch (const InvalidArgumentError& error) {
      SendError(response, 400, error.what());
      return;
    }
    if (++event_streams_ > options_.max_clients) {
      --event_streams_;
      SendError(response, 503,
                "too many viewer pages open (evloc-localizer --viewer-max-clients " +
                    std::to_string(options_.max_clients) + ")");
      return;
    }
    // The stream's state, shared by the calls of the provider.
    struct StreamState {
      Clock::time_point next;
      std::map<uint64_t, uint64_t> sent_poses;
      std::vector<uint64_t> sent_ids;
      bool first = true;
    };
    auto state = std::make_shared<StreamState>();
    state->next = Clock::now();
    const auto period =
        std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(1.0 / rate_hz));
    const std::string token = BearerToken(request);
    response.set_header("Cache-Control", "no-store");
    response.set_header("X-Accel-Buffering", "no");
    response.set_chunked_content_provider(
        "text/event-stream",
        [this, state, period, token](size_t, httplib::DataSink& sink) {
          // Rate limit: one event per period; the wait checks the stop flag every 50 ms.
          if (!sink.is_writable()) return false;
          while (Clock::now() < state->next) {
            if (stopping_) return false;
            std::this_thread::sleep_for(std::min<Clock::duration>(state->next - Clock::now(),
                                                                  std::chrono::milliseconds(50)));
          }
          if (stopping_ || !sink.is_writable()) return false;
          state->next = std::max(state->next + period, Clock::now());
          json ids = json::array();
          json changed = json::array();
          std::vector<uint64_t> id_list;
          for (const auto& session : board_.Sessions()) {
            if (tokens_ != nullptr && !tokens_->Allows(token, session->map_name())) continue;
            ids.push_back(session->id());
            id_list.push_back(session->id());
            uint64_t& sent = state->sent_poses[session->id()];
            if (session->poses() == sent && !state->first) continue;
            const ViewerSessionView view = session->View(false);
            sent = view.poses;
            changed.push_back(SessionJson(view));
          }
          // Forget the sessions that ended.
          for (auto it = state->sent_poses.begin(); it != state->sent_poses.end();) {
            it = std::find(id_list.begin(), id_list.end(), it->first) == id_list.end()
                     ? state->sent_poses.erase(it)
                     : std::next(it);
          }
          state->first = false;
          const std::string event =
              "event: poses\ndata: " + Dump(json{{"ids", ids}, {"sessions", changed}}) + "\n\n";
          return sink.write(event.data(), event.size());
        },
        [this](bool) { --event_streams_; });
  });

  server.set_exception_handler(
      [](const httplib::Request&, httplib::Response& response, std::exception_ptr error) {
        try {
          std::rethrow_exception(error);
        } catch (const std::exception& exception) {
          SendError(response, 500, ScrubServerPaths(exception.what(), {}));
        } catch (...) {
          SendError(response, 500, "internal error");
        }
      });
}

}  // namespace evloc::service
