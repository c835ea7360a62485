// A COLMAP scene folder as gsplat reads it (scene_inputs.h).
#include "gs/train/scene_inputs.h"

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <numeric>

#include "attention/runtime/file_io.h"
#include "gs/cameras/camera.h"
#include "gs/image_io.h"
#include "gs/synth/synth_random.h"
#include "gs/train/loss.h"
#include "gs/train/train_job.h"

namespace macro::gs::train {
namespace {

constexpr double kC0 = 0.28209479177387814;

// The photo of `name` in `dir`: DIR/NAME, else the same stem with a common image extension.
Result<std::string> photo_path(const std::string& dir, const std::string& name) {
  if (file_exists(dir + "/" + name)) return dir + "/" + name;
  const std::string stem = std::filesystem::path(name).replace_extension().string();
  for (const char* ext : {".png", ".jpg", ".jpeg", ".JPG", ".PNG", ".JPEG"})
    if (file_exists(dir + "/" + stem + ext)) return dir + "/" + stem + ext;
  return Status::error("--scene-dir: no photo for image '" + name + "' in " + dir + " (tried " +
                       name + " and " + stem + ".png/.jpg/.jpeg)");
}

// Box average to out_w x out_h (each output pixel the mean of the source pixels it covers).
Image box_downscale(const Image& src, int out_w, int out_h) {
  Image out(out_w, out_h, 3);
  const double sx = double(src.width) / out_w, sy = double(src.height) / out_h;
  for (int i = 0; i < out_h; ++i) {
    const int y0 = int(std::floor(i * sy)), y1 = std::max(y0 + 1, int(std::floor((i + 1) * sy)));
    for (int j = 0; j < out_w; ++j) {
      const int x0 = int(std::floor(j * sx)), x1 = std::max(x0 + 1, int(std::floor((j + 1) * sx)));
      double acc[3] = {0, 0, 0};
      int n = 0;
      for (int y = y0; y < std::min(y1, src.height); ++y)
        for (int x = x0; x < std::min(x1, src.width); ++x, ++n)
          for (int c = 0; c < 3; ++c) acc[c] += src.at(y, x, c);
      for (int c = 0; c < 3; ++c) out.at(i, j, c) = float(acc[c] / std::max(n, 1));
    }
  }
  return out;
}

float logit(double p) {
  return float(std::log(p / (1 - p)));
}

void fill_common(SplatParams* p, const std::vector<double>& dist, synth_random::Rng& rng,
                 double init_opacity, double init_scale) {
  const size_t n = p->size();
  for (size_t i = 0; i < n; ++i) {
    // A lone point (or duplicates at distance 0) gets the smallest positive scale, not log(0).
    const double d = (dist[i] > 0 ? dist[i] : 1e-7) * init_scale;
    for (int a = 0; a < 3; ++a) p->scales[3 * i + a] = float(std::log(d));
    for (int a = 0; a < 4; ++a) p->quats[4 * i + a] = float(rng.uniform());
    if (p->quats[4 * i] == 0 && p->quats[4 * i + 1] == 0 && p->quats[4 * i + 2] == 0 &&
        p->quats[4 * i + 3] == 0)
      p->quats[4 * i] = 1;  // probability 2^-212; a zero quaternion is not a rotation
    p->opacities[i] = logit(init_opacity);
  }
}

}  // namespace

std::vector<bool> test_every_holdout(size_t count, int test_every) {
  std::vector<bool> test(count, false);
  if (test_every <= 0) return test;
  for (size_t i = 0; i < count; ++i) test[i] = i % size_t(test_every) == 0;
  return test;
}

std::vector<double> knn_mean_distance(const std::vector<Eigen::Vector3d>& pts, int k) {
  const size_t n = pts.size();
  std::vector<double> out(n, 0.0);
  std::vector<size_t> order(n);
  std::iota(order.begin(), order.end(), size_t(0));
  std::sort(order.begin(), order.end(), [&](size_t a, size_t b) {
    return pts[a].x() < pts[b].x() || (pts[a].x() == pts[b].x() && a < b);
  });
  std::vector<double> best;  // the k smallest squared distances, ascending
  for (size_t oi = 0; oi < n; ++oi) {
    const Eigen::Vector3d& p = pts[order[oi]];
    best.clear();
    auto offer = [&](size_t oj) {
      const double d2 = (pts[order[oj]] - p).squaredNorm();
      if (int(best.size()) < k) {
        best.insert(std::upper_bound(best.begin(), best.end(), d2), d2);
      } else if (d2 < best.back()) {
        best.pop_back();
        best.insert(std::upper_bound(best.begin(), best.end(), d2), d2);
      }
    };
    // Sweep outwards along x until the x gap alone exceeds the k-th best distance.
    for (size_t oj = oi + 1; oj < n; ++oj) {
      const double dx = pts[order[oj]].x() - p.x();
      if (int(best.size()) == k && dx * dx >= best.back()) break;
      offer(oj);
    }
    for (size_t oj = oi; oj-- > 0;) {
      const double dx = p.x() - pts[order[oj]].x();
      if (int(best.size()) == k && dx * dx >= best.back()) break;
      offer(oj);
    }
    if (best.empty()) continue;
    out[order[oi]] =
        std::sqrt(std::accumulate(best.begin(), best.end(), 0.0) / double(best.size()));
  }
  return out;
}

SplatParams init_from_points(const ColmapPoints& points, int sh_degree, uint64_t seed,
                             double init_opacity, double init_scale) {
  SplatParams p;
  p.resize(points.size(), sh_degree);
  for (size_t i = 0; i < points.size(); ++i) {
    for (int a = 0; a < 3; ++a) p.means[3 * i + a] = float(points.xyz[i](a));
    for (int c = 0; c < 3; ++c)
      p.sh0[3 * i + c] = float((double(points.rgb[3 * i + c]) / 255.0 - 0.5) / kC0);
  }
  synth_random::Rng rng{seed};
  fill_common(&p, knn_mean_distance(points.xyz, 3), rng, init_opacity, init_scale);
  return p;
}

SplatParams init_random(size_t n, double half_extent, int sh_degree, uint64_t seed,
                        double init_opacity, double init_scale) {
  SplatParams p;
  p.resize(n, sh_degree);
  synth_random::Rng rng{seed};
  std::vector<Eigen::Vector3d> xyz(n);
  for (size_t i = 0; i < n; ++i) {
    for (int a = 0; a < 3; ++a) {
      xyz[i](a) = half_extent * (rng.uniform() * 2 - 1);
      p.means[3 * i + a] = float(xyz[i](a));
    }
    for (int c = 0; c < 3; ++c) p.sh0[3 * i + c] = float((rng.uniform() - 0.5) / kC0);
  }
  fill_common(&p, knn_mean_distance(xyz, 3), rng, init_opacity, init_scale);
  return p;
}

Result<SceneDirInputs> load_scene_dir(const std::string& dir, const SceneDirOptions& o) {
  if (!is_directory(dir)) return Status::error("--scene-dir: " + dir + ": not a folder");
  if (o.data_factor < 1)
    return Status::error("--data-factor: expected >= 1, found " + std::to_string(o.data_factor));
  if (o.init != "sfm" && o.init != "random")
    return Status::error("--init: expected sfm or random, found '" + o.init + "'");
  MACRO_ASSIGN_OR_RETURN(std::string model, find_colmap_model_folder(dir));
  auto cams = load_colmap_sparse(model);
  if (!cams) return cams.status().with_context("--scene-dir");
  if (cams->cameras.empty()) return Status::error("--scene-dir: " + model + " holds no images");
  std::vector<Camera> all = cams->cameras;
  std::sort(all.begin(), all.end(),
            [](const Camera& a, const Camera& b) { return a.name < b.name; });
  SceneDirInputs in;
  // The scene scale over every registered image (gsplat's parser uses all of them).
  {
    CameraSet set;
    set.cameras = all;
    in.scene_scale = camera_extent_scale(set);
  }
  // Which frames train and which test.
  std::vector<int> role(all.size(), 0);  // 0 train, 1 test, -1 unused
  const std::string split = dir + "/split.json";
  if (file_exists(split)) {
    auto sp = load_closeup_split(split);
    if (!sp) return sp.status().with_context("--scene-dir");
    in.split_path = split;
    auto stem = [](const std::string& s) {
      return std::filesystem::path(s).filename().replace_extension().string();
    };
    for (size_t i = 0; i < all.size(); ++i) {
      const std::string s = stem(all[i].name);
      bool train = false, closeup = false;
      for (const std::string& f : sp->training_frames) train = train || stem(f) == s;
      for (const std::string& f : sp->closeup_frames) closeup = closeup || stem(f) == s;
      for (const CloseupEvalPair& pr : sp->closeup_eval_pairs)
        closeup = closeup || stem(pr.closeup_frame) == s;
      role[i] = closeup ? -1 : train ? 0 : -1;
      in.closeup_frames_skipped += closeup;
    }
  } else {
    const std::vector<bool> test = test_every_holdout(all.size(), o.test_every);
    for (size_t i = 0; i < all.size(); ++i) role[i] = test[i] ? 1 : 0;
  }
  // Photos.
  const int F = o.data_factor;
  const std::string scaled = dir + "/images_" + std::to_string(F);
  const bool have_scaled = F > 1 && is_directory(scaled);
  in.images_dir = have_scaled ? scaled : dir + "/images";
  if (!is_directory(in.images_dir))
    return Status::error("--scene-dir: " + in.images_dir + ": not a folder");
  for (size_t i = 0; i < all.size(); ++i) {
    if (role[i] < 0) continue;
    Camera cam = all[i];
    for (double k : cam.distortion)
      if (k != 0)
        return Status::error("--scene-dir: image '" + cam.name + "' has " +
                             camera_model_name(cam.model) +
                             " distortion: training with distorted photos is not implemented yet");
    MACRO_ASSIGN_OR_RETURN(std::string path, photo_path(in.images_dir, cam.name));
    auto img = read_image(path);
    if (!img) return img.status().with_context("--scene-dir");
    Image photo = std::move(*img);
    const int want_w = int(std::lround(double(cam.width) / F)),
              want_h = int(std::lround(double(cam.height) / F));
    if (F > 1 && !have_scaled) {
      if (photo.width != cam.width || photo.height != cam.height)
        return Status::error(path + ": image is " + std::to_string(photo.width) + "x" +
                             std::to_string(photo.height) + ", expected the COLMAP camera's " +
                             std::to_string(cam.width) + "x" + std::to_string(cam.height));
      photo = box_downscale(photo, want_w, want_h);
    }
    if (std::abs(photo.width - want_w) > 1 || std::abs(photo.height - want_h) > 1)
      return Status::error(path + ": image is " + std::to_string(photo.width) + "x" +
                           std::to_string(photo.height) + ", expected about " +
                           std::to_string(want_w) + "x" + std::to_string(want_h) +
                           " (the COLMAP camera / --data-factor " + std::to_string(F) + ")");
    cam.fx /= F;
    cam.fy /= F;
    cam.cx /= F;
    cam.cy /= F;
    cam.width = photo.width;
    cam.height = photo.height;
    (role[i] == 1 ? in.test : in.train).push_back({cam, std::move(photo.data)});
  }
  if (in.train.empty())
    return Status::error("--scene-dir: no training views (" + std::to_string(all.size()) +
                         " images" + (in.split_path.empty() ? "" : ", split " + in.split_path) +
                         ")");
  if (o.init == "sfm") {
    auto pts = load_colmap_points(model);
    if (!pts) return pts.status().with_context("--init sfm");
    if (pts->size() == 0)
      return Status::error("--init sfm: " + pts->source + " holds no points (use --init random)");
    in.init = init_from_points(*pts, o.sh_degree, o.seed, o.init_opacity, o.init_scale);
  } else {
    in.init = init_random(o.init_points, o.init_extent * in.scene_scale, o.sh_degree, o.seed,
                          o.init_opacity, o.init_scale);
  }
  return in;
}

Result<EvalResult> evaluate_views(const SplatParams& params, const std::vector<TrainView>& views,
                                  ThreadPool& pool) {
  EvalResult r;
  DiffRenderer renderer;
  DiffImage img;
  std::vector<double> unused;
  for (const TrainView& v : views) {
    MACRO_TRY(renderer.forward(params, v.camera, {}, &img, pool).with_context(v.camera.name));
    std::vector<float> clamped(img.color.size());
    double se = 0;
    for (size_t i = 0; i < clamped.size(); ++i) {
      clamped[i] = float(std::clamp(img.color[i], 0.0, 1.0));
      const double d = double(clamped[i]) - double(v.target[i]);
      se += d * d;
    }
    const double mse = se / double(std::max<size_t>(clamped.size(), 1));
    r.view_psnr.push_back(mse > 0 ? -10 * std::log10(mse) : 99.0);
    std::vector<double> c(clamped.begin(), clamped.end());
    MACRO_ASSIGN_OR_RETURN(LossValue lv, photometric_loss(c.data(), v.target.data(), img.width,
                                                          img.height, nullptr, pool));
    r.view_ssim.push_back(lv.ssim);
  }
  if (!views.empty()) {
    r.psnr = std::accumulate(r.view_psnr.begin(), r.view_psnr.end(), 0.0) / double(views.size());
    r.ssim = std::accumulate(r.view_ssim.begin(), r.view_ssim.end(), 0.0) / double(views.size());
  }
  return r;
}

}  // namespace macro::gs::train
