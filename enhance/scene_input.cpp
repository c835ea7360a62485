// Scene folder / explicit inputs for MACRO (see scene_input.h).
#include "enhance/scene_input.h"

#include <algorithm>
#include <cctype>
#include <filesystem>

#include "attention/runtime/file_io.h"
#include "attention/runtime/progress.h"

namespace macro::enhance {
namespace fs = std::filesystem;

namespace {

bool is_splat_file(const fs::path& p) {
  const std::string ext = p.extension().string();
  return (ext == ".ply" || ext == ".splat" || ext == ".spz" || ext == ".sog" || ext == ".pt" ||
          ext == ".ckpt") &&
         p.filename() != "points3D.ply";
}

// A SOG folder: meta.json with its WebP images beside it.
bool is_sog_folder(const fs::path& p) {
  std::error_code ec;
  return fs::is_regular_file(p / "meta.json", ec);
}

// The trailing number of a file name's stem ("ckpt_29999.pt" -> 29999), or -1.
long trailing_number(const std::string& path) {
  const std::string stem = fs::path(path).stem().string();
  size_t k = stem.size();
  while (k > 0 && std::isdigit(static_cast<unsigned char>(stem[k - 1]))) --k;
  if (k == stem.size() || stem.size() - k > 15) return -1;
  return std::stol(stem.substr(k));
}

// The splat files and SOG folders directly in `dir`, sorted by name.
std::vector<std::string> splats_in(const fs::path& dir) {
  std::vector<std::string> out;
  std::error_code ec;
  if (!fs::is_directory(dir, ec)) return out;
  for (const auto& e : fs::directory_iterator(dir, ec)) {
    if (e.is_regular_file(ec) && is_splat_file(e.path())) out.push_back(e.path().string());
    if (e.is_directory(ec) && is_sog_folder(e.path())) out.push_back(e.path().string());
  }
  std::sort(out.begin(), out.end());
  return out;
}

// The latest of several outputs of one run: the highest trailing step number, else the last by
// name.
std::string latest(const std::vector<std::string>& files) {
  std::string best = files.back();
  long best_n = trailing_number(best);
  for (const std::string& f : files)
    if (trailing_number(f) > best_n) best_n = trailing_number(f), best = f;
  return best;
}

}  // namespace

Result<std::string> find_scene_ply(const std::string& dir) {
  std::error_code ec;
  if (!fs::is_directory(dir, ec)) return Status::error(dir + ": scene folder not found");
  const fs::path root(dir);
  // 1. point_cloud/iteration_N/point_cloud.ply, largest N.
  long best_iter = -1;
  std::string best;
  if (fs::is_directory(root / "point_cloud", ec))
    for (const auto& e : fs::directory_iterator(root / "point_cloud", ec)) {
      const std::string n = e.path().filename().string();
      if (n.rfind("iteration_", 0) != 0) continue;
      char* end = nullptr;
      const long it = std::strtol(n.c_str() + 10, &end, 10);
      if (!end || *end || it <= best_iter) continue;
      if (fs::is_regular_file(e.path() / "point_cloud.ply", ec)) {
        best_iter = it;
        best = (e.path() / "point_cloud.ply").string();
      }
    }
  if (!best.empty()) return best;
  // 2. conventional names.
  for (const char* n : {"scene.ply", "point_cloud.ply", "splat.ply"})
    if (fs::is_regular_file(root / n, ec)) return (root / n).string();
  // 3. the scene folder itself is a SOG folder, or the only splat file / SOG folder at the top.
  if (is_sog_folder(root)) return root.string();
  std::vector<std::string> top = splats_in(root);
  if (top.size() == 1) return top[0];
  if (top.size() > 1) {
    std::string list;
    for (const auto& t : top) list += " " + fs::path(t).filename().string();
    return Status::error(dir + ": several splat files, pass --scene to choose one:" + list);
  }
  // 4. common output folders (gsplat writes results/ply/ and results/ckpts/); the highest step.
  for (const char* sub : {"results", "results/ply", "ply", "output", "results/ckpts", "ckpts"}) {
    std::vector<std::string> f = splats_in(root / sub);
    if (!f.empty()) return latest(f);
  }
  return Status::error(
      dir +
      ": no trained splat found (looked for point_cloud/iteration_*/point_cloud.ply, "
      "scene.ply, point_cloud.ply, splat.ply, a SOG folder (meta.json), a single "
      "*.ply/*.splat/*.spz/*.sog/*.pt, and results/, results/ply/, ply/, output/, "
      "results/ckpts/, ckpts/); pass --scene");
}

Result<SceneInputs> load_scene_inputs(const SceneInputOptions& o) {
  SceneInputs in;
  if (o.closeup.empty()) return Status::error("--closeup: a close-up frame name is required");
  const fs::path root(o.scene_dir);
  auto need_dir = [&](const std::string& what) -> Status {
    if (o.scene_dir.empty()) return Status::error(what + ": give --scene-dir or the explicit path");
    return Status::ok();
  };
  // Splat.
  if (!o.scene.empty()) {
    in.scene_path = o.scene;
  } else {
    MACRO_TRY(need_dir("--scene"));
    MACRO_ASSIGN_OR_RETURN(in.scene_path, find_scene_ply(o.scene_dir));
  }
  // Reference cameras.
  if (!o.cameras.empty()) {
    in.cameras_path = o.cameras;
  } else {
    MACRO_TRY(need_dir("--cameras"));
    in.cameras_path = o.scene_dir;
  }
  MACRO_ASSIGN_OR_RETURN(gs::CameraSet cams, gs::load_cameras(in.cameras_path));
  // Images.
  if (!o.images.empty()) {
    in.images_dir = o.images;
  } else {
    MACRO_TRY(need_dir("--images"));
    in.images_dir = (root / "images").string();
  }
  if (!is_directory(in.images_dir))
    return Status::error(in.images_dir + ": images folder not found");
  // Close-up source.
  gs::CloseupSplit split;
  bool have_split = false;
  if (!o.closeups.empty()) {
    in.closeup_source = o.closeups;
  } else if (!o.scene_dir.empty() && file_exists((root / "split.json").string())) {
    in.closeup_source = (root / "split.json").string();
  }
  if (!in.closeup_source.empty()) {
    auto text = read_text_file(in.closeup_source);
    if (!text) return text.status();
    if (text->find("\"closeup_poses\"") != std::string::npos) {
      MACRO_ASSIGN_OR_RETURN(split, gs::load_closeup_split(in.closeup_source));
      have_split = true;
    }
  }
  // Resolve the close-up: COLMAP (reference model) first, then the split, then a camera file.
  const int registered = o.closeup_camera ? -1 : cams.index_of(o.closeup);
  if (o.closeup_camera) {
    in.closeup = *o.closeup_camera;
    in.closeup_pose_source = "given";
  } else if (registered >= 0) {
    in.closeup = cams.cameras[size_t(registered)];
    in.closeup_pose_source = "colmap";
  } else if (have_split) {
    auto c = split.closeups.find(o.closeup);
    if (!c) return c.status().with_context(in.closeup_source + ": close-up '" + o.closeup + "'");
    in.closeup = *c;
    in.closeup_pose_source = "split";
  } else if (!in.closeup_source.empty()) {
    MACRO_ASSIGN_OR_RETURN(gs::CameraSet cs, gs::load_cameras(in.closeup_source));
    auto c = cs.find(o.closeup);
    if (!c) return c.status().with_context(in.closeup_source);
    in.closeup = *c;
    in.closeup_pose_source = "cameras";
  } else {
    return Status::error("close-up '" + o.closeup + "' is not registered in " + in.cameras_path +
                         " and no split.json / --closeups file gives its pose");
  }
  in.closeup.name = o.closeup;
  // GT size, when present, sets the close-up render size.
  if (!o.scene_dir.empty() && !o.closeup_camera) {
    const fs::path gt = root / "closeup_gt" / fs::path(o.closeup).filename();
    if (file_exists(gt.string())) {
      auto img = gs::read_image(gt.string());
      if (!img) return img.status();
      if (img->width != in.closeup.width || img->height != in.closeup.height)
        in.closeup = in.closeup.resized(img->width, img->height);
    }
  }
  // Candidates.
  std::vector<std::string> excluded = split.closeup_frames;
  for (const gs::Camera& c : cams.cameras) {
    if (std::find(excluded.begin(), excluded.end(), c.name) != excluded.end()) continue;
    if (registered >= 0 && c.name == cams.cameras[size_t(registered)].name) {
      in.notes.push_back("candidate " + c.name + " skipped: it is the close-up frame");
      continue;
    }
    const std::string path = (fs::path(in.images_dir) / c.name).string();
    if (!file_exists(path)) {
      in.notes.push_back("candidate " + c.name + " skipped: no image " + path);
      continue;
    }
    in.candidates.push_back(c);
    in.candidate_images.push_back(path);
  }
  if (in.candidates.empty())
    return Status::error(in.cameras_path + ": no reference candidate has an image in " +
                         in.images_dir);
  // Distorted cameras are refused, not rendered as pinholes (docs/cameras.md §9).
  std::string dir = o.scene_dir;
  while (dir.size() > 1 && dir.back() == '/') dir.pop_back();
  const std::string remedy =
      dir.empty() ? "undistort the scene folder first (macro undistort --scene-dir DIR --out "
                    "NEW_DIR) and pass NEW_DIR's cameras and images"
                  : "undistort the scene folder first: macro undistort --scene-dir " + dir +
                        " --out " + dir + "_undistorted, then use " + dir + "_undistorted";
  MACRO_TRY(gs::refuse_distorted(in.closeup, "MACRO", remedy)
                .with_context(in.closeup_source.empty() ? in.cameras_path : in.closeup_source));
  for (const gs::Camera& c : in.candidates)
    MACRO_TRY(gs::refuse_distorted(c, "MACRO", remedy).with_context(in.cameras_path));
  // Splat last (the expensive part).
  MACRO_ASSIGN_OR_RETURN(in.cloud, gs::load_scene(in.scene_path, o.limits));
  return in;
}

Result<gs::Image> load_candidate_image(const SceneInputs& in, int k) {
  MACRO_CHECK(k >= 0 && size_t(k) < in.candidates.size());
  MACRO_ASSIGN_OR_RETURN(gs::Image img, gs::read_image(in.candidate_images[size_t(k)]));
  const gs::Camera& c = in.candidates[size_t(k)];
  if (img.width != c.width || img.height != c.height)
    return Status::error(in.candidate_images[size_t(k)] + ": image is " +
                         std::to_string(img.width) + "x" + std::to_string(img.height) +
                         ", camera '" + c.name + "' expects " + std::to_string(c.width) + "x" +
                         std::to_string(c.height));
  return img;
}

}  // namespace macro::enhance
