// The training report (train_report.h, docs/training.md §7).
#include "enhance/train_report.h"

#include <nlohmann/json.hpp>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>

#include "attention/runtime/file_io.h"
#include "attention/runtime/progress.h"
#include "enhance/figures/line_chart.h"
#include "enhance/figures/side_by_side.h"
#include "enhance/metrics/metrics.h"
#include "gs/formats/splat_params.h"
#include "gs/image_io.h"
#include "gs/raster/rasterizer.h"
#include "gs/raster/render_job.h"
#include "gs/train/diff_project.h"
#include "gs/train/scene_inputs.h"

namespace macro::enhance {
namespace {

using Json = nlohmann::ordered_json;

std::string fmt(const char* f, double v) {
  char buf[64];
  std::snprintf(buf, sizeof buf, f, v);
  return buf;
}

// A number field of a log line: the value, NaN for null (a non-finite value), an error otherwise.
Result<double> number_field(const Json& j, const char* key, const std::string& where) {
  auto it = j.find(key);
  if (it == j.end())
    return Status::error(where + ": a step line without \"" + key + "\" (expected a number)");
  if (it->is_null()) return double(NAN);
  if (!it->is_number())
    return Status::error(where + ": \"" + key + "\": expected a number, found " + it->dump());
  return it->get<double>();
}

Result<std::vector<std::string>> name_list(const Json& j, const char* key,
                                           const std::string& where) {
  auto it = j.find(key);
  if (it == j.end() || !it->is_array())
    return Status::error(where + ": \"" + key + "\": expected a list of image names");
  std::vector<std::string> out;
  for (const Json& v : *it) {
    if (!v.is_string())
      return Status::error(where + ": \"" + key + "\": expected image names, found " + v.dump());
    out.push_back(v.get<std::string>());
  }
  return out;
}

std::string join(const std::vector<std::string>& v) {
  std::string s;
  for (size_t i = 0; i < v.size(); ++i) s += (i ? ", " : "") + v[i];
  return s.empty() ? "none" : s;
}

// The model as the rasterizer draws it in `mode`; mip folds in the 3D filter of the training
// cameras (gs/train/diff_project.h: s' = sqrt(s^2 + f^2), opacity x prod s / prod s').
gs::GaussianCloud model_cloud(const gs::SplatParams& p, gs::RasterMode mode,
                              const std::vector<gs::Camera>& train_cameras) {
  gs::GaussianCloud cloud = gs::to_cloud(p);
  if (mode != gs::RasterMode::kMip || train_cameras.empty()) return cloud;
  const std::vector<float> f = gs::train::compute_filter_3d(p, train_cameras);
  for (size_t g = 0; g < cloud.size(); ++g) {
    double ratio = 1;
    for (int a = 0; a < 3; ++a) {
      float& s = cloud.scale[3 * g + a];
      const float s2 = std::sqrt(s * s + f[g] * f[g]);
      ratio *= s2 > 0 ? double(s) / double(s2) : 1.0;
      s = s2;
    }
    cloud.opacity[g] = float(double(cloud.opacity[g]) * ratio);
  }
  cloud.mip_filter_3d_applied = true;
  return cloud;
}

struct Rendered {
  gs::Image image;
  double psnr = 0, ssim = 0;
  float max_alpha = 0;
};

Result<Rendered> render_view(const gs::GaussianCloud& cloud, const gs::Camera& camera,
                             const gs::Image& photo, gs::RasterMode mode, ThreadPool& pool) {
  gs::RenderOptions ro;
  ro.mode = mode;
  ro.sh_degree_cap = cloud.sh_degree;
  MACRO_ASSIGN_OR_RETURN(gs::RenderResult r, gs::render(cloud, camera, ro, pool));
  Rendered out;
  // The render as the 8-bit PNG holds it: what the figure shows and the metrics are computed on.
  out.image = gs::png_levels_image(r.color.data(), r.width, r.height);
  for (float a : r.alpha) out.max_alpha = std::max(out.max_alpha, a);
  MACRO_ASSIGN_OR_RETURN(out.psnr, psnr(out.image, photo));
  MACRO_ASSIGN_OR_RETURN(out.ssim, ssim(out.image, photo, {}, pool));
  return out;
}

// Figure-safe file name part of an image name: its stem, other than [A-Za-z0-9._-] as '_'.
std::string file_part(const std::string& name) {
  std::string stem = std::filesystem::path(name).stem().string();
  for (char& c : stem)
    if (!std::isalnum(static_cast<unsigned char>(c)) && c != '.' && c != '-' && c != '_') c = '_';
  return stem.empty() ? "view" : stem;
}

Json metric_json(double psnr, double ssim) {
  Json j;
  j["psnr"] = std::isfinite(psnr) ? Json(psnr) : Json(nullptr);
  j["ssim"] = std::isfinite(ssim) ? Json(ssim) : Json(nullptr);
  return j;
}

std::vector<Chart> curves(const TrainLog& log, const TrainReportJob& job,
                          const TrainReportResult& res) {
  std::vector<double> loss, psnr;
  for (const TrainLogStep& s : log.steps) loss.push_back(s.loss), psnr.push_back(s.psnr);
  const std::vector<double> loss_s = running_mean(loss, job.smooth),
                            psnr_s = running_mean(psnr, job.smooth);
  auto series = [&](const std::vector<double>& y) {
    std::vector<std::pair<double, double>> pts;
    for (size_t i = 0; i < y.size(); ++i) pts.push_back({double(log.steps[i].step + 1), y[i]});
    return pts;
  };
  const std::string smooth = "line: running mean of the last " + std::to_string(job.smooth) +
                             " steps (fewer at the start); faint: each step";
  const uint32_t blue = chart_palette(0), orange = chart_palette(1);
  LineChartSpec l;
  l.text = {"Training loss", smooth, "step", "loss (0.8 L1 + 0.2 (1 \u2212 SSIM))"};
  l.series = {{"", series(loss), blue, 1.0, 0.25}, {"running mean", series(loss_s), blue, 2.0}};
  LineChartSpec p;
  p.text = {"Training-view PSNR", smooth + "; dot: held-out mean", "step",
            "PSNR (dB, higher is better)"};
  p.series = {{"", series(psnr), blue, 1.0, 0.25},
              {"training view, running mean", series(psnr_s), blue, 2.0}};
  if (!res.views.empty())
    p.series.push_back({"held-out mean (" + std::to_string(res.views.size()) + " views)",
                        {{double(res.final_step), res.mean_psnr}},
                        orange,
                        1.8,
                        1,
                        true});
  std::vector<double> g;
  double gmax = 0;
  for (const TrainLogStep& s : log.steps) gmax = std::max(gmax, double(s.num_gaussians));
  const double unit = gmax >= 1e6 ? 1e6 : gmax >= 1e4 ? 1e3 : 1;
  for (const TrainLogStep& s : log.steps) g.push_back(double(s.num_gaussians) / unit);
  LineChartSpec n;
  n.text = {"Gaussians", "after each step (densification and pruning)", "step",
            unit == 1e6   ? "Gaussians (millions)"
            : unit == 1e3 ? "Gaussians (thousands)"
                          : "Gaussians"};
  n.series = {{"", series(g), blue, 2.0}};
  n.y_from_zero = true;
  return {line_chart(l), line_chart(p), line_chart(n)};
}

std::string markdown(const TrainReportJob& job, const TrainReportResult& r, const TrainLog& log) {
  const bool init = !job.init_ply.empty();
  std::string md = "# Training report\n\n";
  md += "- scene: `" + job.scene_dir + "` (data factor " + std::to_string(job.data_factor) +
        ", every " + std::to_string(job.test_every) + "th image held out)\n";
  md += "- model: `" + job.ply + "`, " + std::to_string(r.gaussians) + " Gaussians after " +
        std::to_string(r.final_step) + " steps, " + fmt("%.1f", r.seconds) + " s of training\n";
  if (init) md += "- SfM init: `" + job.init_ply + "`\n";
  md += "- render mode: " + job.mode + "\n";
  if (log.has_eval)
    md += "- the trainer's own held-out evaluation (float render): PSNR " +
          fmt("%.3f", log.eval_psnr) + " dB, SSIM " + fmt("%.4f", log.eval_ssim) + "\n";
  md += "\n| held-out view | PSNR (dB) | SSIM |" +
        std::string(init ? " init PSNR | init SSIM |" : "") + "\n|---|---|---|" +
        (init ? "---|---|" : "") + "\n";
  for (const HeldoutResult& v : r.views) {
    md.append("| ").append(v.name).append(" | ").append(fmt("%.3f", v.psnr));
    md.append(" | ").append(fmt("%.4f", v.ssim)).append(" |");
    if (init) md.append(" ").append(fmt("%.3f", v.init_psnr)).append(" | ");
    if (init) md.append(fmt("%.4f", v.init_ssim)).append(" |");
    md.append("\n");
  }
  md +=
      "| **mean** | **" + fmt("%.3f", r.mean_psnr) + "** | **" + fmt("%.4f", r.mean_ssim) + "** |";
  if (init)
    md += " " + fmt("%.3f", r.init_mean_psnr) + " | " + fmt("%.4f", r.init_mean_ssim) + " |";
  md +=
      "\n\n![loss](curve_loss.png)\n\n![PSNR](curve_psnr.png)\n\n![Gaussians](curve_gaussians.png)"
      "\n";
  for (const HeldoutResult& v : r.views) md += "\n![" + v.name + "](" + v.figure + ")\n";
  return md;
}

}  // namespace

Result<TrainLog> parse_train_log(const std::string& text, const std::string& name) {
  TrainLog log;
  size_t pos = 0;
  int line_no = 0;
  while (pos < text.size()) {
    size_t end = text.find('\n', pos);
    if (end == std::string::npos) end = text.size();
    const std::string line = text.substr(pos, end - pos);
    pos = end + 1;
    ++line_no;
    const std::string where = name + ":" + std::to_string(line_no);
    if (line.find_first_not_of(" \t\r") == std::string::npos) continue;
    Json j = Json::parse(line, nullptr, false);
    if (j.is_discarded())
      return Status::error(where + ": not JSON (expected one object per line, found '" +
                           line.substr(0, 60) + (line.size() > 60 ? "...'" : "'") + ")");
    if (!j.is_object())
      return Status::error(where + ": expected a JSON object, found " + j.dump().substr(0, 60));
    if (j.contains("eval")) {
      MACRO_ASSIGN_OR_RETURN(log.eval_psnr, number_field(j, "psnr", where));
      MACRO_ASSIGN_OR_RETURN(log.eval_ssim, number_field(j, "ssim", where));
      log.has_eval = true;
      continue;
    }
    if (j.contains("scene_dir")) {
      if (!j["scene_dir"].is_string())
        return Status::error(where + ": \"scene_dir\": expected a string");
      log.scene_dir = j["scene_dir"].get<std::string>();
      MACRO_ASSIGN_OR_RETURN(log.train_views, name_list(j, "train_views", where));
      MACRO_ASSIGN_OR_RETURN(log.test_views, name_list(j, "test_views", where));
      log.has_views = true;
      continue;
    }
    auto step = j.find("step");
    if (step == j.end() || !step->is_number_integer())
      return Status::error(where +
                           ": expected a step line (\"step\": an integer), a scene_dir "
                           "line or an eval line, found " +
                           line.substr(0, 60));
    TrainLogStep s;
    s.step = step->get<int>();
    MACRO_ASSIGN_OR_RETURN(s.loss, number_field(j, "loss", where));
    MACRO_ASSIGN_OR_RETURN(s.psnr, number_field(j, "psnr", where));
    MACRO_ASSIGN_OR_RETURN(s.seconds, number_field(j, "seconds", where));
    if (j.contains("l1")) {
      MACRO_ASSIGN_OR_RETURN(s.l1, number_field(j, "l1", where));
    }
    if (j.contains("ssim")) {
      MACRO_ASSIGN_OR_RETURN(s.ssim, number_field(j, "ssim", where));
    }
    auto n = j.find("num_gaussians");
    if (n == j.end() || !n->is_number_unsigned())
      return Status::error(where + ": \"num_gaussians\": expected a non-negative integer, found " +
                           (n == j.end() ? std::string("nothing") : n->dump()));
    s.num_gaussians = n->get<size_t>();
    if (!log.steps.empty() && s.step <= log.steps.back().step)
      return Status::error(where + ": step " + std::to_string(s.step) + " after step " +
                           std::to_string(log.steps.back().step) + " (expected increasing steps)");
    log.steps.push_back(s);
  }
  if (log.steps.empty())
    return Status::error(name + ": no step lines (expected the JSONL of macro train --log)");
  return log;
}

Result<TrainLog> read_train_log(const std::string& path) {
  auto text = read_text_file(path);
  if (!text) return text.status().with_context("--log");
  auto log = parse_train_log(*text, path);
  if (!log) return log.status().with_context("--log");
  return log;
}

Result<TrainReportResult> run_train_report(const TrainReportJob& job, ThreadPool& pool) {
  namespace fs = std::filesystem;
  if (job.scene_dir.empty()) return Status::error("--scene-dir: required");
  if (job.ply.empty()) return Status::error("--ply: required");
  if (job.log.empty()) return Status::error("--log: required");
  if (job.out_dir.empty()) return Status::error("--out: required");
  if (job.smooth < 1)
    return Status::error("--smooth: expected >= 1, found " + std::to_string(job.smooth));
  MACRO_ASSIGN_OR_RETURN(const gs::RasterMode mode, gs::parse_raster_mode(job.mode));
  std::error_code ec;
  if (fs::exists(job.out_dir, ec) && !fs::is_directory(job.out_dir, ec))
    return Status::error("--out: " + job.out_dir + " exists and is not a folder");

  MACRO_ASSIGN_OR_RETURN(TrainLog log, read_train_log(job.log));
  gs::train::SceneDirOptions so;
  so.data_factor = job.data_factor;
  so.test_every = job.test_every;
  so.init = "random", so.init_points = 0;  // the photos and cameras only
  auto scene = gs::train::load_scene_dir(job.scene_dir, so);
  if (!scene) return scene.status().with_context("--scene-dir");
  std::vector<std::string> test_names;
  for (const auto& v : scene->test) test_names.push_back(v.camera.name);
  if (scene->test.empty())
    return Status::error(
        "--scene-dir: " + job.scene_dir + ": no held-out views (" +
        (scene->split_path.empty()
             ? "--test-every " + std::to_string(job.test_every) + " holds none out"
             : scene->split_path + " names the training frames, so none is held out") +
        "); train with --test-every 8 (and no split.json) and report with the same --test-every");
  if (log.has_views && log.test_views != test_names)
    return Status::error("--log: " + job.log + " held out [" + join(log.test_views) +
                         "] but --scene-dir " + job.scene_dir + " with --test-every " +
                         std::to_string(job.test_every) + " holds out [" + join(test_names) +
                         "]: pass the training run's --test-every and --data-factor");

  std::vector<float> file_filter;  // mip: recomputed from the training cameras (model_cloud)
  auto trained =
      gs::read_splat_params(job.ply, {}, mode == gs::RasterMode::kMip ? &file_filter : nullptr);
  if (!trained) return trained.status().with_context("--ply");
  TrainReportResult res;
  const TrainLogStep& last = log.steps.back();
  res.final_step = last.step + 1;
  res.gaussians = trained->size();
  res.seconds = last.seconds;
  if (trained->size() != last.num_gaussians)
    return Status::error("--ply: " + job.ply + " holds " + std::to_string(trained->size()) +
                         " Gaussians, the log's last step (" + std::to_string(last.step) +
                         ") has " + std::to_string(last.num_gaussians) + ": not this run's model");
  std::optional<gs::SplatParams> init;
  if (!job.init_ply.empty()) {
    auto p = gs::read_splat_params(job.init_ply, {},
                                   mode == gs::RasterMode::kMip ? &file_filter : nullptr);
    if (!p) return p.status().with_context("--init-ply");
    init = std::move(*p);
  }
  std::vector<gs::Camera> train_cameras;
  for (const auto& v : scene->train) train_cameras.push_back(v.camera);
  const gs::GaussianCloud cloud = model_cloud(*trained, mode, train_cameras);
  std::optional<gs::GaussianCloud> init_cloud;
  if (init) init_cloud = model_cloud(*init, mode, train_cameras);

  // Render and score every held-out view, compose its figure (in memory).
  std::vector<std::pair<std::string, std::vector<uint8_t>>> figures;
  Progress progress("train-report: held-out views", scene->test.size(), job.progress ? 0.0 : 1e30);
  float trained_alpha = 0, init_alpha = 0;
  for (const auto& v : scene->test) {
    gs::Image photo(v.camera.width, v.camera.height, 3);
    photo.data = v.target;
    const std::string name = v.camera.name;
    auto t = render_view(cloud, v.camera, photo, mode, pool);
    if (!t) return t.status().with_context("--ply: " + job.ply + ": held-out view " + name);
    trained_alpha = std::max(trained_alpha, t->max_alpha);
    HeldoutResult h;
    h.name = name;
    h.psnr = t->psnr, h.ssim = t->ssim;
    std::optional<Rendered> i;
    if (init_cloud) {
      auto r = render_view(*init_cloud, v.camera, photo, mode, pool);
      if (!r) return r.status().with_context("--init-ply: " + job.init_ply + ": view " + name);
      init_alpha = std::max(init_alpha, r->max_alpha);
      h.init_psnr = r->psnr, h.init_ssim = r->ssim;
      i = std::move(*r);
    }
    auto caption = [](double p, double s) {
      return "PSNR " + fmt("%.2f", p) + " dB \u00b7 SSIM " + fmt("%.3f", s);
    };
    std::vector<FigurePanel> panels = {{&photo, "photo (held out)", {name}},
                                       {&t->image,
                                        "3DGS, " + std::to_string(res.final_step) + " steps",
                                        {caption(h.psnr, h.ssim)}}};
    if (i)
      panels.push_back({&i->image, "SfM init, untrained", {caption(h.init_psnr, h.init_ssim)}});
    MACRO_ASSIGN_OR_RETURN(SideBySide fig, compose_side_by_side(panels));
    MACRO_ASSIGN_OR_RETURN(std::vector<uint8_t> png, gs::encode_png(fig.image));
    h.figure = "heldout_" + file_part(name) + ".png";
    for (const auto& [f, bytes] : figures)
      if (f == h.figure)
        h.figure = "heldout_" + file_part(name) + "_" + std::to_string(res.views.size()) + ".png";
    figures.push_back({h.figure, std::move(png)});
    res.views.push_back(std::move(h));
    progress.advance();
  }
  progress.finish();
  // A model that covers no pixel of any held-out view is not a model of this scene.
  if (trained_alpha < 0.5f)
    return Status::error("--ply: " + job.ply + " covers no held-out view of " + job.scene_dir +
                         " (largest alpha " + fmt("%.3f", trained_alpha) +
                         ", expected >= 0.5): not a model of this scene");
  if (init_cloud && init_alpha < 0.05f)
    return Status::error("--init-ply: " + job.init_ply + " covers no held-out view of " +
                         job.scene_dir + " (largest alpha " + fmt("%.3f", init_alpha) +
                         ", expected >= 0.05): not an initialisation of this scene");
  const double n = double(res.views.size());
  res.mean_psnr = res.mean_ssim = 0;
  if (init_cloud) res.init_mean_psnr = res.init_mean_ssim = 0;
  for (const HeldoutResult& h : res.views) {
    res.mean_psnr += h.psnr / n, res.mean_ssim += h.ssim / n;
    if (init_cloud) res.init_mean_psnr += h.init_psnr / n, res.init_mean_ssim += h.init_ssim / n;
  }

  Json j;
  j["scene_dir"] = job.scene_dir;
  j["data_factor"] = job.data_factor;
  j["test_every"] = job.test_every;
  j["ply"] = job.ply;
  j["init_ply"] = job.init_ply.empty() ? Json(nullptr) : Json(job.init_ply);
  j["log"] = job.log;
  j["mode"] = job.mode;
  j["final_step"] = res.final_step;
  j["gaussians"] = res.gaussians;
  j["training_seconds"] = std::isfinite(res.seconds) ? Json(res.seconds) : Json(nullptr);
  j["heldout"] = Json::array();
  for (const HeldoutResult& h : res.views) {
    Json v;
    v["name"] = h.name;
    v["figure"] = h.figure;
    v["trained"] = metric_json(h.psnr, h.ssim);
    if (init_cloud) v["init"] = metric_json(h.init_psnr, h.init_ssim);
    j["heldout"].push_back(v);
  }
  j["mean"]["trained"] = metric_json(res.mean_psnr, res.mean_ssim);
  if (init_cloud) j["mean"]["init"] = metric_json(res.init_mean_psnr, res.init_mean_ssim);
  if (log.has_eval) j["trainer_eval"] = metric_json(log.eval_psnr, log.eval_ssim);

  // Write everything; on a failure remove what this job wrote.
  const std::vector<Chart> charts = curves(log, job, res);
  auto write_all = [&]() -> Status {
    fs::create_directories(job.out_dir, ec);
    if (ec) return Status::error("--out: cannot create " + job.out_dir + ": " + ec.message());
    const char* stems[] = {"curve_loss", "curve_psnr", "curve_gaussians"};
    for (size_t k = 0; k < charts.size(); ++k)
      MACRO_TRY(write_chart(charts[k], (fs::path(job.out_dir) / stems[k]).string(), &res.written)
                    .with_context("--out"));
    for (const auto& [f, bytes] : figures) {
      const std::string path = (fs::path(job.out_dir) / f).string();
      MACRO_TRY(write_file_atomic(path, bytes.data(), bytes.size()).with_context("--out"));
      res.written.push_back(path);
    }
    for (const auto& [f, text] :
         {std::pair<std::string, std::string>{"report.json", j.dump(2) + "\n"},
          {"report.md", markdown(job, res, log)}}) {
      const std::string path = (fs::path(job.out_dir) / f).string();
      MACRO_TRY(write_file_atomic(path, text).with_context("--out"));
      res.written.push_back(path);
    }
    return Status::ok();
  };
  if (Status s = write_all(); !s) {
    for (const std::string& p : res.written) fs::remove(p, ec);
    return s;
  }
  return res;
}

std::string train_report_summary(const TrainReportJob& job, const TrainReportResult& r) {
  std::string s = std::to_string(r.views.size()) + " held-out view" +
                  (r.views.size() == 1 ? "" : "s") + ": PSNR " + fmt("%.2f", r.mean_psnr) +
                  " dB, SSIM " + fmt("%.3f", r.mean_ssim);
  if (std::isfinite(r.init_mean_psnr))
    s += " (SfM init " + fmt("%.2f", r.init_mean_psnr) + " dB, " + fmt("%.3f", r.init_mean_ssim) +
         ")";
  s += " after " + std::to_string(r.final_step) + " steps, " + std::to_string(r.gaussians) +
       " Gaussians, " + fmt("%.1f", r.seconds) + " s of training; wrote " +
       (std::filesystem::path(job.out_dir) / "report.md").string();
  return s;
}

}  // namespace macro::enhance
