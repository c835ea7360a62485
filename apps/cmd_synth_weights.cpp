// macro synth-weights: a synthetic checkpoint folder with the exact tensor names and shapes of the
// real download (from a manifest), seeded random values. For loader tests and benchmarks without
// the real weights; the result is not a trained network.
#include <cstdio>

#include "apps/args.h"
#include "attention/nets/synthetic_checkpoint.h"

namespace macro::cli {
namespace {

int run_synth_weights(std::vector<std::string> argv) {
  Args args(std::move(argv));
  if (args.flag("--help")) {
    std::printf(
        "usage: macro synth-weights --out DIR [--seed S] [--dtype f32|bf16]\n"
        "         (--manifest M.json --class UNet2DConditionModel|AutoencoderKL\n"
        "          | --pipeline UNET_MANIFEST.json VAE_MANIFEST.json)\n"
        "Writes config.json + diffusion_pytorch_model.safetensors (or a pipeline folder with\n"
        "model_index.json, unet/, vae/, scheduler/) from manifests such as\n"
        "data/manifests/{unet,vae}.json. Values are seeded random, not trained.\n");
    return 0;
  }
  if (Status s = apply_common_flags(args); !s) return fail("synth-weights", s);
  const std::string out = args.required("--out");
  const int seed = args.int_or("--seed", 1, 0, 1 << 30);
  const std::string dtype = args.value_or("--dtype", "f32");
  auto manifest = args.value("--manifest");
  const std::string class_name = args.value_or("--class", "");
  auto pipeline = args.value("--pipeline");
  std::vector<std::string> rest = args.positionals();
  if (Status s = args.finish(); !s) return fail("synth-weights", s);
  if (dtype != "f32" && dtype != "bf16")
    return fail("synth-weights",
                Status::error("--dtype: expected f32 or bf16, found '" + dtype + "'"));
  nets::SyntheticCheckpointOptions options;
  options.seed = uint64_t(seed);
  options.bf16 = dtype == "bf16";
  if (Status s = prepare_output_dir(out, "--out"); !s) return fail("synth-weights", s);
  Status s;
  if (pipeline) {
    if (manifest || rest.size() != 1)
      return fail("synth-weights", Status::error("--pipeline: expected two manifests (U-Net, VAE) "
                                                 "and no --manifest"));
    s = nets::write_synthetic_pipeline(*pipeline, rest[0], out, options);
  } else {
    if (!manifest || !rest.empty())
      return fail("synth-weights", Status::error("expected --manifest M.json --class NAME, or "
                                                 "--pipeline UNET_MANIFEST VAE_MANIFEST"));
    if (class_name != "UNet2DConditionModel" && class_name != "AutoencoderKL")
      return fail("synth-weights", Status::error("--class: expected UNet2DConditionModel or "
                                                 "AutoencoderKL, found '" +
                                                 class_name + "'"));
    s = nets::write_synthetic_component(*manifest, out, class_name, options);
  }
  if (!s) return fail("synth-weights", s);
  std::printf("wrote %s (synthetic, seed %d, %s)\n", out.c_str(), seed, dtype.c_str());
  return 0;
}

const bool registered = register_command(
    {"synth-weights", "synthetic full-size checkpoint folder from a tensor manifest",
     run_synth_weights});

}  // namespace
}  // namespace macro::cli
