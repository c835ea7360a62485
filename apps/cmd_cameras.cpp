// macro cameras: list the cameras of any camera file (gs::describe_cameras).
#include <cstdio>

#include "apps/args.h"
#include "gs/cameras/camera.h"

namespace macro::cli {
namespace {

constexpr const char* kUsage =
    "usage: macro cameras FILE|DIR [--strict] [--no-undo-applied-transform]\n"
    "  FILE|DIR   our cameras.json, a COLMAP sparse folder or file, transforms.json, a DL3DV "
    "split,\n"
    "             or a scene folder (sparse/0, transforms.json, cameras.json are looked for)\n"
    "  prints each camera's name, size, model (with its coefficients) and centre in world\n"
    "  coordinates, then the entries left out as invalid by index and name\n"
    "  --strict   any invalid entry is an error (exit 1)\n"
    "  --no-undo-applied-transform  keep nerfstudio poses in the transforms.json world frame\n";

int run_cameras(std::vector<std::string> argv) {
  Args args(std::move(argv));
  if (args.flag("--help")) {
    std::printf("%s", kUsage);
    return 0;
  }
  if (Status s = apply_common_flags(args); !s) return fail("cameras", s);
  gs::CameraLoadOptions options;
  options.strict = args.flag("--strict");
  options.undo_applied_transform = !args.flag("--no-undo-applied-transform");
  const std::vector<std::string> files = args.positionals();
  if (Status s = args.finish(); !s) {
    return fail("cameras", Status::error(s.message() + " (macro cameras --help for usage)"));
  }
  if (files.size() != 1) {
    std::fprintf(stderr, "macro cameras: expected one camera file or folder, found %zu\n%s",
                 files.size(), kUsage);
    return 2;
  }
  gs::CameraFormat format;
  auto set = gs::load_cameras(files[0], options, &format);
  if (!set) return fail("cameras", set.status());
  std::printf("%s", gs::describe_cameras(*set, format).c_str());
  return 0;
}

const bool registered = register_command(
    {"cameras", "list the cameras of a camera file (name, size, model, centre)", run_cameras});

}  // namespace
}  // namespace macro::cli
