// COLMAP sparse text writer: cameras.txt, images.txt (two lines per image, the 2D points line left
// empty) and an empty points3D.txt, each written atomically. Cameras with identical intrinsics
// share one camera id, as COLMAP does for a single physical camera.
#include <cstdio>
#include <filesystem>
#include <map>
#include <set>
#include <tuple>

#include "attention/runtime/file_io.h"
#include "gs/cameras/camera.h"

namespace macro::gs {
namespace {

std::string g17(double v) {
  char buf[40];
  std::snprintf(buf, sizeof buf, "%.17g", v);
  return buf;
}

// The COLMAP model name and parameter list of a camera. SIMPLE_RADIAL / RADIAL need fx = fy
// (else they are written as the equivalent OPENCV); OPENCV with k3 is written as the equivalent
// FULL_OPENCV (k4 = k5 = k6 = 0).
Result<std::pair<std::string, std::vector<double>>> colmap_params(const Camera& c,
                                                                  const std::string& where) {
  std::vector<double> p = {c.fx, c.fy, c.cx, c.cy};
  const std::vector<double>& d = c.distortion;
  auto with = [&](const char* model, std::vector<double> params, std::vector<double> coefs) {
    params.insert(params.end(), coefs.begin(), coefs.end());
    return std::make_pair(std::string(model), params);
  };
  const size_t need = size_t(camera_model_distortion_count(c.model));
  if (d.size() < need || d.size() > (c.model == CameraModel::kOpenCV ? 5 : need)) {
    return Status::error(where + ": camera '" + c.name + "': " + camera_model_name(c.model) +
                         " takes " + std::to_string(need) + " distortion parameters, found " +
                         std::to_string(d.size()));
  }
  switch (c.model) {
    case CameraModel::kPinhole:
      return std::make_pair(std::string("PINHOLE"), p);
    case CameraModel::kSimpleRadial:
      if (c.fx == c.fy) return with("SIMPLE_RADIAL", {c.fx, c.cx, c.cy}, d);
      return with("OPENCV", p, {d[0], 0, 0, 0});
    case CameraModel::kRadial:
      if (c.fx == c.fy) return with("RADIAL", {c.fx, c.cx, c.cy}, d);
      return with("OPENCV", p, {d[0], d[1], 0, 0});
    case CameraModel::kOpenCV:
      if (d.size() == 5 && d[4] != 0)
        return with("FULL_OPENCV", p, {d[0], d[1], d[2], d[3], d[4], 0, 0, 0});
      return with("OPENCV", p, {d[0], d[1], d[2], d[3]});
    case CameraModel::kFullOpenCV:
      return with("FULL_OPENCV", p, d);
    case CameraModel::kOpenCVFisheye:
      return with("OPENCV_FISHEYE", p, d);
  }
  return Status::error(where + ": camera '" + c.name + "': unknown model");
}

// Appends each field with a leading space, except at the start of a line.
void append_fields(std::string* line, std::initializer_list<std::string> fields) {
  for (const std::string& f : fields) {
    if (!line->empty() && line->back() != '\n') line->push_back(' ');
    line->append(f);
  }
}

}  // namespace

Status save_colmap_text(const CameraSet& set, const std::string& folder) {
  std::error_code ec;
  std::filesystem::create_directories(folder, ec);
  if (ec) return Status::error(folder + ": cannot create folder: " + ec.message());
  const std::string dir = folder.back() == '/' ? folder : folder + "/";

  using Key = std::tuple<std::string, int, int, std::vector<double>>;
  std::map<Key, int> camera_ids;
  std::string cameras_txt =
      "# Camera list with one line of data per camera:\n"
      "#   CAMERA_ID, MODEL, WIDTH, HEIGHT, PARAMS[]\n";
  std::string images_txt =
      "# Image list with two lines of data per image:\n"
      "#   IMAGE_ID, QW, QX, QY, QZ, TX, TY, TZ, CAMERA_ID, NAME\n"
      "#   POINTS2D[] as (X, Y, POINT3D_ID)\n";
  std::string camera_lines;
  // The cameras' own COLMAP image ids when each has a distinct positive one (so a points3D file
  // written beside stays valid), else 1..N in set order.
  std::set<int64_t> ids;
  for (const Camera& c : set.cameras)
    if (c.colmap_image_id > 0 && c.colmap_image_id <= INT32_MAX) ids.insert(c.colmap_image_id);
  const bool keep_ids = ids.size() == set.cameras.size();
  int64_t image_id = 0;
  for (const Camera& c : set.cameras) {
    MACRO_TRY(c.validate().with_context(dir + "images.txt"));
    if (c.name.empty() || c.name.find_first_of(" \t\r\n") != std::string::npos) {
      return Status::error(dir + "images.txt: camera name '" + c.name +
                           "' cannot be a COLMAP image name (empty or contains whitespace)");
    }
    MACRO_ASSIGN_OR_RETURN(auto model, colmap_params(c, dir + "cameras.txt"));
    Key key{model.first, c.width, c.height, model.second};
    auto [it, inserted] = camera_ids.emplace(key, int(camera_ids.size()) + 1);
    if (inserted) {
      append_fields(&camera_lines, {std::to_string(it->second), model.first,
                                    std::to_string(c.width), std::to_string(c.height)});
      for (double v : model.second) append_fields(&camera_lines, {g17(v)});
      camera_lines.push_back('\n');
    }
    const Eigen::Vector4d q = quaternion_wxyz_from_rotation(c.R);
    ++image_id;
    images_txt.append(std::to_string(keep_ids ? c.colmap_image_id : image_id));
    for (int k = 0; k < 4; ++k) append_fields(&images_txt, {g17(q[k])});
    for (int k = 0; k < 3; ++k) append_fields(&images_txt, {g17(c.t[k])});
    append_fields(&images_txt, {std::to_string(it->second), c.name});
    images_txt.append("\n\n");  // the image line and its empty 2D points line
  }
  cameras_txt.append("# Number of cameras: ")
      .append(std::to_string(camera_ids.size()))
      .append("\n");
  cameras_txt.append(camera_lines);
  MACRO_TRY(write_file_atomic(dir + "cameras.txt", cameras_txt));
  MACRO_TRY(write_file_atomic(dir + "images.txt", images_txt));
  return write_file_atomic(
      dir + "points3D.txt",
      "# 3D point list with one line of data per point:\n"
      "#   POINT3D_ID, X, Y, Z, R, G, B, ERROR, TRACK[] as (IMAGE_ID, POINT2D_IDX)\n"
      "# Number of points: 0\n");
}

}  // namespace macro::gs
