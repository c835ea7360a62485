// macro metrics: PSNR, SSIM, LPIPS-Alex, DINOv2, DreamSim of one prediction against its ground
// truth (the evaluation protocol of docs/spec/macro-method.md §7). Metrics whose networks are not
// available print "not computed: <reason>".
#include <cstdio>

#include "apps/args.h"
#include "enhance/metrics/metrics.h"
#include "gs/image_io.h"

namespace macro::cli {
namespace {

constexpr const char* kUsage =
    "usage: macro metrics --pred A.png --gt B.png [--lpips-backbone alexnet.safetensors]\n"
    "                     [--lpips-heads lpips_v0.1_alex.safetensors] [--dinov2 W.safetensors]\n"
    "                     [--dreamsim W.safetensors] [--no-resize] [--json] [--threads N]\n"
    "  The prediction is Lanczos-resized (Pillow-exact) to the ground-truth size unless "
    "--no-resize.\n"
    "  LPIPS needs the AlexNet backbone (torchvision weights as safetensors, names\n"
    "  features.{0,3,6,8,10}.{weight,bias}); default data/weights/lpips/alexnet.safetensors.\n";

int run_metrics(std::vector<std::string> argv) {
  Args args(std::move(argv));
  if (args.flag("--help")) {
    std::printf("%s", kUsage);
    return 0;
  }
  if (Status s = apply_common_flags(args); !s) return fail("metrics", s);
  const std::string pred_path = args.required("--pred");
  const std::string gt_path = args.required("--gt");
  enhance::MetricOptions opt;
  opt.lpips_backbone = args.value_or("--lpips-backbone", "");
  opt.lpips_heads = args.value_or("--lpips-heads", "");
  opt.dinov2_weights = args.value_or("--dinov2", "");
  opt.dreamsim_weights = args.value_or("--dreamsim", "");
  opt.resize_pred = !args.flag("--no-resize");
  const bool json = args.flag("--json");
  if (Status s = args.finish(); !s) return fail("metrics", s);

  Result<gs::Image> pred = gs::read_image(pred_path);
  if (!pred) return fail("metrics", pred.status());
  Result<gs::Image> gt = gs::read_image(gt_path);
  if (!gt) return fail("metrics", gt.status());
  Result<std::vector<enhance::MetricValue>> values = enhance::compute_metrics(*pred, *gt, opt);
  if (!values) return fail("metrics", values.status().with_context(pred_path + " vs " + gt_path));
  const std::string out =
      json ? enhance::format_metrics_json(*values) : enhance::format_metrics_text(*values);
  std::fwrite(out.data(), 1, out.size(), stdout);
  return 0;
}

const bool registered = register_command(
    {"metrics", "PSNR / SSIM / LPIPS of a prediction against its ground truth", run_metrics});

}  // namespace
}  // namespace macro::cli
