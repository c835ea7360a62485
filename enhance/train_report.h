// `macro train-report` (docs/training.md §7): the figures and tables of a finished `macro train
// --scene-dir` run, from its log, its trained .ply and the scene folder.
//
// Outputs (in OUT, each written atomically; a failure removes those already written):
//   curve_loss.{png,svg,pdf}       loss vs step: the trailing running mean over `smooth` steps
//                                  over the faint per-step values
//   curve_psnr.{png,svg,pdf}       training-view PSNR vs step, the same smoothing, and the held-out
//                                  mean of this report at the last step as a marker
//   curve_gaussians.{png,svg,pdf}  Gaussians vs step
//   heldout_<name>.png             per held-out view: photo | trained render | SfM init render,
//                                  captioned with PSNR / SSIM against the photo
//   report.json, report.md         per view and mean PSNR / SSIM (trained and init), the final
//                                  step, the Gaussians, the training seconds
// The held-out views are load_scene_dir's test views (gs/train/scene_inputs.h), so the same
// --data-factor and --test-every as the training select the same photos. Renders use gs::render
// in `mode` (mip: the 3D filter from the training cameras folded in, as the trainer computes it);
// PSNR and SSIM (enhance/metrics) are of the 8-bit render the figure holds against the photo, so
// `macro metrics` on the figure's panel and the photo gives the same numbers.
#pragma once

#include <cmath>
#include <optional>
#include <string>
#include <vector>

#include "attention/runtime/status.h"
#include "attention/runtime/thread_pool.h"

namespace macro::enhance {

// One `--log` step line (gs/train/train_job.cpp writes them); NaN where the log wrote null.
struct TrainLogStep {
  int step = 0;  // 0-based
  double loss = 0, l1 = 0, ssim = 0, psnr = 0, seconds = 0;
  size_t num_gaussians = 0;
};

struct TrainLog {
  std::vector<TrainLogStep> steps;  // in file order, step strictly increasing
  // The --scene-dir line (absent for --images runs).
  bool has_views = false;
  std::string scene_dir;
  std::vector<std::string> train_views, test_views;
  // The trainer's own held-out evaluation line (gs::train::evaluate_views).
  bool has_eval = false;
  double eval_psnr = 0, eval_ssim = 0;
};

// Errors name the file and the 1-based line: not JSON, not an object, a step line without one
// of step / loss / psnr / num_gaussians / seconds or with a wrong type, steps not increasing, no
// step line at all.
Result<TrainLog> parse_train_log(const std::string& text, const std::string& name);
Result<TrainLog> read_train_log(const std::string& path);

struct TrainReportJob {
  std::string scene_dir;
  int data_factor = 1, test_every = 8;
  std::string ply, init_ply;  // init_ply "" = no init panel
  std::string log;
  std::string out_dir;
  std::string mode = "classic";  // classic | antialiased | mip
  int smooth = 50;               // running-mean window of the curves, steps
  bool progress = true;
};

struct HeldoutResult {
  std::string name, figure;
  double psnr = 0, ssim = 0;
  double init_psnr = NAN, init_ssim = NAN;  // NaN without --init-ply
};

struct TrainReportResult {
  std::vector<HeldoutResult> views;
  double mean_psnr = 0, mean_ssim = 0;
  double init_mean_psnr = NAN, init_mean_ssim = NAN;
  int final_step = 0;  // steps done: the last logged step + 1
  size_t gaussians = 0;
  double seconds = 0;  // the last step's "seconds"
  std::vector<std::string> written;
};

Result<TrainReportResult> run_train_report(const TrainReportJob& job,
                                           ThreadPool& pool = ThreadPool::global());

// "2 held-out views: PSNR 27.31 dB, SSIM 0.912 (SfM init 14.20 dB, 0.410) after 7000 steps, ..."
std::string train_report_summary(const TrainReportJob& job, const TrainReportResult& result);

}  // namespace macro::enhance
