// load_cameras: which camera format a path holds (docs/cameras.md).
//   folder  COLMAP model in the folder, sparse/0/, sparse/, colmap/sparse/0/ (first found), else
//           transforms.json, else cameras.json.
//   file    cameras|images|points3D .txt/.bin -> the COLMAP model in its folder; otherwise JSON by
//           content: a list -> our cameras JSON; an object with "closeup_poses" -> DL3DV-Closeup
//           split; an object with "frames" -> nerfstudio transforms.json.
#include "attention/runtime/file_io.h"
#include "gs/cameras/camera.h"
#include "gs/cameras/cameras_json_fields.h"

namespace macro::gs {
namespace {

bool has_colmap_files(const std::string& dir) {
  return file_exists(dir + "/cameras.bin") || file_exists(dir + "/cameras.txt") ||
         file_exists(dir + "/images.bin") || file_exists(dir + "/images.txt");
}

std::string file_name_of(const std::string& path) {
  const size_t slash = path.find_last_of('/');
  return slash == std::string::npos ? path : path.substr(slash + 1);
}

std::string parent_dir(const std::string& path) {
  const size_t slash = path.find_last_of('/');
  return slash == std::string::npos ? std::string(".") : path.substr(0, slash);
}

Result<CameraSet> load_folder(const std::string& folder, const CameraLoadOptions& options,
                              CameraFormat* format) {
  std::string dir = folder;
  while (dir.size() > 1 && dir.back() == '/') dir.pop_back();
  for (const char* sub : {"", "/sparse/0", "/sparse", "/colmap/sparse/0"}) {
    if (has_colmap_files(dir + sub)) return load_colmap_sparse(dir + sub, format, options);
  }
  if (file_exists(dir + "/transforms.json")) {
    if (format) *format = CameraFormat::kNerfstudio;
    return load_nerfstudio(dir + "/transforms.json", options);
  }
  if (file_exists(dir + "/cameras.json")) {
    if (format) *format = CameraFormat::kJson;
    return load_cameras_json(dir + "/cameras.json", options);
  }
  return Status::error(folder +
                       ": no cameras found (looked for a COLMAP model in ., sparse/0, "
                       "sparse, colmap/sparse/0, then transforms.json and cameras.json)");
}

}  // namespace

Result<CameraSet> load_cameras(const std::string& path) {
  return load_cameras(path, {}, nullptr);
}

Result<CameraSet> load_cameras(const std::string& path, const CameraLoadOptions& options,
                               CameraFormat* format) {
  if (is_directory(path)) return load_folder(path, options, format);
  if (!file_exists(path)) return Status::error(path + ": no such file or folder");

  const std::string name = file_name_of(path);
  for (const char* colmap :
       {"cameras.txt", "images.txt", "points3D.txt", "cameras.bin", "images.bin", "points3D.bin"}) {
    if (name == colmap) return load_colmap_sparse(parent_dir(path), format, options);
  }

  MACRO_ASSIGN_OR_RETURN(detail::Json root, detail::parse_json_file(path));
  if (root.is_array()) {
    if (format) *format = CameraFormat::kJson;
    return load_cameras_json(path, options);
  }
  if (root.is_object() && root.contains("closeup_poses")) {
    if (format) *format = CameraFormat::kCloseupSplit;
    MACRO_ASSIGN_OR_RETURN(CloseupSplit split, load_closeup_split(path, options));
    return std::move(split.closeups);
  }
  if (root.is_object() && root.contains("frames")) {
    if (format) *format = CameraFormat::kNerfstudio;
    return load_nerfstudio(path, options);
  }
  return Status::error(path +
                       ": not a camera file: expected a list of cameras, a nerfstudio object "
                       "with 'frames' or a DL3DV-Closeup split with 'closeup_poses', found " +
                       detail::describe_json(root));
}

}  // namespace macro::gs
