// One viewed scene and what the viewer does with it, without the HTTP layer (view_api.h maps
// requests onto this, view_server.h serves it): the splat and its cameras, frames rendered by the
// CPU rasterizer (gs::Rasterizer, the same options as `macro render`, so a PNG frame equals
// `macro render` of that camera byte for byte), the close-up file (closeup_store.h), and the
// MACRO jobs on a placed close-up: `plan` (enhance::build_plan, build_views, write_plan_json,
// write_plan_debug, as `macro plan --debug-dir`) and `enhance` (enhance::enhance_closeup, as
// `macro enhance`: the transfer enhancer, or Difix when weights are given) in the background.
//
// Threads: frames render on the session's own ThreadPool under one lock; plan and enhance run on
// the global pool, one job at a time (a second is refused while one runs).
#pragma once

#include <atomic>
#include <chrono>
#include <memory>
#include <mutex>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include "attention/runtime/status.h"
#include "attention/runtime/thread_pool.h"
#include "enhance/scene_input.h"
#include "enhance/view/closeup_store.h"
#include "enhance/view/view_camera.h"
#include "gs/raster/rasterizer.h"

namespace macro::enhance::view {

struct ViewOptions {
  std::string scene_dir;  // a DL3DV-Closeup folder (plan and enhance need one) ...
  std::string scene;      // ... or a splat file or a scene folder holding scene.ply
  std::string cameras;    // the scene's cameras (any gs::load_cameras format); optional
  // Where close-ups are saved: a split JSON or a cameras JSON (closeup_store.h). Default: the
  // scene folder's split.json, else closeups.json beside the splat.
  std::string save_to;
  std::string weights;      // Difix pipeline folder: enhance runs Difix instead of transfer
  std::string results_dir;  // plan and enhance outputs (created; must be given)
  FrameLimits limits;
  int render_threads = 0;  // 0 = the machine's cores
};

struct Frame {
  std::vector<uint8_t> png;
  int width = 0, height = 0;
  double ms_render = 0, ms_encode = 0;
  size_t visible = 0;
};

// The background enhance job, as the page polls it.
struct JobState {
  std::string state = "idle";  // idle, running, done, failed
  int id = 0;
  std::string closeup, stage, error;
  std::vector<std::string> log;  // the job's progress lines, oldest first (the last 64)
  double elapsed_ms = 0;
  nlohmann::json result;  // done: files and timings
};

class ViewSession {
 public:
  static Result<std::unique_ptr<ViewSession>> open(const ViewOptions& options);
  ~ViewSession();

  // Cameras (training + the close-up file's), bounds {center, radius}, the up direction, the
  // close-up file and whether plan / enhance can run, the enhancer.
  nlohmann::json scene_json() const;
  // A camera of the scene or of the close-up file by name, or nullopt.
  std::optional<gs::Camera> find_camera(const std::string& name) const;

  Result<Frame> render(const gs::Camera& camera);

  Result<gs::CameraSet> closeups() const;
  const CloseupStore& store() const { return store_; }
  Status save_closeup(const std::string& name, const gs::Camera& camera, bool overwrite,
                      bool* exists);

  bool can_plan() const { return inputs_.has_value(); }
  bool job_running() const { return running_.load(); }
  // Runs the plan now (fails with "busy" when a job runs: check job_running() first). The reply:
  // the plan JSON, and the debug images and plan.json as result paths ("plan-3/plane_map.png").
  Result<nlohmann::json> plan(const gs::Camera& closeup);
  // Starts enhance in the background; false when a job is already running.
  Result<bool> start_enhance(const gs::Camera& closeup);
  JobState job() const;
  // Waits for a running job (the server's shutdown).
  void join_job();

  // A file under the results folder by its result path ("enhance-2/enhanced.png"); an error for
  // any other name.
  Result<std::string> result_file(const std::string& rel) const;
  const std::string& results_dir() const { return options_.results_dir; }

 private:
  ViewSession() = default;
  SceneInputs inputs_for(const gs::Camera& closeup) const;
  Result<std::string> new_result_dir(const char* kind);
  void run_enhance_job(gs::Camera closeup);

  ViewOptions options_;
  gs::GaussianCloud cloud_;               // --scene mode (scene-dir mode: inputs_->cloud)
  std::optional<SceneInputs> inputs_;     // scene-dir mode: references for plan and enhance
  std::vector<gs::Camera> cameras_;       // the scene's cameras
  std::vector<std::string> camera_notes;  // rejected entries, skipped candidates
  CloseupStore store_;
  double center_[3] = {0, 0, 0}, radius_ = 1, up_[3] = {0, -1, 0};

  std::mutex render_mutex_;
  std::unique_ptr<ThreadPool> render_pool_;
  gs::Rasterizer rasterizer_;
  gs::RenderResult frame_;

  mutable std::mutex job_mutex_;  // guards job_, the job thread and the result counter
  std::atomic<bool> running_{false};
  std::thread job_thread_;
  JobState job_;
  std::chrono::steady_clock::time_point job_start_;
  int next_result_ = 1;
  std::mutex store_mutex_;
};

}  // namespace macro::enhance::view
