// What the live viewer shows of the running sessions (docs/viewer.md): each session publishes its
// latest pose, status and a bounded trail into its own slot, and the viewer's threads read the
// slots. A slot is guarded by its own small mutex, held only to copy a few numbers (the tracking
// worker's publish is one uncontended lock per request; a viewer copies the whole trail once per
// client, then only what is new), so a viewer never holds a tracking worker. The time surface is
// rendered on demand: a viewer raises the slot's request flag, the session's worker renders the
// picture after its next request and the viewer waits for it.
#pragma once

#include <atomic>
#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <deque>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <vector>

#include <opencv2/core.hpp>

#include "core/geometry/rigid3.h"
#include "localizer/tracking/tracker.h"

namespace evloc::service {

// One pose of a session as the viewer shows it.
struct ViewerPose {
  // Session time of the step, ns.
  int64_t t_ns = 0;
  // The estimate (the last good pose while not TRACKING).
  Rigid3d world_from_cam;
  // The tracker state of the step.
  tracking::TrackingStatus status = tracking::TrackingStatus::kInitializing;
};

// What a viewer reads of one session.
struct ViewerSessionView {
  // Session id (SessionStarted.session_id).
  uint64_t id = 0;
  // The map (or site) it tracks against.
  std::string map_name;
  // The client's name (SessionStart.client_name, escaped for display).
  std::string client_name;
  // Poses published so far.
  uint64_t poses = 0;
  // The latest pose (nullopt before the first).
  std::optional<ViewerPose> latest;
  // The trail: the positions of the last poses, oldest first (filled only when asked for).
  std::vector<Eigen::Vector3d> trail;
};

// The slot of one session. Publish and the surface calls come from the session's tracking
// worker; the rest from viewer threads. Thread-safe.
class ViewerSession {
 public:
  // Most trail positions kept per session.
  static constexpr size_t kMaxTrail = 600;

  ViewerSession(uint64_t id, std::string map_name, std::string client_name);

  // Publishes the pose of a step (the worker; one short lock).
  void Publish(const ViewerPose& pose);
  // The session's view; with the trail when `with_trail`.
  ViewerSessionView View(bool with_trail) const;
  // Poses published so far (lock-free; tells a viewer whether anything changed).
  uint64_t poses() const { return poses_.load(std::memory_order_acquire); }
  // Session id.
  uint64_t id() const { return id_; }
  // Map name.
  const std::string& map_name() const { return map_name_; }

  // True when a viewer waits for a time-surface picture (the worker checks it after each
  // request; a relaxed atomic load).
  bool surface_requested() const { return surface_requested_.load(std::memory_order_relaxed); }
  // The worker hands over the picture (CV_8UC3) and clears the request.
  void PublishSurface(cv::Mat picture);
  // A viewer asks for a picture newer than the one it has and waits at most `timeout` for the
  // worker to render it; returns it, or an empty Mat when none came (the session does not
  // track any request meanwhile, or ended).
  cv::Mat RequestSurface(std::chrono::milliseconds timeout);
  // The session ended: a waiting viewer returns at once.
  void Close();
  // True once Close() was called.
  bool closed() const;

 private:
  const uint64_t id_;
  const std::string map_name_;
  const std::string client_name_;
  mutable std::mutex mutex_;
  std::optional<ViewerPose> latest_;
  std::deque<Eigen::Vector3d> trail_;
  std::atomic<uint64_t> poses_{0};
  std::atomic<bool> surface_requested_{false};
  std::condition_variable surface_ready_;
  cv::Mat surface_;
  uint64_t surface_generation_ = 0;
  bool closed_ = false;
};

// The slots of the running sessions. Thread-safe.
class ViewerBoard {
 public:
  // Adds the slot of a session that just opened.
  std::shared_ptr<ViewerSession> Open(uint64_t id, const std::string& map_name,
                                      const std::string& client_name);
  // Removes the slot of a session that ended (its waiting viewers return).
  void Close(uint64_t id);
  // The running sessions, by id.
  std::vector<std::shared_ptr<ViewerSession>> Sessions() const;
  // One session, or null.
  std::shared_ptr<ViewerSession> Find(uint64_t id) const;
  // Changes whenever a session opens or ends.
  uint64_t membership() const { return membership_.load(std::memory_order_acquire); }

 private:
  mutable std::mutex mutex_;
  std::map<uint64_t, std::shared_ptr<ViewerSession>> sessions_;
  std::atomic<uint64_t> membership_{0};
};

}  // namespace evloc::service
