// macro nn-run: run a network folder on input tensors, write the outputs (attention/nets/nn_run.h).
#include <cstdio>

#include "apps/args.h"
#include "attention/nets/nn_run.h"
#include "attention/runtime/thread_pool.h"

namespace macro::cli {
namespace {

int run_nn_run(std::vector<std::string> argv) {
  Args args(std::move(argv));
  if (args.flag("--help")) {
    std::printf(
        "usage: macro nn-run --model DIR --inputs IN.safetensors --out OUT.safetensors\n"
        "                    [--precision fp32|bf16] [--threads N] [--isa NAME]\n"
        "  taesd folder: input.image [N,3,H,W] in [0,1] -> output.latent, output.decoded\n"
        "  unet folder (config.json UNet2DConditionModel): input.z, input.ctx, [input.timestep],\n"
        "      [mask.levelL] -> output.eps\n"
        "  vae folder (config.json AutoencoderKL, Difix): input.image [N,3,H,W] in [-1,1] ->\n"
        "      output.moments, output.z, output.skip0.., output.decoded_view0\n"
        "  pipeline folder (model_index.json, unet/, vae/): input.images [V,3,H,W] in [-1,1],\n"
        "      [input.ctx], [input.timestep], [mask.levelL] -> output.z, output.eps, output.z0,\n"
        "      output.image (no input.ctx: the cached embedding of \"remove degradation\" from\n"
        "      text_encoder/ + tokenizer/)\n"
        "  clip text folder (config.json CLIPTextModel): input.ids [B,L] I64|I32 ->\n"
        "      output.hidden [B,L,D]\n");
    return 0;
  }
  if (Status s = apply_common_flags(args); !s) return fail("nn-run", s);
  nets::NnRunOptions opt;
  opt.model = args.required("--model");
  opt.inputs = args.required("--inputs");
  opt.out = args.required("--out");
  const std::string precision = args.value_or("--precision", "fp32");
  if (Status s = args.finish(); !s) return fail("nn-run", s);
  auto p = nets::parse_precision(precision);
  if (!p) return fail("nn-run", p.status().with_context("--precision"));
  opt.precision = *p;
  opt.pool = &ThreadPool::global();
  if (Status s = prepare_output(opt.out, "--out", {".safetensors"}); !s) return fail("nn-run", s);
  if (Status s = nets::nn_run(opt); !s) return fail("nn-run", s);
  return 0;
}

const bool registered = register_command(
    {"nn-run", "run a network folder (TAESD, ...) on safetensors inputs", run_nn_run});

}  // namespace
}  // namespace macro::cli
