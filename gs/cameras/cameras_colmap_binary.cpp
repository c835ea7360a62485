// COLMAP sparse binary model, little-endian (COLMAP src/colmap/scene/reconstruction_io.cc):
//   cameras.bin: u64 count; per camera: u32 camera_id, i32 model_id, u64 width, u64 height,
//                f64 params[num_params(model)]                       (24 + 8 * num_params bytes)
//   images.bin:  u64 count; per image: u32 image_id, f64 qw qx qy qz, f64 tx ty tz, u32 camera_id,
//                name bytes + '\0', u64 num_points2D, then num_points2D x (f64 x, f64 y,
//                u64 point3D_id)                                    (>= 64 + 1 + 8 bytes)
// Every count is checked against the bytes left before anything is allocated or skipped.
#include <cstdint>
#include <cstring>

#include "attention/runtime/file_io.h"
#include "gs/cameras/camera.h"
#include "gs/cameras/cameras_colmap.h"

namespace macro::gs {
namespace {

using detail::ColmapCameraRecord;
using detail::ColmapImageRecord;

// Bounds-checked little-endian cursor over a whole file.
class ByteReader {
 public:
  ByteReader(const std::vector<uint8_t>& data, std::string path)
      : data_(data), path_(std::move(path)) {}

  uint64_t offset() const { return pos_; }
  uint64_t left() const { return data_.size() - pos_; }
  const std::string& path() const { return path_; }

  Status need(uint64_t bytes, const std::string& what) const {
    if (bytes <= left()) return Status::ok();
    return Status::error(what + ": file truncated at byte " + std::to_string(pos_) + ": needs " +
                         std::to_string(bytes) + " bytes, " + std::to_string(left()) + " left");
  }
  template <typename T>
  Result<T> read(const std::string& what) {
    MACRO_TRY(need(sizeof(T), what));
    T v;
    std::memcpy(&v, data_.data() + pos_, sizeof(T));  // x86-64 is little-endian, like the files
    pos_ += sizeof(T);
    return v;
  }
  Status skip(uint64_t bytes, const std::string& what) {
    MACRO_TRY(need(bytes, what));
    pos_ += bytes;
    return Status::ok();
  }
  Result<std::string> read_cstring(const std::string& what) {
    const void* end = std::memchr(data_.data() + pos_, 0, left());
    if (!end) {
      return Status::error(what + ": file truncated at byte " + std::to_string(pos_) +
                           ": no terminating NUL before the end of the file");
    }
    const size_t n = static_cast<const uint8_t*>(end) - (data_.data() + pos_);
    std::string s(reinterpret_cast<const char*>(data_.data() + pos_), n);
    pos_ += n + 1;
    return s;
  }

 private:
  const std::vector<uint8_t>& data_;
  std::string path_;
  uint64_t pos_ = 0;
};

// Checks a count against the file: `count` records of at least `min_bytes` each must fit. `what`
// starts with the file name.
Status check_count(const ByteReader& r, uint64_t count, uint64_t min_bytes,
                   const std::string& what) {
  if (count <= r.left() / min_bytes) return Status::ok();
  return Status::error(what + " count " + std::to_string(count) + " at byte " +
                       std::to_string(r.offset()) + " needs at least " + std::to_string(min_bytes) +
                       " bytes each, only " + std::to_string(r.left()) +
                       " bytes left (truncated or not a COLMAP file)");
}

// An unsupported model (its parameter count is known) is kept with `error` set when non-strict.
Result<std::vector<ColmapCameraRecord>> parse_cameras_bin(const std::string& path, bool strict) {
  MACRO_ASSIGN_OR_RETURN(std::vector<uint8_t> bytes, read_file(path));
  ByteReader r(bytes, path);
  MACRO_ASSIGN_OR_RETURN(uint64_t count, r.read<uint64_t>(path + ": camera count"));
  MACRO_TRY(check_count(r, count, 24, path + ": camera"));
  std::vector<ColmapCameraRecord> cams;
  cams.reserve(count);
  for (uint64_t i = 0; i < count; ++i) {
    ColmapCameraRecord c;
    c.where =
        path + ": camera #" + std::to_string(i) + " (byte " + std::to_string(r.offset()) + ")";
    MACRO_ASSIGN_OR_RETURN(uint32_t id, r.read<uint32_t>(c.where + " camera_id"));
    MACRO_ASSIGN_OR_RETURN(int32_t model_id, r.read<int32_t>(c.where + " model_id"));
    MACRO_ASSIGN_OR_RETURN(uint64_t w, r.read<uint64_t>(c.where + " width"));
    MACRO_ASSIGN_OR_RETURN(uint64_t h, r.read<uint64_t>(c.where + " height"));
    c.id = id;
    c.width = w > uint64_t(INT64_MAX) ? INT64_MAX : int64_t(w);
    c.height = h > uint64_t(INT64_MAX) ? INT64_MAX : int64_t(h);
    c.model = detail::colmap_model_by_id(model_id);
    if (!c.model) {
      return Status::error(c.where + ": camera " + std::to_string(id) +
                           ": unknown camera model id " + std::to_string(model_id) +
                           " (supported: " + detail::colmap_supported_models() + ")");
    }
    if (!c.model->supported) {
      c.error = c.where + ": camera " + std::to_string(id) + ": camera model " + c.model->name +
                " (id " + std::to_string(model_id) +
                ") is not supported (supported: " + detail::colmap_supported_models() + ")";
      if (strict) return Status::error(c.error);
    }
    c.params.resize(c.model->num_params);
    for (int k = 0; k < c.model->num_params; ++k) {
      MACRO_ASSIGN_OR_RETURN(c.params[k],
                             r.read<double>(c.where + " params[" + std::to_string(k) + "]"));
    }
    cams.push_back(std::move(c));
  }
  if (r.left() != 0) {
    return Status::error(path + ": " + std::to_string(r.left()) + " unexpected bytes after " +
                         std::to_string(count) + " cameras");
  }
  return cams;
}

Result<std::vector<ColmapImageRecord>> parse_images_bin(const std::string& path) {
  MACRO_ASSIGN_OR_RETURN(std::vector<uint8_t> bytes, read_file(path));
  ByteReader r(bytes, path);
  MACRO_ASSIGN_OR_RETURN(uint64_t count, r.read<uint64_t>(path + ": image count"));
  MACRO_TRY(check_count(r, count, 64 + 1 + 8, path + ": image"));
  std::vector<ColmapImageRecord> images;
  images.reserve(count);
  for (uint64_t i = 0; i < count; ++i) {
    ColmapImageRecord im;
    im.where =
        path + ": image #" + std::to_string(i) + " (byte " + std::to_string(r.offset()) + ")";
    MACRO_ASSIGN_OR_RETURN(uint32_t id, r.read<uint32_t>(im.where + " image_id"));
    im.id = id;
    for (int k = 0; k < 4; ++k) {
      MACRO_ASSIGN_OR_RETURN(im.q[k], r.read<double>(im.where + " quaternion"));
    }
    for (int k = 0; k < 3; ++k) {
      MACRO_ASSIGN_OR_RETURN(im.t[k], r.read<double>(im.where + " translation"));
    }
    MACRO_ASSIGN_OR_RETURN(uint32_t cam_id, r.read<uint32_t>(im.where + " camera_id"));
    im.camera_id = cam_id;
    MACRO_ASSIGN_OR_RETURN(im.name, r.read_cstring(im.where + " name"));
    MACRO_ASSIGN_OR_RETURN(uint64_t npts, r.read<uint64_t>(im.where + " num_points2D"));
    MACRO_TRY(check_count(r, npts, 24, im.where + " '" + im.name + "' points2D"));
    MACRO_TRY(r.skip(npts * 24, im.where + " points2D"));
    images.push_back(std::move(im));
  }
  if (r.left() != 0) {
    return Status::error(path + ": " + std::to_string(r.left()) + " unexpected bytes after " +
                         std::to_string(count) + " images");
  }
  return images;
}

}  // namespace

Result<CameraSet> load_colmap_binary(const std::string& cameras_bin, const std::string& images_bin,
                                     const CameraLoadOptions& options) {
  MACRO_ASSIGN_OR_RETURN(auto cams, parse_cameras_bin(cameras_bin, options.strict));
  MACRO_ASSIGN_OR_RETURN(auto images, parse_images_bin(images_bin));
  // A model without images gives no cameras; every caller needs at least one, so an image count
  // of 0 is refused here, naming the file, instead of failing later as "no camera named ...".
  if (images.empty())
    return Status::error(images_bin + ": image count 0: a COLMAP model needs at least one " +
                         "registered image");
  const size_t slash = cameras_bin.find_last_of('/');
  const std::string folder =
      slash == std::string::npos ? cameras_bin : cameras_bin.substr(0, slash);
  return detail::assemble_colmap(cams, images, cameras_bin, folder, options);
}

}  // namespace macro::gs
