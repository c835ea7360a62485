// The logic behind `macro grad` and `macro train` (docs/training.md): load, check, run, write.
//
// grad: one forward and backward of the loss on one view, written as safetensors (F32, gsplat
// names and shapes; N Gaussians, K SH coefficients per channel, H x W pixels):
//   loss, l1, ssim [1]; color [H,W,3]; alpha [H,W];
//   grad.means [N,3], grad.scales [N,3] (log scales), grad.quats [N,4] (raw w,x,y,z),
//   grad.opacities [N] (logits), grad.sh0 [N,1,3], grad.shN [N,K-1,3], grad.means2d [N,2]
// train: Adam steps over the views in camera-file order, the result as an Inria .ply (raw
// parameters), a JSONL log (one line per step: step, loss, l1, ssim, num_gaussians, seconds) and
// progress on stderr (step, loss, PSNR of the step's view, Gaussians, it/s, ETA); with
// --save-every a checkpoint OUT.ckpt (checkpoint.h), and --resume continues from one.
// The photo of camera NAME is DIR/NAME when NAME has an extension, else the one of
// DIR/NAME.png, .jpg, .jpeg, .exr that exists (two of them is an error); it must have the
// camera's size. Settings this milestone does not implement are refused by flag name.
#pragma once

#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "attention/runtime/status.h"
#include "gs/cameras/camera.h"
#include "gs/formats/scene_io.h"
#include "gs/train/scene_inputs.h"
#include "gs/train/train_memory.h"
#include "gs/train/trainer.h"

namespace macro::gs::train {

struct GradJob {
  std::string scene_path;    // Inria .ply (read as raw parameters)
  std::string cameras_path;  // any camera file load_cameras reads
  std::string camera_name;
  std::string target_path;          // PNG/JPEG (byte / 255) or EXR (R, G, B)
  std::string out_path;             // .safetensors
  std::string mode = "classic";     // classic | antialiased | mip (the 3D filter from every camera)
  std::string precision = "float";  // --precision: float (SIMD path) | double (the reference)
  LoadLimits limits;
};

struct GradJobResult {
  Camera camera;
  size_t gaussians = 0;
  LossValue loss;
  double ms = 0;
};

Result<GradJobResult> run_grad_job(const GradJob& job, ThreadPool& pool = ThreadPool::global());

struct TrainJob {
  std::string images_dir;
  std::string cameras_path;
  // Without scene_dir: an Inria .ply. With scene_dir: sfm (default), random, or an Inria .ply.
  std::string init_path;
  std::string scene_dir;  // --scene-dir (scene_inputs.h); replaces --images and --cameras
  int data_factor = 1;    // --data-factor
  int test_every = 8;     // --test-every (0: no hold-out)
  std::string out_path;   // .ply
  std::string log_path;   // JSONL, optional
  int steps = 30000;
  // gsplat's defaults where a flag is absent; only the values named in docs/training.md run.
  std::string strategy = "default";     // --strategy: default | mcmc | none
  std::string lr_schedule = "gsplat";   // --lr-schedule: gsplat | constant
  std::string view_order = "shuffled";  // --view-order: shuffled | sequential
  int sh_degree_interval = 1000;        // --sh-degree-interval: 0 = every band from the start
  std::string mode = "classic";         // --mode: classic | antialiased | mip
  size_t cap_max = 1000000;             // --cap-max (mcmc)
  bool absgrad = false;                 // --absgrad (default strategy: AbsGS gradients)
  double grow_grad2d = 0.0002;          // --grow-grad2d (default strategy)
  int save_every = 0;                   // --save-every: a checkpoint every N steps (0: none)
  std::string resume_path;              // --resume CKPT
  std::string precision = "float";      // --precision: float (SIMD path) | double (reference)
  std::optional<double> scene_scale;    // --scene-scale; absent: gsplat's camera extent
  uint64_t seed = 42;                   // --seed: view order and split samples
  bool progress = true;                 // stderr progress (also off when quiet())
  LoadLimits limits;  // limits.max_gaussians (--max-gaussians) also caps densification
};

struct TrainJobResult {
  size_t gaussians = 0, views = 0;  // gaussians: after training; views: training views
  size_t initial_gaussians = 0;
  std::vector<std::string> train_views, test_views;  // camera names
  bool evaluated = false;  // test views existed: PSNR / SSIM on them after training
  double test_psnr = 0, test_ssim = 0;
  double scene_scale = 1;
  std::vector<StepRecord> records;
  double seconds = 0;
  TrainMemory memory;              // the estimate at the start (train_memory.h)
  size_t peak_resident_bytes = 0;  // the process's peak resident set at the end
};

// The flags' values this milestone implements; anything else is "not implemented yet".
Status check_train_settings(const TrainJob& job);
// "classic", "antialiased", "mip".
Result<RasterMode> parse_raster_mode(const std::string& flag, const std::string& value);
Result<TrainJobResult> run_train_job(const TrainJob& job, ThreadPool& pool = ThreadPool::global());

// gsplat's scene scale when none is given: 1.1 x the largest distance of a camera centre from
// the centres' mean.
double camera_extent_scale(const CameraSet& cameras);
// DIR/NAME or DIR/NAME.{png,jpg,jpeg,exr} (see the top of this file).
Result<std::string> find_view_image(const std::string& dir, const std::string& name);
// A target image as float RGB [H,W,3]: PNG/JPEG through gs::read_image, EXR from its R, G, B.
Result<std::vector<float>> read_target(const std::string& path, int width, int height);

}  // namespace macro::gs::train
