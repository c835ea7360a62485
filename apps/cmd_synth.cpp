// macro synth: a deterministic synthetic scene with known geometry (gs/synth/synth.h) to a folder:
// scene.ply, cameras.json, geometry.json.
#include <cstdio>

#include "apps/args.h"
#include "attention/runtime/progress.h"
#include "gs/synth/synth.h"

namespace macro::cli {
namespace {

constexpr const char* kUsage =
    "usage: macro synth --out DIR [--seed S] [--kind planes|mixed] [--gaussians N]\n"
    "         [--width W] [--height H] [--training-views N] [--closeup-views N] [--no-background]\n"
    "  writes DIR/scene.ply, DIR/cameras.json (cameras train_NN, closeup, closeup_NN) and\n"
    "  DIR/geometry.json (planes, spheres, rods, close-up targets: the analytic answers)\n";

int run_synth(std::vector<std::string> argv) {
  Args args(std::move(argv));
  if (args.flag("--help")) {
    std::printf("%s", kUsage);
    return 0;
  }
  if (Status s = apply_common_flags(args); !s) return fail("synth", s);
  gs::SynthParams p;
  const std::string out = args.required("--out");
  p.seed = uint64_t(args.int_or("--seed", 1, 0, 2147483647));
  const std::string kind = args.value_or("--kind", "mixed");
  p.gaussians = size_t(args.int_or("--gaussians", int(p.gaussians), 1000, 20'000'000));
  p.width = args.int_or("--width", p.width, 16, 16384);
  p.height = args.int_or("--height", p.height, 16, 16384);
  p.training_views = args.int_or("--training-views", p.training_views, 1, 256);
  p.closeup_views = args.int_or("--closeup-views", p.closeup_views, 0, 256);
  p.background = !args.flag("--no-background");
  if (Status s = args.finish(); !s) {
    return fail("synth", Status::error(s.message() + " (macro synth --help for usage)"));
  }
  auto parsed_kind = gs::parse_synth_kind(kind);
  if (!parsed_kind) return fail("synth", parsed_kind.status());
  p.kind = *parsed_kind;
  auto scene = gs::generate_synthetic_scene(p);
  if (!scene) return fail("synth", scene.status());
  if (Status s = prepare_output_dir(out, "--out"); !s) return fail("synth", s);
  if (Status s = gs::write_synthetic_scene(*scene, out); !s) return fail("synth", s);
  if (!quiet()) {
    std::printf("synth: %s, %s (%s), %s, %s, %s -> %s/{scene.ply,cameras.json,geometry.json}\n",
                count_noun(scene->cloud.size(), "Gaussian").c_str(),
                count_noun(scene->cameras.cameras.size(), "camera").c_str(),
                count_noun(scene->geometry.closeups.size(), "close-up").c_str(),
                count_noun(scene->geometry.planes.size(), "plane").c_str(),
                count_noun(scene->geometry.spheres.size(), "sphere").c_str(),
                count_noun(scene->geometry.rods.size(), "rod").c_str(), out.c_str());
  }
  return 0;
}

const bool registered =
    register_command({"synth", "generate a synthetic scene with known geometry", run_synth});

}  // namespace
}  // namespace macro::cli
