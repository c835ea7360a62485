// macro train-report: the curves, held-out figures and tables of a finished `macro train
// --scene-dir` run. Thin main over enhance::run_train_report (enhance/train_report.h,
// docs/training.md §7).
#include <cstdio>

#include "apps/args.h"
#include "attention/runtime/progress.h"
#include "enhance/train_report.h"

namespace macro::cli {
namespace {

constexpr const char* kUsage =
    "usage: macro train-report --scene-dir DIR [--data-factor F] [--test-every 8]\n"
    "         --ply TRAINED.ply [--init-ply INIT.ply] --log LOG.jsonl --out OUTDIR\n"
    "         [--mode classic|antialiased|mip] [--smooth 50] [--threads N] [--quiet]\n"
    "  --scene-dir, --data-factor, --test-every  as given to macro train: the same held-out\n"
    "              views (every --test-every-th image by name; split.json's training frames)\n"
    "  --ply       the trained Gaussians (macro train --out)\n"
    "  --init-ply  the initialisation (e.g. the SfM init) drawn beside it, untrained\n"
    "  --log       macro train --log (JSONL); its last step gives the step count and the time\n"
    "  --out       folder: curve_loss, curve_psnr, curve_gaussians (.png .svg .pdf),\n"
    "              heldout_<name>.png per held-out view, report.json, report.md\n"
    "  --mode      the render mode the model was trained with (default classic)\n"
    "  --smooth    the curves' running-mean window in steps (default 50)\n";

int run_train_report(std::vector<std::string> argv) {
  Args args(std::move(argv));
  if (args.flag("--help")) {
    std::printf("%s", kUsage);
    return 0;
  }
  if (Status s = apply_common_flags(args); !s) return fail("train-report", s);
  enhance::TrainReportJob job;
  job.scene_dir = args.required("--scene-dir");
  job.data_factor = args.int_or("--data-factor", 1, 1, 64);
  job.test_every = args.int_or("--test-every", 8, 0, 1000000);
  job.ply = args.required("--ply");
  job.init_ply = args.value_or("--init-ply", "");
  job.log = args.required("--log");
  job.out_dir = args.required("--out");
  job.mode = args.value_or("--mode", job.mode);
  job.smooth = args.int_or("--smooth", job.smooth, 1, 1000000);
  if (Status s = args.finish(); !s)
    return fail("train-report",
                Status::error(s.message() + " (macro train-report --help for usage)"));
  auto result = enhance::run_train_report(job);
  if (!result) return fail("train-report", result.status());
  if (!quiet()) std::printf("%s\n", enhance::train_report_summary(job, *result).c_str());
  return 0;
}

const bool registered = register_command(
    {"train-report", "curves, held-out figures and PSNR/SSIM tables of a finished macro train run",
     run_train_report});

}  // namespace
}  // namespace macro::cli
