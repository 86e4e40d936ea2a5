#include "localizer/service/viewer_board.h"

#include <utility>

namespace evloc::service {

ViewerSession::ViewerSession(uint64_t id, std::string map_name, std::string client_name)
    : id_(id), map_name_(std::move(map_name)), client_name_(std::move(client_name)) {}

void ViewerSession::Publish(const ViewerPose& pose) {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    latest_ = pose;
    if (trail_.size() == kMaxTrail) trail_.pop_front();
    trail_.push_back(pose.world_from_cam.translation);
  }
  poses_.fetch_add(1, std::memory_order_release);
}

ViewerSessionView ViewerSession::View(bool with_trail) const {
  ViewerSessionView view;
  view.id = id_;
  view.map_name = map_name_;
  view.client_name = client_name_;
  std::lock_guard<std::mutex> lock(mutex_);
  view.poses = poses_.load(std::memory_order_relaxed);
  view.latest = latest_;
  if (with_trail) view.trail.assign(trail_.begin(), trail_.end());
  return view;
}

void ViewerSession::PublishSurface(cv::Mat picture) {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    surface_ = std::move(picture);
    ++surface_generation_;
    surface_requested_.store(false, std::memory_order_relaxed);
  }
  surface_ready_.notify_all();
}

cv::Mat ViewerSession::RequestSurface(std::chrono::milliseconds timeout) {
  std::unique_lock<std::mutex> lock(mutex_);
  const uint64_t generation = surface_generation_;
  surface_requested_.store(true, std::memory_order_relaxed);
  surface_ready_.wait_for(lock, timeout,
                          [&] { return closed_ || surface_generation_ != generation; });
  if (surface_generation_ == generation) return cv::Mat();
  return surface_;
}

void ViewerSession::Close() {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    closed_ = true;
  }
  surface_ready_.notify_all();
}

bool ViewerSession::closed() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return closed_;
}

std::shared_ptr<ViewerSession> ViewerBoard::Open(uint64_t id, const std::string& map_name,
                                                 const std::string& client_name) {
  auto session = std::make_shared<ViewerSession>(id, map_name, client_name);
  {
    std::lock_guard<std::mutex> lock(mutex_);
    sessions_[id] = session;
  }
  membership_.fetch_add(1, std::memory_order_release);
  return session;
}

void ViewerBoard::Close(uint64_t id) {
  std::shared_ptr<ViewerSession> session;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    const auto found = sessions_.find(id);
    if (found == sessions_.end()) return;
    session = std::move(found->second);
    sessions_.erase(found);
  }
  session->Close();
  membership_.fetch_add(1, std::memory_order_release);
}

std::vector<std::shared_ptr<ViewerSession>> ViewerBoard::Sessions() const {
  std::lock_guard<std::mutex> lock(mutex_);
  std::vector<std::shared_ptr<ViewerSession>> sessions;
  sessions.reserve(sessions_.size());
  for (const auto& [id, session] : sessions_) sessions.push_back(session);
  return sessions;
}

std::shared_ptr<ViewerSession> ViewerBoard::Find(uint64_t id) const {
  std::lock_guard<std::mutex> lock(mutex_);
  const auto found = sessions_.find(id);
  return found == sessions_.end() ? nullptr : found->second;
}

}  // namespace evloc::service
