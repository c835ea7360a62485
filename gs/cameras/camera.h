// Cameras. One internal convention everywhere (docs/cameras.md):
//   OpenCV axes (x right, y down, z forward), world-to-camera x_c = R x_w + t,
//   pixel (row i, column j) has its centre at (j + 0.5, i + 0.5); u = fx * x/z + cx.
// Loaders for other conventions (COLMAP, nerfstudio, DL3DV-Closeup split JSON) convert on load;
// the writers produce our JSON and COLMAP text. Distortion parameters are carried, never applied.
//
// Files: camera.cpp (Camera, CameraSet, pose conventions), cameras_load.cpp (format detection),
// cameras_json.cpp (our JSON), cameras_colmap*.cpp (COLMAP sparse text/binary, text writer),
// cameras_nerfstudio.cpp (transforms.json), cameras_split.cpp (DL3DV-Closeup split JSON).
#pragma once

#include <Eigen/Core>
#include <string>
#include <vector>

#include "attention/runtime/status.h"

namespace macro::gs {

enum class CameraModel { kPinhole, kOpenCV, kOpenCVFisheye };
// "PINHOLE", "OPENCV", "OPENCV_FISHEYE" (the COLMAP / nerfstudio spelling).
const char* camera_model_name(CameraModel model);
// Distortion parameter count a model carries: 0, 4 (k1 k2 p1 p2), 4 (k1 k2 k3 k4).
int camera_model_distortion_count(CameraModel model);

struct Camera {
  std::string name;
  int width = 0, height = 0;
  double fx = 0, fy = 0, cx = 0, cy = 0;
  Eigen::Matrix3d R = Eigen::Matrix3d::Identity();  // world -> camera rotation
  Eigen::Vector3d t = Eigen::Vector3d::Zero();      // world -> camera translation
  CameraModel model = CameraModel::kPinhole;
  std::vector<double>
      distortion;  // OPENCV: k1 k2 p1 p2 [k3...]; fisheye: k1..k4. Kept, not applied.
  // The image path exactly as the source stored it (nerfstudio file_path; COLMAP name and split
  // key, equal to `name` there). For nerfstudio `name` is its file name. find() accepts either.
  std::string file_path;

  Eigen::Vector3d center() const { return -R.transpose() * t; }
  // The same camera with intrinsics scaled to another image size (sx = new_w / width, ...):
  // fx, cx scale by sx and fy, cy by sy, which is exact for +0.5 pixel centres. Sizes must be > 0.
  Camera resized(int new_width, int new_height) const;
  // Checks: positive size, finite positive focal lengths, finite principal point, R orthonormal
  // with det +1 (tolerance 1e-4), finite t, finite distortion. The message names the camera and the
  // field.
  Status validate() const;

  Eigen::Matrix3d K() const;                             // [[fx,0,cx],[0,fy,cy],[0,0,1]]
  Eigen::Matrix4d world_to_camera() const;               // [R t; 0 0 0 1]
  Eigen::Matrix4d camera_to_world() const;               // its inverse (OpenCV axes)
  void set_world_to_camera(const Eigen::Matrix4d& w2c);  // takes R = w2c[0:3,0:3], t = w2c[0:3,3]
  // Pinhole projection of a world point, distortion ignored: (u, v) in pixels and camera depth z.
  Eigen::Vector3d project(const Eigen::Vector3d& x_world) const;
};

struct CameraSet {
  std::vector<Camera> cameras;
  std::string source;  // the file or folder it was loaded from (empty if built in memory)

  // Camera by name: an exact `name`, then an exact `file_path`, then the file name of the query
  // (so "images/frame_00001.png" finds "frame_00001.png"). An ambiguous or unknown name is an
  // error that lists a few available names.
  Result<Camera> find(const std::string& name) const;
  // Index of the camera find() would return, or -1.
  int index_of(const std::string& name) const;
};

// ---- Pose conventions (exposed for tests and writers) ------------------------------------------
// COLMAP quaternion (QW QX QY QZ, Hamilton, unit) -> rotation matrix.
Eigen::Matrix3d rotation_from_quaternion_wxyz(double qw, double qx, double qy, double qz);
// Rotation -> unit quaternion (qw, qx, qy, qz) with qw >= 0.
Eigen::Vector4d quaternion_wxyz_from_rotation(const Eigen::Matrix3d& R);
// OpenGL camera-to-world (x right, y up, z back) -> OpenCV world-to-camera: negate columns 1 and
// 2 of the rotation, then invert the rigid transform. The bottom row is not read.
Eigen::Matrix4d opencv_w2c_from_opengl_c2w(const Eigen::Matrix4d& c2w_gl);
Eigen::Matrix4d opengl_c2w_from_opencv_w2c(const Eigen::Matrix4d& w2c_cv);
// The inverse of a rigid transform [R t; 0 1].
Eigen::Matrix4d invert_rigid(const Eigen::Matrix4d& m);

// ---- Loading
// -------------------------------------------------------------------------------------
enum class CameraFormat { kJson, kColmapText, kColmapBinary, kNerfstudio, kCloseupSplit };
const char* camera_format_name(CameraFormat format);

struct CameraLoadOptions {
  // nerfstudio transforms.json: apply the inverse of `applied_transform` so the poses land in the
  // COLMAP (.ply) world frame. Off: keep the poses in the transforms.json world frame.
  bool undo_applied_transform = true;
};

// Any supported camera file, detected by content: our JSON list (golden cameras.json), a COLMAP
// sparse folder (cameras/images .txt or .bin), nerfstudio transforms.json, or a DL3DV-Closeup split
// JSON (close-up poses + intrinsics). A folder is searched for, in order: COLMAP files in the
// folder, sparse/0/, sparse/, colmap/sparse/0/, then transforms.json, cameras.json
// (docs/cameras.md). Every camera is validated. `format`, if given, receives what was detected.
Result<CameraSet> load_cameras(const std::string& path);
Result<CameraSet> load_cameras(const std::string& path, const CameraLoadOptions& options,
                               CameraFormat* format = nullptr);

// The format-specific loaders behind load_cameras.
Result<CameraSet> load_cameras_json(const std::string& path);
// `folder` holds cameras.bin + images.bin or cameras.txt + images.txt (binary preferred).
Result<CameraSet> load_colmap_sparse(const std::string& folder, CameraFormat* format = nullptr);
Result<CameraSet> load_colmap_text(const std::string& cameras_txt, const std::string& images_txt);
Result<CameraSet> load_colmap_binary(const std::string& cameras_bin, const std::string& images_bin);
Result<CameraSet> load_nerfstudio(const std::string& path, const CameraLoadOptions& options = {});

// ---- DL3DV-Closeup split JSON (docs/spec/macro-method.md §7)
// ------------------------------------------------
struct CloseupEvalPair {
  std::string training_frame;
  std::string closeup_frame;
  double depth_ratio = 0, iou = 0, angle_deg = 0, pair_score = 0;
};

struct CloseupSplit {
  std::string scene;                         // 64-hex scene id ("" if absent)
  int data_factor = 0;                       // image downscale of the intrinsics (0 if absent)
  std::vector<std::string> training_frames;  // "training_frames", or MobileClose "train_frames"
  bool has_closeup_frames = false;           // MobileClose: frames removed from the ref pool
  std::vector<std::string> closeup_frames;
  std::vector<CloseupEvalPair> closeup_eval_pairs;
  // One camera per `closeup_poses` entry, in file order, named by its key; the shared `intrinsics`
  // (pinhole or OPENCV with k1 k2 p1 p2), pose converted from OpenGL c2w to OpenCV w2c.
  CameraSet closeups;
};

Result<CloseupSplit> load_closeup_split(const std::string& path);

// ---- Writing (atomic)
// ------------------------------------------------------------------------------ Our JSON list:
// name, width, height, fx, fy, cx, cy, world_to_camera (4x4 row-major, OpenCV), and for distorted
// cameras "model" and "distortion". Numbers are written to round-trip exactly.
Status save_cameras_json(const CameraSet& set, const std::string& path);
// COLMAP text model in `folder` (created if missing): cameras.txt (one camera per distinct
// intrinsics), images.txt (empty 2D point lines), empty points3D.txt. Image names are the cameras'
// names; the DL3DV layout uses <scene>/sparse/0 with images/ beside it.
Status save_colmap_text(const CameraSet& set, const std::string& folder);

}  // namespace macro::gs
