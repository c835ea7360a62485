// Undistorting a scene folder (gs/cameras/undistort_scene.h has the layout).
#include "gs/cameras/undistort_scene.h"

#include <filesystem>
#include <map>
#include <tuple>

#include "attention/runtime/file_io.h"
#include "gs/cameras/cameras_json_fields.h"
#include "gs/cameras/colmap_points.h"
#include "gs/cameras/undistort.h"
#include "gs/image_io.h"

namespace macro::gs {
namespace {
namespace fs = std::filesystem;

// One plan per distinct intrinsics (a COLMAP camera is usually shared by every image).
class PlanCache {
 public:
  explicit PlanCache(KHandover handover) : handover_(handover) {}
  Result<const Undistortion*> get(const Camera& c) {
    Key key{int(c.model), c.width, c.height, c.fx, c.fy, c.cx, c.cy, c.distortion};
    auto it = plans_.find(key);
    if (it == plans_.end()) {
      MACRO_ASSIGN_OR_RETURN(Undistortion u, plan_undistortion(c, handover_));
      it = plans_.emplace(key, std::move(u)).first;
    }
    return &it->second;
  }
  int size() const { return int(plans_.size()); }

 private:
  using Key = std::tuple<int, int, int, double, double, double, double, std::vector<double>>;
  KHandover handover_;
  std::map<Key, Undistortion> plans_;
};

Status make_parent(const std::string& path) {
  std::error_code ec;
  fs::create_directories(fs::path(path).parent_path(), ec);
  if (ec) return Status::error(path + ": cannot create its folder: " + ec.message());
  return Status::ok();
}

Status copy_atomic(const std::string& from, const std::string& to) {
  MACRO_ASSIGN_OR_RETURN(std::vector<uint8_t> bytes, read_file(from));
  MACRO_TRY(make_parent(to));
  return write_file_atomic(to, bytes.data(), bytes.size());
}

enum class OutputKind { kPng, kJpeg, kOther };

OutputKind output_kind(const std::string& name) {
  std::string ext = fs::path(name).extension().string();
  for (char& ch : ext) ch = char(std::tolower(static_cast<unsigned char>(ch)));
  if (ext == ".png") return OutputKind::kPng;
  if (ext == ".jpg" || ext == ".jpeg") return OutputKind::kJpeg;
  return OutputKind::kOther;
}

// Undistorts `from` with `u` into `to`, in the format its name says: PNG, or JPEG at quality
// 100 (4:4:4; the image keeps its name, so cameras and splits stay valid). Other formats are
// refused, naming the file.
Status undistort_file(const Undistortion& u, const std::string& from, const std::string& to,
                      UndistortSceneReport& report, const Image* already_read = nullptr) {
  const OutputKind kind = output_kind(to);
  if (kind == OutputKind::kOther) {
    return Status::error(from + " (camera '" + u.source.name +
                         "'): undistorted images are written as PNG or JPEG, and this name ends "
                         "in neither .png, .jpg nor .jpeg");
  }
  Image loaded;
  if (!already_read) {
    MACRO_ASSIGN_OR_RETURN(loaded, read_image(from));
  }
  const Image& img = already_read ? *already_read : loaded;
  MACRO_ASSIGN_OR_RETURN(Image out, undistort_image(u, img, from));
  MACRO_TRY(make_parent(to));
  if (kind == OutputKind::kPng) return write_png(to, out);
  if (!report.jpeg_reencoded++) {
    report.notes.push_back("JPEG images are re-encoded at quality 100 (4:4:4), e.g. " + to);
  }
  return write_jpeg(to, out, 100);
}

// split.json: the intrinsics replaced by `pinhole`'s, the rest kept in file order.
Status write_split(const std::string& in_path, const std::string& out_path, const Camera& pinhole) {
  MACRO_ASSIGN_OR_RETURN(detail::Json root, detail::parse_json_file(in_path));
  detail::Json& in = root["intrinsics"];
  for (const char* key : {"k1", "k2", "k3", "k4", "k5", "k6", "p1", "p2"}) in.erase(key);
  in["w"] = pinhole.width;
  in["h"] = pinhole.height;
  in["fl_x"] = pinhole.fx;
  in["fl_y"] = pinhole.fy;
  in["cx"] = pinhole.cx;
  in["cy"] = pinhole.cy;
  in["camera_model"] = "PINHOLE";
  return write_file_atomic(out_path, root.dump(1) + "\n");
}

Status undistort_closeup_gt(const std::string& in_dir, const std::string& out_dir,
                            const Camera& intrinsics, PlanCache& plans,
                            UndistortSceneReport& report) {
  std::error_code ec;
  std::vector<fs::path> files;
  for (const auto& e : fs::directory_iterator(in_dir, ec))
    if (e.is_regular_file(ec)) files.push_back(e.path());
  if (ec) return Status::error(in_dir + ": cannot list: " + ec.message());
  std::sort(files.begin(), files.end());
  for (const fs::path& f : files) {
    const std::string to = (fs::path(out_dir) / f.filename()).string();
    if (!intrinsics.has_distortion()) {
      MACRO_TRY(copy_atomic(f.string(), to));
      continue;
    }
    MACRO_ASSIGN_OR_RETURN(Image img, read_image(f.string()));
    Camera c = intrinsics;
    c.name = f.filename().string();
    if (img.width != c.width || img.height != c.height) c = c.resized(img.width, img.height);
    MACRO_ASSIGN_OR_RETURN(const Undistortion* u, plans.get(c));
    MACRO_TRY(undistort_file(*u, f.string(), to, report, &img));
    ++report.undistorted;
  }
  return Status::ok();
}

}  // namespace

Result<UndistortSceneReport> undistort_scene_folder(const std::string& in_dir,
                                                    const std::string& out_dir,
                                                    const CameraLoadOptions& options,
                                                    KHandover handover) {
  std::error_code ec;
  if (!is_directory(in_dir)) return Status::error("--scene-dir " + in_dir + ": not a folder");
  if (out_dir.empty()) return Status::error("--out: an output folder is required");
  if (fs::exists(out_dir, ec) && fs::equivalent(in_dir, out_dir, ec))
    return Status::error("--out " + out_dir + ": is the input folder; choose a new folder");
  if (fs::exists(out_dir, ec) && !is_directory(out_dir))
    return Status::error("--out " + out_dir + ": exists and is not a folder");
  const fs::path in(in_dir), out(out_dir);

  MACRO_ASSIGN_OR_RETURN(CameraSet set, load_cameras(in_dir, options));
  UndistortSceneReport report;
  report.rejected = set.rejected;
  PlanCache plans(handover);
  CameraSet pinholes;
  pinholes.source = (out / "sparse" / "0").string();
  for (const Camera& c : set.cameras) {
    MACRO_ASSIGN_OR_RETURN(const Undistortion* u, plans.get(c));
    // The plan is shared by every camera with these intrinsics: only its intrinsics are taken;
    // name, pose and image id stay this camera's.
    Camera pinhole = c;
    pinhole.model = u->pinhole.model;
    pinhole.distortion = u->pinhole.distortion;
    pinhole.width = u->pinhole.width;
    pinhole.height = u->pinhole.height;
    pinhole.fx = u->pinhole.fx;
    pinhole.fy = u->pinhole.fy;
    pinhole.cx = u->pinhole.cx;
    pinhole.cy = u->pinhole.cy;
    pinholes.cameras.push_back(pinhole);
    const std::string from = (in / "images" / c.name).string();
    const std::string to = (out / "images" / c.name).string();
    if (!file_exists(from)) {
      report.notes.push_back("camera " + c.name + ": no image " + from + " (camera written)");
      continue;
    }
    if (c.has_distortion()) {
      MACRO_TRY(undistort_file(*u, from, to, report));
      ++report.undistorted;
    } else {
      MACRO_TRY(copy_atomic(from, to));
      ++report.copied;
    }
  }
  report.cameras = int(pinholes.cameras.size());
  const std::string sparse = (out / "sparse" / "0").string();
  MACRO_TRY(save_colmap_text(pinholes, sparse));
  // points3D: copied from the input's COLMAP model, replacing the empty points3D.txt.
  if (auto model = find_colmap_model_folder(in_dir); model) {
    if (file_exists(*model + "/points3D.bin")) {
      MACRO_TRY(copy_atomic(*model + "/points3D.bin", sparse + "/points3D.bin"));
      fs::remove(sparse + "/points3D.txt", ec);
    } else if (file_exists(*model + "/points3D.txt")) {
      MACRO_TRY(copy_atomic(*model + "/points3D.txt", sparse + "/points3D.txt"));
    } else {
      report.notes.push_back(*model + ": no points3D file; wrote an empty points3D.txt");
    }
  }
  // The split and the close-up ground truth.
  const std::string split_path = (in / "split.json").string();
  if (file_exists(split_path)) {
    MACRO_ASSIGN_OR_RETURN(CloseupSplit split, load_closeup_split(split_path, options));
    Camera intr = split.closeups.cameras.empty() ? Camera{} : split.closeups.cameras.front();
    if (split.closeups.cameras.empty()) return Status::error(split_path + ": no close-up poses");
    intr.name = "split.json intrinsics";
    MACRO_ASSIGN_OR_RETURN(const Undistortion* u, plans.get(intr));
    MACRO_TRY(write_split(split_path, (out / "split.json").string(), u->pinhole));
    if (is_directory((in / "closeup_gt").string())) {
      MACRO_TRY(undistort_closeup_gt((in / "closeup_gt").string(), (out / "closeup_gt").string(),
                                     intr, plans, report));
    }
  }
  // Everything else at the top level (the trained splat, ...) and point_cloud/ as they are.
  for (const auto& e : fs::directory_iterator(in, ec)) {
    const std::string name = e.path().filename().string();
    if (e.is_regular_file(ec) && name != "split.json") {
      MACRO_TRY(copy_atomic(e.path().string(), (out / name).string()));
    } else if (e.is_directory(ec) && name == "point_cloud") {
      fs::copy(e.path(), out / name,
               fs::copy_options::recursive | fs::copy_options::overwrite_existing, ec);
      if (ec) return Status::error(e.path().string() + ": cannot copy: " + ec.message());
    } else if (e.is_directory(ec) && name != "images" && name != "sparse" && name != "closeup_gt") {
      report.notes.push_back(e.path().string() + "/: not copied");
    }
  }
  report.intrinsics = plans.size();
  return report;
}

}  // namespace macro::gs
