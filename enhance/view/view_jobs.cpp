// The viewer's MACRO jobs on a placed close-up: plan (synchronous) and enhance (background), one at
// a time (see view_session.h). They call the library functions `macro plan` and `macro enhance`
// call; nothing of the method is repeated here.
#include <chrono>
#include <filesystem>

#include "attention/runtime/file_io.h"
#include "attention/runtime/progress.h"
#include "enhance/enhance.h"
#include "enhance/macro/plan.h"
#include "enhance/side_by_side.h"
#include "enhance/view/view_session.h"
#include "gs/image_io.h"

namespace macro::enhance::view {
namespace fs = std::filesystem;
using Json = nlohmann::json;

SceneInputs ViewSession::inputs_for(const gs::Camera& closeup) const {
  SceneInputs in = *inputs_;  // a copy: the cloud and candidates stay as loaded
  in.closeup = closeup;
  if (in.closeup.name.empty()) in.closeup.name = "viewer";
  in.closeup_pose_source = "given";
  in.notes.clear();
  return in;
}

Result<std::string> ViewSession::new_result_dir(const char* kind) {
  const std::string rel = std::string(kind) + "-" + std::to_string(next_result_++);
  const std::string dir = (fs::path(options_.results_dir) / rel).string();
  std::error_code ec;
  fs::create_directories(dir, ec);
  if (!is_directory(dir)) return Status::error(dir + ": cannot create: " + ec.message());
  return rel;
}

namespace {

// Result paths of the files in results/<rel>, sorted.
Json listing(const std::string& root, const std::string& rel) {
  std::vector<std::string> names;
  std::error_code ec;
  for (const auto& e : fs::directory_iterator(fs::path(root) / rel, ec))
    if (e.is_regular_file(ec)) names.push_back(e.path().filename().string());
  std::sort(names.begin(), names.end());
  Json out = Json::array();
  for (const std::string& n : names) out.push_back(rel + "/" + n);
  return out;
}

}  // namespace

Result<Json> ViewSession::plan(const gs::Camera& closeup) {
  if (!inputs_) return Status::error("plan: needs a scene folder (macro view --scene-dir DIR)");
  bool expected = false;
  if (!running_.compare_exchange_strong(expected, true))
    return Status::error("plan: busy, an enhance job is running");
  struct Clear {
    std::atomic<bool>& flag;
    ~Clear() { flag.store(false); }
  } clear{running_};
  const SceneInputs in = inputs_for(closeup);
  PlanOptions o;  // the released MACRO: K = 3, P = 3, masks 'released', full crops
  MACRO_ASSIGN_OR_RETURN(MacroPlan plan, build_plan(in, o));
  MACRO_ASSIGN_OR_RETURN(auto up, make_upsampler("lanczos"));
  MACRO_ASSIGN_OR_RETURN(PlanViews views, build_views(plan, in, *up));
  std::string rel;
  {
    std::lock_guard<std::mutex> lock(job_mutex_);
    MACRO_ASSIGN_OR_RETURN(rel, new_result_dir("plan"));
  }
  const fs::path dir = fs::path(options_.results_dir) / rel;
  MACRO_TRY(write_plan_debug(plan, views, dir.string()));
  MACRO_TRY(write_plan_json(plan, (dir / "plan.json").string()));
  Json reply;
  reply["plan"] = Json::parse(plan_to_json(plan), nullptr, false);
  reply["files"] = listing(options_.results_dir, rel);
  reply["folder"] = rel;
  return reply;
}

Result<bool> ViewSession::start_enhance(const gs::Camera& closeup) {
  if (!inputs_) return Status::error("enhance: needs a scene folder (macro view --scene-dir DIR)");
  std::lock_guard<std::mutex> lock(job_mutex_);
  bool expected = false;
  if (!running_.compare_exchange_strong(expected, true)) return false;
  if (job_thread_.joinable()) job_thread_.join();
  job_ = JobState();
  job_.state = "running";
  job_.id = next_result_;
  job_.closeup = closeup.name;
  job_.stage = "starting";
  job_start_ = std::chrono::steady_clock::now();
  job_thread_ = std::thread(&ViewSession::run_enhance_job, this, closeup);
  return true;
}

void ViewSession::run_enhance_job(gs::Camera closeup) {
  set_log_observer([this](const std::string& stage, const std::string& message) {
    std::lock_guard<std::mutex> lock(job_mutex_);
    job_.stage = stage + ": " + message;
    job_.log.push_back(job_.stage);
    if (job_.log.size() > 64) job_.log.erase(job_.log.begin());
  });
  auto run = [&]() -> Result<Json> {
    const SceneInputs in = inputs_for(closeup);
    EnhanceOptions o;  // macro, the released plan options
    o.weights = options_.weights;
    o.enhancer = options_.weights.empty() ? Enhancer::kTransfer : Enhancer::kDifix;
    MACRO_ASSIGN_OR_RETURN(EnhanceResult r, enhance_closeup(in, o));
    std::string rel;
    {
      std::lock_guard<std::mutex> lock(job_mutex_);
      MACRO_ASSIGN_OR_RETURN(rel, new_result_dir("enhance"));
    }
    const fs::path dir = fs::path(options_.results_dir) / rel;
    MACRO_TRY(gs::write_png((dir / "render.png").string(), r.render));
    MACRO_TRY(gs::write_png((dir / "enhanced.png").string(), r.image));
    MACRO_TRY(write_side_by_side((dir / "side_by_side.png").string(), options_.scene_dir,
                                 in.closeup.name, r));
    Json j;
    j["render"] = rel + "/render.png";
    j["enhanced"] = rel + "/enhanced.png";
    j["side_by_side"] = rel + "/side_by_side.png";
    j["enhancer"] = r.enhancer;
    j["views"] = r.views;
    j["size"] = {r.image.width, r.image.height};
    j["ms_total"] = r.timings.ms_total;
    return j;
  };
  Result<Json> result = run();
  set_log_observer({});
  std::lock_guard<std::mutex> lock(job_mutex_);
  job_.elapsed_ms = ms_since(job_start_);
  if (result) {
    job_.state = "done";
    job_.stage = "done";
    job_.result = *result;
  } else {
    job_.state = "failed";
    job_.error = result.status().message();
  }
  running_.store(false);
}

JobState ViewSession::job() const {
  std::lock_guard<std::mutex> lock(job_mutex_);
  JobState j = job_;
  if (j.state == "running") j.elapsed_ms = ms_since(job_start_);
  return j;
}

void ViewSession::join_job() {
  std::thread t;
  {
    std::lock_guard<std::mutex> lock(job_mutex_);
    t = std::move(job_thread_);
  }
  if (t.joinable()) t.join();
}

}  // namespace macro::enhance::view
