// `macro grad` and `macro train` as library calls (train_job.h).
#include "gs/train/train_job.h"

#include <sys/resource.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>

#include "attention/runtime/file_io.h"
#include "attention/runtime/interrupt_note.h"
#include "attention/runtime/io/safetensors.h"
#include "attention/runtime/progress.h"
#include "attention/runtime/text.h"
#include "gs/formats/splat_params.h"
#include "gs/image_io.h"
#include "gs/train/checkpoint.h"
#include "gs/train/diff_project.h"
#include "gs/train/train_memory.h"

namespace macro::gs::train {
namespace {

// The output's folder exists and is writable, and the path is not a folder.
Status check_output(const char* flag, const std::string& path) {
  namespace fs = std::filesystem;
  if (path.empty()) return Status::error(std::string(flag) + ": required");
  const fs::path folder = fs::path(path).parent_path();
  const std::string parent = folder.empty() ? std::string(".") : folder.string();
  if (is_directory(path))
    return Status::error(std::string(flag) + ": " + path + ": is a folder, expected a file path");
  if (!is_directory(parent))
    return Status::error(std::string(flag) + ": " + path + ": folder '" + parent +
                         "' does not exist");
  if (::access(parent.c_str(), W_OK) != 0)
    return Status::error(std::string(flag) + ": " + path + ": folder '" + parent +
                         "' is not writable");
  return Status::ok();
}

std::string lower(std::string s) {
  std::transform(s.begin(), s.end(), s.begin(), [](unsigned char c) { return std::tolower(c); });
  return s;
}

bool has_extension(const std::string& name) {
  const size_t slash = name.find_last_of('/');
  const size_t dot = name.find_last_of('.');
  return dot != std::string::npos && (slash == std::string::npos || dot > slash + 1);
}

std::string json_number(double v) {
  if (!std::isfinite(v)) return "null";
  char buf[40];
  std::snprintf(buf, sizeof buf, "%.9g", v);
  return buf;
}

// A JSON string literal: quotes, backslashes and control characters escaped.
std::string json_string(const std::string& v) {
  std::string out = "\"";
  for (unsigned char c : v) {
    if (c == '"' || c == '\\') {
      out += '\\';
      out += char(c);
    } else if (c < 0x20) {
      char buf[8];
      std::snprintf(buf, sizeof buf, "\\u%04x", c);
      out += buf;
    } else {
      out += char(c);
    }
  }
  return out + "\"";
}

// Training fits pinhole renders to the photos, so a camera with distortion (whose photos are not
// undistorted) cannot be used as it is.
Status check_pinhole(const Camera& camera) {
  for (double k : camera.distortion)
    if (k != 0)
      return Status::error("camera '" + camera.name + "' has " + camera_model_name(camera.model) +
                           " distortion: training with distorted photos is not implemented yet "
                           "(undistort them and give pinhole cameras)");
  return Status::ok();
}

}  // namespace

double camera_extent_scale(const CameraSet& cameras) {
  if (cameras.cameras.empty()) return 0;
  Eigen::Vector3d mean = Eigen::Vector3d::Zero();
  for (const Camera& c : cameras.cameras) mean += c.center();
  mean /= double(cameras.cameras.size());
  double extent = 0;
  for (const Camera& c : cameras.cameras) extent = std::max(extent, (c.center() - mean).norm());
  return 1.1 * extent;
}

Result<std::string> find_view_image(const std::string& dir, const std::string& name) {
  if (!is_directory(dir)) return Status::error("--images: " + dir + ": not a folder");
  if (has_extension(name)) {
    const std::string path = dir + "/" + name;
    if (!file_exists(path))
      return Status::error("--images: no photo for camera '" + name + "': " + path +
                           " does not exist");
    return path;
  }
  std::vector<std::string> found;
  for (const char* ext : {".png", ".jpg", ".jpeg", ".exr"})
    if (file_exists(dir + "/" + name + ext)) found.push_back(dir + "/" + name + ext);
  if (found.empty())
    return Status::error("--images: no photo for camera '" + name + "': none of " + dir + "/" +
                         name + ".png, .jpg, .jpeg, .exr exists");
  if (found.size() > 1)
    return Status::error("--images: camera '" + name + "' has two photos, " + found[0] + " and " +
                         found[1] + "; expected one");
  return found[0];
}

Result<std::vector<float>> read_target(const std::string& path, int width, int height) {
  auto size_error = [&](int w, int h) {
    return Status::error(path + ": image is " + std::to_string(w) + "x" + std::to_string(h) +
                         ", expected the camera's " + std::to_string(width) + "x" +
                         std::to_string(height));
  };
  const std::string name = lower(path);
  if (name.size() > 4 && name.compare(name.size() - 4, 4, ".exr") == 0) {
    MACRO_ASSIGN_OR_RETURN(ExrImage exr, read_exr(path));
    if (exr.width != width || exr.height != height) return size_error(exr.width, exr.height);
    const std::vector<float>* ch[3] = {exr.find("R"), exr.find("G"), exr.find("B")};
    for (int c = 0; c < 3; ++c)
      if (!ch[c])
        return Status::error(path + ": EXR has no channel '" + std::string(1, "RGB"[c]) +
                             "' (expected R, G, B)");
    std::vector<float> out(size_t(width) * size_t(height) * 3);
    for (size_t p = 0; p < size_t(width) * size_t(height); ++p)
      for (int c = 0; c < 3; ++c) {
        const float v = (*ch[c])[p];
        if (!std::isfinite(v))
          return Status::error(path + ": EXR channel '" + std::string(1, "RGB"[c]) +
                               "' has a non-finite value at pixel " + std::to_string(p));
        out[3 * p + c] = v;
      }
    return out;
  }
  MACRO_ASSIGN_OR_RETURN(Image img, read_image(path));
  if (img.width != width || img.height != height) return size_error(img.width, img.height);
  MACRO_CHECK(img.channels == 3);
  return std::move(img.data);
}

Result<RasterMode> parse_raster_mode(const std::string& flag, const std::string& value) {
  if (value == "classic") return RasterMode::kClassic;
  if (value == "antialiased") return RasterMode::kAntialiased;
  if (value == "mip") return RasterMode::kMip;
  return Status::error(flag + ": expected classic, antialiased or mip, found '" + value + "'");
}

Result<GradJobResult> run_grad_job(const GradJob& job, ThreadPool& pool) {
  const auto t0 = std::chrono::steady_clock::now();
  MACRO_ASSIGN_OR_RETURN(RasterMode mode, parse_raster_mode("--mode", job.mode));
  if (job.scene_path.empty()) return Status::error("--scene: required");
  if (job.cameras_path.empty()) return Status::error("--cameras: required");
  if (job.target_path.empty()) return Status::error("--target: required");
  MACRO_TRY(check_output("--out", job.out_path));
  std::vector<float> file_filter;  // mip: recomputed from --cameras below
  auto params = read_splat_params(job.scene_path, job.limits,
                                  mode == RasterMode::kMip ? &file_filter : nullptr);
  if (!params) return params.status().with_context("--scene");
  auto cameras = load_cameras(job.cameras_path);
  if (!cameras) return cameras.status().with_context("--cameras");
  auto camera = cameras->find(job.camera_name);
  if (!camera) return camera.status().with_context("--camera " + job.camera_name);
  MACRO_TRY(check_pinhole(*camera).with_context("--cameras"));
  TrainView view;
  view.camera = *camera;
  auto target = read_target(job.target_path, camera->width, camera->height);
  if (!target) return target.status().with_context("--target");
  view.target = std::move(*target);
  DiffRenderOptions ro;
  ro.mode = mode;
  // Mip: the 3D filter of every camera of --cameras (the training cameras).
  std::vector<float> filter;
  if (mode == RasterMode::kMip) {
    filter = compute_filter_3d(*params, cameras->cameras);
    ro.filter_3d = &filter;
  }
  MACRO_ASSIGN_OR_RETURN(Precision precision, parse_precision(job.precision));
  MACRO_ASSIGN_OR_RETURN(ViewGradient vg, view_gradient(*params, view, ro, pool, precision));

  const int64_t N = int64_t(params->size()), H = camera->height, W = camera->width;
  const int64_t R = params->sh_rest();
  const float loss = float(vg.loss.loss), l1 = float(vg.loss.l1), ssim = float(vg.loss.ssim);
  const std::vector<float> color(vg.image.color.begin(), vg.image.color.end());
  const std::vector<float> alpha(vg.image.alpha.begin(), vg.image.alpha.end());
  const SplatGrads& g = vg.grads;
  MACRO_TRY(write_safetensors(job.out_path,
                              {{"loss", DType::kF32, {1}, &loss},
                               {"l1", DType::kF32, {1}, &l1},
                               {"ssim", DType::kF32, {1}, &ssim},
                               {"color", DType::kF32, {H, W, 3}, color.data()},
                               {"alpha", DType::kF32, {H, W}, alpha.data()},
                               {"grad.means", DType::kF32, {N, 3}, g.means.data()},
                               {"grad.scales", DType::kF32, {N, 3}, g.scales.data()},
                               {"grad.quats", DType::kF32, {N, 4}, g.quats.data()},
                               {"grad.opacities", DType::kF32, {N}, g.opacities.data()},
                               {"grad.sh0", DType::kF32, {N, 1, 3}, g.sh0.data()},
                               {"grad.shN", DType::kF32, {N, R, 3}, g.shN.data()},
                               {"grad.means2d", DType::kF32, {N, 2}, g.means2d.data()}},
                              {{"scene", job.scene_path},
                               {"camera", camera->name},
                               {"target", job.target_path},
                               {"mode", job.mode},
                               {"sh_degree", std::to_string(params->sh_degree)},
                               {"loss", "0.8 L1 + 0.2 (1 - SSIM valid 11x11 sigma 1.5)"}})
                .with_context("--out"));
  GradJobResult out;
  out.camera = *camera;
  out.gaussians = params->size();
  out.loss = vg.loss;
  out.ms = ms_since(t0);
  return out;
}

Status check_train_settings(const TrainJob& job) {
  if (auto p = parse_precision(job.precision); !p) return p.status();
  if (job.strategy != "none" && job.strategy != "default" && job.strategy != "mcmc")
    return Status::error("--strategy: expected default, mcmc or none, found '" + job.strategy +
                         "'");
  if (job.cap_max < 1) return Status::error("--cap-max: expected >= 1, found 0");
  if ((job.absgrad || job.grow_grad2d != 0.0002) && job.strategy != "default")
    return Status::error(
        "--absgrad / --grow-grad2d: only with --strategy default, found --strategy " +
        job.strategy);
  if (!(job.grow_grad2d > 0) || !std::isfinite(job.grow_grad2d))
    return Status::error("--grow-grad2d: expected a positive number, found " +
                         json_number(job.grow_grad2d));
  if (job.save_every < 0)
    return Status::error("--save-every: expected >= 0, found " + std::to_string(job.save_every));
  if (job.lr_schedule != "constant" && job.lr_schedule != "gsplat")
    return Status::error("--lr-schedule: expected gsplat or constant, found '" + job.lr_schedule +
                         "'");
  if (job.view_order != "sequential" && job.view_order != "shuffled")
    return Status::error("--view-order: expected shuffled or sequential, found '" + job.view_order +
                         "'");
  if (job.sh_degree_interval < 0)
    return Status::error("--sh-degree-interval: expected >= 0, found " +
                         std::to_string(job.sh_degree_interval));
  MACRO_TRY(parse_raster_mode("--mode", job.mode).status());
  if (job.data_factor < 1)
    return Status::error("--data-factor: expected >= 1, found " + std::to_string(job.data_factor));
  if (job.test_every < 0)
    return Status::error("--test-every: expected >= 0, found " + std::to_string(job.test_every));
  if (job.steps < 0)
    return Status::error("--steps: expected >= 0, found " + std::to_string(job.steps));
  if (job.scene_scale && !(*job.scene_scale > 0 && std::isfinite(*job.scene_scale)))
    return Status::error("--scene-scale: expected a positive number, found " +
                         std::to_string(*job.scene_scale));
  return Status::ok();
}

Result<TrainJobResult> run_train_job(const TrainJob& job, ThreadPool& pool) {
  MACRO_TRY(check_train_settings(job));
  const bool from_scene = !job.scene_dir.empty();
  if (!from_scene) {
    if (job.images_dir.empty()) return Status::error("--images: required (or --scene-dir)");
    if (job.cameras_path.empty()) return Status::error("--cameras: required (or --scene-dir)");
    if (job.init_path.empty()) return Status::error("--init: required");
  } else if (!job.images_dir.empty() || !job.cameras_path.empty()) {
    return Status::error("--scene-dir replaces --images and --cameras; give one or the other");
  }
  MACRO_TRY(check_output("--out", job.out_path));
  if (!job.log_path.empty()) {
    MACRO_TRY(check_output("--log", job.log_path));
    if (job.log_path == job.out_path)
      return Status::error("--log and --out are the same file " + job.out_path);
  }
  std::optional<SplatParams> params;
  std::vector<TrainView> views, test_views;
  TrainJobResult result;
  std::string views_line;  // the log's first line for --scene-dir
  if (from_scene) {
    SceneDirOptions so;
    so.data_factor = job.data_factor;
    so.test_every = job.test_every;
    const bool ply = job.init_path != "sfm" && job.init_path != "random" && !job.init_path.empty();
    so.init = ply ? "random" : (job.init_path.empty() ? "sfm" : job.init_path);
    if (ply) so.init_points = 0;
    so.seed = job.seed;
    if (job.strategy == "mcmc") so.init_opacity = 0.5, so.init_scale = 0.1;  // gsplat mcmc config
    MACRO_ASSIGN_OR_RETURN(SceneDirInputs in, load_scene_dir(job.scene_dir, so));
    if (ply) {
      // A mip-mode .ply (filter_3D) is accepted in mip mode; the filter is recomputed from the
      // training cameras, as Mip-Splatting does when training starts.
      std::vector<float> file_filter;
      auto p =
          read_splat_params(job.init_path, job.limits, job.mode == "mip" ? &file_filter : nullptr);
      if (!p) return p.status().with_context("--init");
      params = std::move(*p);
    } else {
      params = std::move(in.init);
    }
    views = std::move(in.train);
    test_views = std::move(in.test);
    result.scene_scale = in.scene_scale;
    auto names = [](const std::vector<TrainView>& vs) {
      std::string out = "[";
      for (size_t i = 0; i < vs.size(); ++i)
        out += (i ? ", " : "") + json_string(vs[i].camera.name);
      return out + "]";
    };
    views_line = "{\"scene_dir\": " + json_string(job.scene_dir) +
                 ", \"images\": " + json_string(in.images_dir) +
                 ", \"split\": " + (in.split_path.empty() ? "null" : json_string(in.split_path)) +
                 ", \"closeup_frames_skipped\": " + std::to_string(in.closeup_frames_skipped) +
                 ", \"train_views\": " + names(views) + ", \"test_views\": " + names(test_views) +
                 "}\n";
  } else {
    std::vector<float> file_filter;  // recomputed from the cameras (as above)
    auto p =
        read_splat_params(job.init_path, job.limits, job.mode == "mip" ? &file_filter : nullptr);
    if (!p) return p.status().with_context("--init");
    params = std::move(*p);
    auto cameras = load_cameras(job.cameras_path);
    if (!cameras) return cameras.status().with_context("--cameras");
    if (cameras->cameras.empty())
      return Status::error("--cameras: " + job.cameras_path + " holds no cameras");
    for (const Camera& cam : cameras->cameras)
      MACRO_TRY(check_pinhole(cam).with_context("--cameras"));
    for (const Camera& cam : cameras->cameras) {
      MACRO_ASSIGN_OR_RETURN(std::string path, find_view_image(job.images_dir, cam.name));
      auto target = read_target(path, cam.width, cam.height);
      if (!target) return target.status().with_context("--images");
      views.push_back({cam, std::move(*target)});
    }
    result.scene_scale = camera_extent_scale(*cameras);
  }
  for (const TrainView& v : views) result.train_views.push_back(v.camera.name);
  for (const TrainView& v : test_views) result.test_views.push_back(v.camera.name);
  result.initial_gaussians = params->size();
  result.gaussians = params->size();
  result.views = views.size();
  if (job.scene_scale) result.scene_scale = *job.scene_scale;
  if (!(result.scene_scale > 0))
    return Status::error("--scene-scale: not given, and the cameras' extent is " +
                         std::to_string(result.scene_scale) +
                         " (a single camera, or all at one place); pass --scene-scale");

  TrainOptions options;
  options.steps = job.steps;
  options.adam.scene_scale = result.scene_scale;
  options.exponential_lr = job.lr_schedule == "gsplat";
  options.shuffled_views = job.view_order == "shuffled";
  options.sh_degree_interval = job.sh_degree_interval;
  options.strategy = job.strategy == "default" ? Strategy::kDefault
                     : job.strategy == "mcmc"  ? Strategy::kMcmc
                                               : Strategy::kNone;
  options.default_strategy.max_gaussians = job.limits.max_gaussians;
  options.default_strategy.absgrad = job.absgrad;
  options.default_strategy.grow_grad2d = job.grow_grad2d;
  options.mcmc.cap_max = std::min(
      job.cap_max, job.limits.max_gaussians > 0 ? size_t(job.limits.max_gaussians) : job.cap_max);
  if (job.strategy == "mcmc") options.opacity_reg = options.scale_reg = 0.01;  // gsplat mcmc
  MACRO_ASSIGN_OR_RETURN(options.render.mode, parse_raster_mode("--mode", job.mode));
  options.seed = job.seed;
  MACRO_ASSIGN_OR_RETURN(options.precision, parse_precision(job.precision));

  // Checkpoints: the settings a resume must repeat, the state to continue from.
  std::string settings;
  {
    char scale[40];
    std::snprintf(scale, sizeof scale, "%.17g", result.scene_scale);
    settings = "scene_dir=" + job.scene_dir + "\nimages=" + job.images_dir +
               "\ncameras=" + job.cameras_path + "\ninit=" + job.init_path +
               "\ndata_factor=" + std::to_string(job.data_factor) +
               "\ntest_every=" + std::to_string(job.test_every) +
               "\nsteps=" + std::to_string(job.steps) + "\nstrategy=" + job.strategy +
               "\nmode=" + job.mode + "\nprecision=" + job.precision +
               "\nlr_schedule=" + job.lr_schedule + "\nview_order=" + job.view_order +
               "\nsh_degree_interval=" + std::to_string(job.sh_degree_interval) +
               "\nseed=" + std::to_string(job.seed) + "\nscene_scale=" + scale +
               "\ncap_max=" + std::to_string(options.mcmc.cap_max) +
               "\nabsgrad=" + std::to_string(int(job.absgrad)) +
               "\ngrow_grad2d=" + json_number(job.grow_grad2d) + "\nviews=";
    for (const TrainView& v : views)
      settings += v.camera.name + ":" + std::to_string(v.camera.width) + "x" +
                  std::to_string(v.camera.height) + ",";
    settings += "\n";
  }
  std::optional<Checkpoint> resume;
  TrainHooks hooks;
  if (!job.resume_path.empty()) {
    MACRO_ASSIGN_OR_RETURN(Checkpoint ck, read_checkpoint(job.resume_path, settings));
    if (ck.state.next_step > job.steps)
      return Status::error("--resume: " + job.resume_path + ": the checkpoint is at step " +
                           std::to_string(ck.state.next_step) + ", beyond --steps " +
                           std::to_string(job.steps));
    if (job.limits.max_gaussians > 0 && ck.params.size() > job.limits.max_gaussians)
      return Status::error(
          "--resume: " + job.resume_path + ": " + std::to_string(ck.params.size()) +
          " Gaussians, more than --max-gaussians " + std::to_string(job.limits.max_gaussians));
    resume = std::move(ck);
    params = std::move(resume->params);
    hooks.resume = &resume->state;
  }
  const int first_step = resume ? resume->state.next_step : 0;
  const std::string ckpt_path = checkpoint_path_for(job.out_path);
  if (job.save_every > 0) {
    MACRO_TRY(check_output("--save-every", ckpt_path));
    hooks.checkpoint_every = job.save_every;
    hooks.checkpoint = [&](const SplatParams& p, const TrainState& st) -> Status {
      MACRO_TRY(write_checkpoint(ckpt_path, settings, p, st).with_context("--save-every"));
      set_interrupt_note("the checkpoint " + ckpt_path + " (step " + std::to_string(st.next_step) +
                         " of " + std::to_string(job.steps) +
                         ") was kept: continue with the same flags and --resume " + ckpt_path +
                         "\n");
      return Status::ok();
    };
  }
  AtomicFile log;
  if (!job.log_path.empty()) MACRO_TRY(log.open(job.log_path).with_context("--log"));
  if (!job.log_path.empty() && !views_line.empty())
    MACRO_TRY(log.write(views_line).with_context("--log"));
  const bool show = job.progress && !quiet();
  {
    size_t largest = 0, photo_pixels = 0;
    for (const auto* set : {&views, &test_views})
      for (const TrainView& v : *set) {
        const size_t px = size_t(v.camera.width) * size_t(v.camera.height);
        largest = std::max(largest, px);
        photo_pixels += px;
      }
    result.memory = train_memory(params->size(), params->sh_degree, largest, photo_pixels);
    if (show) {
      const size_t cap = job.limits.max_gaussians;
      std::fprintf(stderr, "[train] memory: %s; at most %s before pairs (--max-gaussians %zu)\n",
                   describe(result.memory).c_str(),
                   format_bytes(result.memory.fixed_at(cap)).c_str(), cap);
    }
  }
  auto last_draw = std::chrono::steady_clock::now() - std::chrono::seconds(1);
  auto on_step = [&](const StepRecord& r) -> Status {
    result.records.push_back(r);
    if (!job.log_path.empty()) {
      const std::string line =
          "{\"step\": " + std::to_string(r.step) + ", \"loss\": " + json_number(r.loss) +
          ", \"l1\": " + json_number(r.l1) + ", \"ssim\": " + json_number(r.ssim) +
          ", \"num_gaussians\": " + std::to_string(r.num_gaussians) +
          ", \"view\": " + json_string(views[r.view].camera.name) +
          ", \"sh_degree\": " + std::to_string(r.sh_degree) +
          ", \"means_lr\": " + json_number(r.means_lr) +
          (r.refine.refined ? ", \"duplicated\": " + std::to_string(r.refine.duplicated) +
                                  ", \"split\": " + std::to_string(r.refine.split) +
                                  ", \"pruned\": " + std::to_string(r.refine.pruned)
                            : std::string()) +
          (r.refine.reset ? ", \"opacity_reset\": true" : "") +
          (r.mcmc.refined ? ", \"relocated\": " + std::to_string(r.mcmc.relocated) +
                                ", \"added\": " + std::to_string(r.mcmc.added)
                          : std::string()) +
          ", \"psnr\": " + json_number(r.psnr) + ", \"seconds\": " + json_number(r.seconds) + "}\n";
      MACRO_TRY(log.write(line).with_context("--log"));
    }
    const auto now = std::chrono::steady_clock::now();
    const bool final_step = r.step + 1 == job.steps;
    if (show && (final_step || now - last_draw >= std::chrono::milliseconds(250))) {
      last_draw = now;
      const double rate = r.seconds > 0 ? double(r.step + 1 - first_step) / r.seconds : 0;
      const double eta = rate > 0 ? double(job.steps - r.step - 1) / rate : -1;
      std::fprintf(stderr,
                   "\r[train] step %d/%d  loss %.5f  psnr %.2f dB  %zu gaussians  %.2f it/s  "
                   "eta %s%s",
                   r.step + 1, job.steps, r.loss, r.psnr, r.num_gaussians, rate,
                   format_seconds(eta).c_str(), final_step ? "\n" : "   ");
      std::fflush(stderr);
    }
    return Status::ok();
  };
  MACRO_TRY(train(&*params, views, options, on_step, pool, hooks));
  result.gaussians = params->size();
  if (!test_views.empty()) {
    MACRO_ASSIGN_OR_RETURN(EvalResult ev, evaluate_views(*params, test_views, pool));
    result.evaluated = true;
    result.test_psnr = ev.psnr;
    result.test_ssim = ev.ssim;
    if (!job.log_path.empty()) {
      std::string line = "{\"eval\": \"test\", \"psnr\": " + json_number(ev.psnr) +
                         ", \"ssim\": " + json_number(ev.ssim) + ", \"views\": [";
      for (size_t i = 0; i < test_views.size(); ++i)
        line += std::string(i ? ", " : "") +
                "{\"name\": " + json_string(test_views[i].camera.name) +
                ", \"psnr\": " + json_number(ev.view_psnr[i]) +
                ", \"ssim\": " + json_number(ev.view_ssim[i]) + "}";
      MACRO_TRY(log.write(line + "]}\n").with_context("--log"));
    }
  }
  // Mip: the 3D filter of the trained Gaussians from the training cameras goes into the .ply
  // (filter_3D, as Mip-Splatting saves it), so renderers apply it.
  const bool mip = options.render.mode == RasterMode::kMip;
  std::vector<float> out_filter;
  if (mip) {
    std::vector<Camera> cams;
    for (const TrainView& v : views) cams.push_back(v.camera);
    out_filter = compute_filter_3d(*params, cams);
  }
  MACRO_TRY(
      write_splat_params(*params, job.out_path, mip ? &out_filter : nullptr).with_context("--out"));
  if (!job.log_path.empty()) MACRO_TRY(log.commit().with_context("--log"));
  result.seconds = result.records.empty() ? 0 : result.records.back().seconds;
  rusage ru{};
  if (getrusage(RUSAGE_SELF, &ru) == 0) result.peak_resident_bytes = size_t(ru.ru_maxrss) * 1024;
  if (show)
    std::fprintf(stderr, "[train] peak memory (resident): %s; %zu Gaussians x %zu B = %s\n",
                 format_bytes(result.peak_resident_bytes).c_str(), result.gaussians,
                 result.memory.per_gaussian,
                 format_bytes(uint64_t(result.gaussians) * result.memory.per_gaussian).c_str());
  return result;
}

}  // namespace macro::gs::train
