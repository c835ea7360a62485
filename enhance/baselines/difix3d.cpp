// Difix3D's progressive 3D update for one close-up (difix3d.h).
#include "enhance/baselines/difix3d.h"

#include <unistd.h>

#include <atomic>
#include <chrono>
#include <filesystem>
#include <system_error>

#include "attention/runtime/progress.h"
#include "enhance/baselines/progressive_cameras.h"
#include "gs/raster/rasterizer.h"
#include "gs/train/train_job.h"
#include "gs/train/trainer.h"

namespace macro::enhance {
namespace {

using Clock = std::chrono::steady_clock;

double seconds_since(Clock::time_point t0) {
  return std::chrono::duration<double>(Clock::now() - t0).count();
}

// A folder for the enhanced novel images (PR-Difix3D's references are files, as the release
// writes its fixed images), removed with everything in it when the run ends.
class ScratchDir {
 public:
  Status create() {
    static std::atomic<int> counter{0};
    std::error_code ec;
    const auto base = std::filesystem::temp_directory_path(ec);
    if (ec) return Status::error("difix3d: no temporary folder: " + ec.message());
    path_ =
        (base / ("macro-difix3d-" + std::to_string(::getpid()) + "-" + std::to_string(counter++)))
            .string();
    std::filesystem::remove_all(path_, ec);
    if (!std::filesystem::create_directory(path_, ec))
      return Status::error("difix3d: cannot create " + path_ + ": " + ec.message());
    return Status::ok();
  }
  ~ScratchDir() {
    if (path_.empty()) return;
    std::error_code ec;
    std::filesystem::remove_all(path_, ec);
  }
  const std::string& path() const { return path_; }

 private:
  std::string path_;
};

// The reference candidates a fix may use: the training photos, and (PR-Difix3D) the enhanced
// novel images of earlier rounds.
struct References {
  std::vector<gs::Camera> cameras;
  std::vector<std::string> images;
};

Result<EnhanceResult> enhance_one(const gs::GaussianCloud& cloud, const gs::Camera& camera,
                                  const References& refs, int ref, const std::string& scene_path,
                                  const Difix3dOptions& o, ThreadPool* pool) {
  SceneInputs in;
  in.scene_path = scene_path + " (fine-tuned)";
  in.closeup_source = "difix3d";
  in.cloud = cloud;
  in.closeup = camera;
  in.closeup_pose_source = "given";
  in.candidates = {refs.cameras[size_t(ref)]};
  in.candidate_images = {refs.images[size_t(ref)]};
  EnhanceOptions e;
  e.method = EnhanceMethod::kDifix;
  e.plan.refs = 1;
  e.weights = o.weights;
  e.ctx_path = o.ctx_path;
  e.precision = o.precision;
  e.enhancer = o.weights.empty() ? Enhancer::kTransfer : Enhancer::kDifix;
  e.transfer.source = TransferSource::kWhole;
  e.pool = pool;
  return enhance_closeup(in, e);
}

}  // namespace

struct Difix3dRun::State {
  Difix3dOptions options;
  std::string scene_path;
  gs::Camera closeup;
  gs::GaussianCloud tuned;
  References refs;
  ScratchDir scratch;
  bool enhanced = false;
};

Difix3dRun::~Difix3dRun() = default;

Result<std::unique_ptr<Difix3dRun>> Difix3dRun::run(const SceneInputs& inputs,
                                                    const Difix3dOptions& o) {
  using gs::train::TrainView;
  if (o.rounds < 1 || o.rounds > 1000)
    return Status::error("difix3d: rounds " + std::to_string(o.rounds) + ", expected 1..1000");
  if (o.round_steps < 1 || o.round_steps > 1000000)
    return Status::error("difix3d: round steps " + std::to_string(o.round_steps) +
                         ", expected 1..1000000");
  if (!(o.pose_step > 0))
    return Status::error("difix3d: pose step " + std::to_string(o.pose_step) + ", expected > 0");
  if (inputs.candidates.empty())
    return Status::error("difix3d: no training photos among the reference candidates");
  ThreadPool* pool = o.pool ? o.pool : &ThreadPool::global();
  const bool show = o.progress && !quiet();
  MACRO_ASSIGN_OR_RETURN(gs::SplatParams params, gs::from_cloud(inputs.cloud, inputs.scene_path));

  // The photos, at their cameras' sizes, loss weight real_weight.
  std::vector<TrainView> photos;
  gs::CameraSet training;
  for (size_t k = 0; k < inputs.candidates.size(); ++k) {
    MACRO_ASSIGN_OR_RETURN(gs::Image img, load_candidate_image(inputs, int(k)));
    TrainView v;
    v.camera = inputs.candidates[k];
    v.target = std::move(img.data);
    v.loss_weight = o.real_weight;
    photos.push_back(std::move(v));
    training.cameras.push_back(inputs.candidates[k]);
  }
  double scene_scale = gs::train::camera_extent_scale(training);
  if (!(scene_scale > 0)) scene_scale = 1;  // one training camera: gsplat's extent is 0

  const auto schedule =
      progressive_schedule(training.cameras, {inputs.closeup}, o.rounds, o.pose_step);
  std::unique_ptr<Difix3dRun> run(new Difix3dRun);
  run->state_ = std::make_unique<State>();
  State& st = *run->state_;
  st.options = o;
  st.scene_path = inputs.scene_path;
  st.closeup = inputs.closeup;
  Difix3dResult& res = run->result_;
  res.enhancer = enhancer_label(o.weights.empty() ? Enhancer::kTransfer : Enhancer::kDifix);
  st.refs = {training.cameras, inputs.candidate_images};
  References& refs = st.refs;
  ScratchDir& scratch = st.scratch;
  if (o.progressive_reference) MACRO_TRY(scratch.create());

  gs::train::TrainOptions t;
  t.steps = o.rounds * o.round_steps;
  t.adam.scene_scale = scene_scale;
  t.exponential_lr = true;
  t.lr_schedule_steps = 2 * t.steps;
  t.shuffled_views = true;
  t.sh_degree_interval = 0;
  t.strategy = gs::train::Strategy::kNone;
  t.seed = o.seed;
  gs::train::TrainHooks hooks;
  hooks.novel.every = o.round_steps;
  hooks.novel.real_probability = o.real_probability;
  const auto t_start = Clock::now();
  double fix_seconds = 0;
  hooks.novel.refresh = [&](int step, const gs::SplatParams& p,
                            std::vector<TrainView>* novel) -> Status {
    const auto t0 = Clock::now();
    const int round = step / o.round_steps;
    const gs::Camera& cam = schedule[size_t(round)][0];
    const gs::GaussianCloud cloud = gs::to_cloud(p);
    gs::RenderOptions ro;  // classic, black background
    MACRO_ASSIGN_OR_RETURN(gs::RenderResult r, gs::render(cloud, cam, ro));
    const int ref = nearest_pose(cam, refs.cameras);
    res.seconds_fix_render += seconds_since(t0);
    const auto t1 = Clock::now();
    MACRO_ASSIGN_OR_RETURN(EnhanceResult e,
                           enhance_one(cloud, cam, refs, ref, inputs.scene_path, o, pool));
    res.seconds_fix_enhance += seconds_since(t1);
    if (e.image.width != cam.width || e.image.height != cam.height)
      return Status::error("difix3d: the enhancer returned " + std::to_string(e.image.width) + "x" +
                           std::to_string(e.image.height) + " for a " + std::to_string(cam.width) +
                           "x" + std::to_string(cam.height) + " novel view");
    TrainView v;
    v.camera = cam;
    v.target = e.image.data;
    v.loss_weight = o.novel_weight;
    v.mask.resize(r.alpha.size());
    size_t inside = 0;
    for (size_t i = 0; i < r.alpha.size(); ++i) {
      v.mask[i] = r.alpha[i] > o.mask_opacity ? 1.f : 0.f;
      inside += v.mask[i] != 0.f;
    }
    Difix3dRound rr;
    rr.camera = cam;
    rr.reference = refs.cameras[size_t(ref)].name;
    rr.mask_fraction = r.alpha.empty() ? 0 : double(inside) / double(r.alpha.size());
    res.rounds.push_back(rr);
    if (o.progressive_reference) {
      const std::string path = scratch.path() + "/round_" + std::to_string(round) + ".png";
      MACRO_TRY(gs::write_png(path, e.image));
      refs.cameras.push_back(cam);
      refs.images.push_back(path);
    }
    novel->clear();
    novel->push_back(std::move(v));
    fix_seconds += seconds_since(t0);
    if (show)
      log_info("difix3d", "round " + std::to_string(round + 1) + "/" + std::to_string(o.rounds) +
                              ": novel view " + cam.name + ", reference " + rr.reference + ", " +
                              std::to_string(int(100 * rr.mask_fraction + 0.5)) + "% masked in, " +
                              std::to_string(seconds_since(t_start)) + " s so far");
    return Status::ok();
  };
  MACRO_TRY(gs::train::train(&params, photos, t, {}, *pool, hooks).with_context("difix3d"));
  res.seconds_finetune = seconds_since(t_start) - fix_seconds;
  res.finetune_steps = t.steps;
  res.gaussians = params.size();

  const auto t2 = Clock::now();
  st.tuned = gs::to_cloud(params);
  gs::RenderOptions ro;
  MACRO_ASSIGN_OR_RETURN(gs::RenderResult final_render, gs::render(st.tuned, inputs.closeup, ro));
  // The 8-bit PNG levels of the render, as the release saves and reloads it.
  res.render =
      gs::png_levels_image(final_render.color.data(), final_render.width, final_render.height);
  res.seconds_final_render = seconds_since(t2);
  return run;
}

Result<const Difix3dResult*> Difix3dRun::enhance_final() {
  State& st = *state_;
  if (st.enhanced) return &result_;
  const auto t0 = Clock::now();
  ThreadPool* pool = st.options.pool ? st.options.pool : &ThreadPool::global();
  const int ref = nearest_pose(st.closeup, st.refs.cameras);
  MACRO_ASSIGN_OR_RETURN(EnhanceResult e, enhance_one(st.tuned, st.closeup, st.refs, ref,
                                                      st.scene_path, st.options, pool));
  result_.enhanced = std::move(e.image);
  result_.final_reference = st.refs.cameras[size_t(ref)].name;
  result_.seconds_final_enhance = seconds_since(t0);
  st.enhanced = true;
  return &result_;
}

}  // namespace macro::enhance
