// macro view: the local web viewer and close-up picker (enhance/view/, docs/viewer.md). Thin main
// over ViewSession::open and serve_view.
#include <cstdio>
#include <cstdlib>
#include <filesystem>

#include "apps/args.h"
#include "attention/runtime/file_io.h"
#include "attention/runtime/progress.h"
#include "enhance/enhance.h"
#include "enhance/view/view_server.h"
#include "enhance/view/view_session.h"

namespace macro::cli {
namespace {

constexpr const char* kUsage =
    "usage: macro view (--scene-dir DIR | --scene S [--cameras C]) [--port 8080]\n"
    "         [--save-to FILE.json] [--weights DIFIX_DIR] [--results DIR] [--threads N] [--quiet]\n"
    "  Serves the viewer on http://127.0.0.1:PORT (this machine only; --port 0 picks a free one):\n"
    "  orbit, pan, zoom and fly through the scene rendered by the CPU rasterizer, jump to its\n"
    "  cameras, place a close-up and save it, run plan and enhance on it (docs/viewer.md).\n"
    "  --scene-dir  a DL3DV-Closeup folder (images/, sparse/0, split.json, the trained splat);\n"
    "               plan and enhance need one. --scene: a splat or a folder with scene.ply.\n"
    "  --save-to    where close-ups are saved: a split JSON (closeup_poses) or a cameras JSON\n"
    "               (created if missing). Default: DIR/split.json, else closeups.json beside the\n"
    "               splat.\n"
    "  --weights    the Difix-ref pipeline: enhance runs Difix (default: the weight-free "
    "transfer)\n"
    "  --results    keep plan and enhance outputs in DIR (default: a temporary folder, removed\n"
    "               when the server stops)\n"
    "  Ctrl-C stops the server (a running enhance is finished first).\n";

int run_view(std::vector<std::string> argv) {
  Args args(std::move(argv));
  if (args.flag("--help")) {
    std::printf("%s", kUsage);
    return 0;
  }
  if (Status s = apply_common_flags(args); !s) return fail("view", s);
  enhance::view::ViewOptions o;
  o.scene_dir = args.value_or("--scene-dir", "");
  o.scene = args.value_or("--scene", "");
  o.cameras = args.value_or("--cameras", "");
  o.save_to = args.value_or("--save-to", "");
  o.weights = args.value_or("--weights", "");
  const std::string results = args.value_or("--results", "");
  enhance::view::ServeOptions serve;
  serve.port = args.int_or("--port", 8080, 0, 65535);
  if (Status s = args.finish(); !s)
    return fail("view", Status::error(s.message() + " (macro view --help for usage)"));
  if (o.scene_dir.empty() == o.scene.empty())
    return fail("view", Status::error("give one of --scene-dir DIR or --scene S"));
  if (!o.save_to.empty())
    if (Status s = check_output_name(o.save_to, "--save-to", {".json"}); !s) return fail("view", s);
  if (!o.weights.empty())
    if (Status s = enhance::check_difix_weights(o.weights); !s)
      return fail("view", s.with_context("--weights"));
  auto viewer_dir = enhance::view::find_viewer_dir();
  if (!viewer_dir) return fail("view", viewer_dir.status());
  serve.viewer_dir = *viewer_dir;

  namespace fs = std::filesystem;
  std::string temp;
  if (results.empty()) {
    std::string pattern = (fs::temp_directory_path() / "macro-view-XXXXXX").string();
    if (!::mkdtemp(pattern.data()))
      return fail("view", Status::error("cannot create a temporary results folder"));
    temp = pattern;
    o.results_dir = temp;
  } else {
    o.results_dir = results;
  }
  struct RemoveTemp {
    std::string dir;
    ~RemoveTemp() {
      std::error_code ec;
      if (!dir.empty()) fs::remove_all(dir, ec);
    }
  } remove_temp{temp};

  auto session = enhance::view::ViewSession::open(o);
  if (!session) return fail("view", session.status());
  serve.on_listening = [](int port) {
    // One line on stdout, always (scripts and the browser test read the port from it).
    std::printf("macro view: listening on http://127.0.0.1:%d/ (Ctrl-C stops)\n", port);
    std::fflush(stdout);
  };
  if (Status s = enhance::view::serve_view(**session, serve); !s) return fail("view", s);
  if (!quiet()) std::fprintf(stderr, "macro view: stopped\n");
  return 0;
}

const bool registered = register_command(
    {"view", "local web viewer: orbit the scene, place and save close-ups, plan and enhance",
     run_view});

}  // namespace
}  // namespace macro::cli
