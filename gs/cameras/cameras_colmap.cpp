// COLMAP sparse models: the camera model table, joining images with cameras, and finding the
// files in a folder. Text and binary parsing live in cameras_colmap_text.cpp and
// cameras_colmap_binary.cpp, the writer in cameras_colmap_writer.cpp.
#include "gs/cameras/cameras_colmap.h"

#include <algorithm>
#include <climits>
#include <cmath>
#include <unordered_map>

#include "attention/runtime/file_io.h"
#include "attention/runtime/text.h"

namespace macro::gs::detail {
namespace {

// COLMAP src/colmap/sensor/models.h: model ids and parameter counts.
constexpr ColmapModelInfo kModels[] = {
    {0, "SIMPLE_PINHOLE", 3, true},          // f cx cy
    {1, "PINHOLE", 4, true},                 // fx fy cx cy
    {2, "SIMPLE_RADIAL", 4, true},           // f cx cy k
    {3, "RADIAL", 5, true},                  // f cx cy k1 k2
    {4, "OPENCV", 8, true},                  // fx fy cx cy k1 k2 p1 p2
    {5, "OPENCV_FISHEYE", 8, true},          // fx fy cx cy k1 k2 k3 k4
    {6, "FULL_OPENCV", 12, true},            // fx fy cx cy k1 k2 p1 p2 k3 k4 k5 k6
    {7, "FOV", 5, false},                    // fx fy cx cy omega
    {8, "SIMPLE_RADIAL_FISHEYE", 4, false},  // f cx cy k
    {9, "RADIAL_FISHEYE", 5, false},         // f cx cy k1 k2
    {10, "THIN_PRISM_FISHEYE", 12, false},
    {11, "RAD_TAN_THIN_PRISM_FISHEYE", 16, false},
};

}  // namespace

const ColmapModelInfo* colmap_model_by_id(int64_t id) {
  for (const auto& m : kModels) {
    if (m.id == id) return &m;
  }
  return nullptr;
}

const ColmapModelInfo* colmap_model_by_name(const std::string& name) {
  for (const auto& m : kModels) {
    if (name == m.name) return &m;
  }
  return nullptr;
}

std::string colmap_supported_models() {
  return "SIMPLE_PINHOLE, PINHOLE, SIMPLE_RADIAL, RADIAL, OPENCV, OPENCV_FISHEYE, FULL_OPENCV";
}

Result<CameraSet> assemble_colmap(const std::vector<ColmapCameraRecord>& cameras,
                                  const std::vector<ColmapImageRecord>& images,
                                  const std::string& cameras_path, const std::string& source,
                                  const CameraLoadOptions& options,
                                  std::vector<RejectedCamera> rejected) {
  if (options.strict && !rejected.empty()) return Status::error(rejected.front().message);
  std::unordered_map<int64_t, const ColmapCameraRecord*> by_id;
  std::unordered_map<int64_t, std::string> bad_camera;  // camera id -> why it is invalid
  for (const ColmapCameraRecord& c : cameras) {
    if (!by_id.emplace(c.id, &c).second) {
      return Status::error(c.where + ": camera id " + std::to_string(c.id) + " appears twice");
    }
    std::string error = c.error;
    if (error.empty() &&
        (c.width <= 0 || c.height <= 0 || c.width > INT_MAX || c.height > INT_MAX)) {
      error = c.where + ": camera " + std::to_string(c.id) + ": size " + std::to_string(c.width) +
              "x" + std::to_string(c.height) + ": expected width and height in 1.." +
              std::to_string(INT_MAX);
    }
    if (!error.empty()) {
      if (options.strict) return Status::error(error);
      bad_camera[c.id] = error;
      continue;
    }
    MACRO_CHECK(c.model && c.model->supported && int(c.params.size()) == c.model->num_params);
  }

  CameraSet set;
  set.source = source;
  set.rejected = std::move(rejected);
  set.cameras.reserve(images.size());
  std::unordered_map<int64_t, int> seen_image_ids;
  for (size_t index = 0; index < images.size(); ++index) {
    const ColmapImageRecord& im = images[index];
    const std::string where = im.where + " (image " + std::to_string(im.id) + " '" + im.name + "')";
    auto reject = [&](const std::string& message) -> Status {
      if (options.strict) return Status::error(message);
      set.rejected.push_back({int(index), im.name, message});
      return Status::ok();
    };
    if (!seen_image_ids.emplace(im.id, 0).second) {
      MACRO_TRY(reject(where + ": image id " + std::to_string(im.id) + " appears twice"));
      continue;
    }
    if (auto bad = bad_camera.find(im.camera_id); bad != bad_camera.end()) {
      MACRO_TRY(reject(where + ": its camera " + std::to_string(im.camera_id) +
                       " is invalid: " + bad->second));
      continue;
    }
    auto it = by_id.find(im.camera_id);
    if (it == by_id.end()) {
      std::string ids;
      int shown = 0;
      for (const ColmapCameraRecord& c : cameras) {
        if (shown++ == 5) {
          ids += ", ...";
          break;
        }
        ids += (ids.empty() ? "" : ", ") + std::to_string(c.id);
      }
      MACRO_TRY(reject(where + ": camera id " + std::to_string(im.camera_id) + " is not in " +
                       cameras_path + " (its ids: " + (ids.empty() ? "none" : ids) + ")"));
      continue;
    }
    const double qn =
        std::sqrt(im.q[0] * im.q[0] + im.q[1] * im.q[1] + im.q[2] * im.q[2] + im.q[3] * im.q[3]);
    if (!(std::abs(qn - 1.0) <= 1e-3)) {
      MACRO_TRY(reject(where + ": quaternion (QW QX QY QZ) = (" + format_number(im.q[0]) + ", " +
                       format_number(im.q[1]) + ", " + format_number(im.q[2]) + ", " + format_number(im.q[3]) + ") has norm " +
                       format_number(qn) + ", expected a unit quaternion"));
      continue;
    }
    const ColmapCameraRecord& rec = *it->second;
    const std::vector<double>& p = rec.params;
    Camera cam;
    cam.name = im.name;
    cam.file_path = im.name;
    cam.colmap_image_id = im.id;
    cam.width = static_cast<int>(rec.width);
    cam.height = static_cast<int>(rec.height);
    const std::string model = rec.model->name;
    // Models with one focal length: f cx cy [k [k2]]; the others fx fy cx cy [coefficients].
    const bool single_f =
        model == "SIMPLE_PINHOLE" || model == "SIMPLE_RADIAL" || model == "RADIAL";
    const size_t first_coef = single_f ? 3 : 4;
    if (single_f) {
      cam.fx = cam.fy = p[0];
      cam.cx = p[1];
      cam.cy = p[2];
    } else {
      cam.fx = p[0];
      cam.fy = p[1];
      cam.cx = p[2];
      cam.cy = p[3];
    }
    if (model != "SIMPLE_PINHOLE" && model != "PINHOLE") {
      const bool known = camera_model_from_name(model, &cam.model);
      MACRO_CHECK(known);
      cam.distortion.assign(p.begin() + first_coef, p.end());
    }
    cam.R = rotation_from_quaternion_wxyz(im.q[0], im.q[1], im.q[2], im.q[3]);
    cam.t = Eigen::Vector3d(im.t[0], im.t[1], im.t[2]);
    if (Status s = cam.validate().with_context(im.where); !s) {
      MACRO_TRY(reject(s.message()));
      continue;
    }
    set.cameras.push_back(std::move(cam));
  }
  // Image ids are arbitrary; like the Inria and gsplat parsers, order by name.
  std::stable_sort(set.cameras.begin(), set.cameras.end(),
                   [](const Camera& a, const Camera& b) { return a.name < b.name; });
  return finish_lenient_load(std::move(set), cameras_path);
}

}  // namespace macro::gs::detail

namespace macro::gs {

Result<CameraSet> load_colmap_sparse(const std::string& folder, CameraFormat* format,
                                     const CameraLoadOptions& options) {
  const std::string dir = folder.empty() || folder.back() == '/' ? folder : folder + "/";
  const bool cb = file_exists(dir + "cameras.bin"), ib = file_exists(dir + "images.bin");
  const bool ct = file_exists(dir + "cameras.txt"), it = file_exists(dir + "images.txt");
  if (cb && ib) {
    if (format) *format = CameraFormat::kColmapBinary;
    return load_colmap_binary(dir + "cameras.bin", dir + "images.bin", options);
  }
  if (ct && it) {
    if (format) *format = CameraFormat::kColmapText;
    return load_colmap_text(dir + "cameras.txt", dir + "images.txt", options);
  }
  if (cb || ct)
    return Status::error(folder + ": has " + (cb ? "cameras.bin" : "cameras.txt") + " but no " +
                         (cb ? "images.bin" : "images.txt"));
  if (ib || it)
    return Status::error(folder + ": has " + (ib ? "images.bin" : "images.txt") + " but no " +
                         (ib ? "cameras.bin" : "cameras.txt"));
  return Status::error(folder +
                       ": no COLMAP model (expected cameras.bin + images.bin or "
                       "cameras.txt + images.txt)");
}

}  // namespace macro::gs
