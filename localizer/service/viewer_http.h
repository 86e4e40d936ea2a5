// The live web viewer of `evloc-localizer serve --viewer [ADDR:]PORT` (docs/viewer.md): a page
// (three.js, embedded in the binary) that shows a map's points coloured by depth or gradient, its
// keyframes, the tiles of a site, and the live pose, trail and status of every session, with a
// session's time surface and the map reprojected onto it on demand. The routes:
//   GET /, /app.js, /vendor/...        the page and its scripts (no authentication: no data)
//   GET /api/maps                      the maps and sites (JSON)
//   GET /api/maps/NAME                 a map's summary, keyframes, a site's tiles (JSON)
//   GET /api/maps/NAME/points?max=N    at most N points of a map (binary, 7 float32 each)
//   GET /api/sessions                  the running sessions with their trails (JSON)
//   GET /api/events?rate=HZ            server-sent events: the sessions' new poses, at most
//                                      `max_rate_hz` per client
//   GET /api/sessions/ID/surface.png   the session's time surface with the map reprojected
// With a token file every /api/ route needs `Authorization: Bearer TOKEN` and shows only the
// maps (and the sessions on maps) the token may use. Library code: throws typed errors.
#pragma once

#include <atomic>
#include <cstdint>
#include <memory>
#include <optional>
#include <string>

#include "localizer/service/auth.h"
#include "localizer/service/http_server.h"
#include "localizer/service/map_registry.h"
#include "localizer/service/viewer_board.h"

namespace evloc::service {

// Options of the viewer.
struct ViewerOptions {
  // Where to listen, IPV4:PORT (--viewer).
  std::string address;
  // Most event streams (open pages) at once; more get 503 (--viewer-max-clients).
  int max_clients = 8;
  // Highest update rate of a page's event stream, Hz (--viewer-rate); a page asks for less with
  // ?rate=.
  double max_rate_hz = 30.0;
  // Most points of a map sent to a page (a page asks for fewer with ?max=).
  int64_t max_points = 500'000;
  // Most time a page waits for a session's time-surface picture, seconds.
  double surface_timeout_s = 2.0;
  // TLS material; nullopt: plaintext.
  std::optional<TlsPem> tls;

  // Throws InvalidArgumentError naming the first invalid field.
  void Check() const;
};

// One map point as the page receives it: position (metres), depth from its source keyframe
// along that keyframe's optical axis (metres; NaN without a source keyframe) and 3D gradient.
inline constexpr int kViewerFloatsPerPoint = 7;

// The viewer's HTTP server over the server's map registry, session board and tokens.
class ViewerServer {
 public:
  // Starts serving. `tokens` (may be null: no authentication) and the rest must outlive it.
  // Throws like HttpServer.
  ViewerServer(const ViewerOptions& options, ViewerBoard& board, MapRegistry& registry,
               TokenFile* tokens);
  ~ViewerServer();

  // The port bound.
  int port() const { return http_->port(); }
  // Event streams open now.
  int event_streams() const { return event_streams_.load(); }
  // The HTTP server (HandleRawRequest for the fuzz target).
  HttpServer& http() { return *http_; }

 private:
  void AddRoutes(httplib::Server& server);

  ViewerOptions options_;
  ViewerBoard& board_;
  MapRegistry& registry_;
  TokenFile* tokens_;
  std::atomic<int> event_streams_{0};
  // Set first when the viewer stops: the event streams end.
  std::atomic<bool> stopping_{false};
  std::unique_ptr<HttpServer> http_;
};

// The page's static files, embedded at build time (viewer/ and three.js from scripts/
// build-viewer.sh): the body and content type of `path`, or nullptr.
struct ViewerAsset {
  const char* path;
  const char* content_type;
  const unsigned char* data;
  size_t size;
};
const ViewerAsset* FindViewerAsset(const std::string& path);

}  // namespace evloc::service
