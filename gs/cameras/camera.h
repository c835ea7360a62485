// Cameras. One internal convention everywhere (docs/cameras.md):
//   OpenCV axes (x right, y down, z forward), world-to-camera x_c = R x_w + t,
//   pixel (row i, column j) has its centre at (j + 0.5, i + 0.5); u = fx * x/z + cx.
// Loaders for other conventions (COLMAP, nerfstudio, DL3DV-Closeup split JSON) convert on load;
// the writers produce our JSON and COLMAP text. The renderer draws pinhole images: a camera with
// lens distortion is undistorted first (gs/cameras/undistort.h, `macro undistort`), and the
// commands that render refuse a distorted camera unless told to ignore the distortion.
//
// Files: camera.cpp (Camera, CameraSet, pose conventions), cameras_load.cpp (format detection),
// cameras_json.cpp (our JSON), cameras_colmap*.cpp (COLMAP sparse text/binary, text writer),
// cameras_nerfstudio.cpp (transforms.json), cameras_split.cpp (DL3DV-Closeup split JSON),
// lens.h (the distortion models' forward formulas), undistort.h (OpenCV undistortion).
#pragma once

#include <Eigen/Core>
#include <cstdint>
#include <string>
#include <vector>

#include "attention/runtime/status.h"

namespace macro::gs {

// The lens models, as COLMAP defines them (src/colmap/sensor/models.h; docs/cameras.md §1):
//   kPinhole        no distortion
//   kSimpleRadial   k                           (COLMAP SIMPLE_RADIAL; fx = fy)
//   kRadial         k1 k2                       (COLMAP RADIAL; fx = fy)
//   kOpenCV         k1 k2 p1 p2 [k3]            (COLMAP OPENCV, nerfstudio OPENCV with k3)
//   kFullOpenCV     k1 k2 p1 p2 k3 k4 k5 k6     (COLMAP FULL_OPENCV, OpenCV's rational model)
//   kOpenCVFisheye  k1 k2 k3 k4                 (COLMAP OPENCV_FISHEYE, OpenCV's fisheye model)
enum class CameraModel { kPinhole, kOpenCV, kOpenCVFisheye, kSimpleRadial, kRadial, kFullOpenCV };
// "PINHOLE", "OPENCV", "OPENCV_FISHEYE", "SIMPLE_RADIAL", "RADIAL", "FULL_OPENCV" (the COLMAP
// spelling).
const char* camera_model_name(CameraModel model);
// The model by that name, or false.
bool camera_model_from_name(const std::string& name, CameraModel* model);
// Distortion parameter count a model needs: 0, 4, 4, 1, 2, 8 (kOpenCV also takes a fifth, k3).
int camera_model_distortion_count(CameraModel model);

struct Camera {
  std::string name;
  int width = 0, height = 0;
  double fx = 0, fy = 0, cx = 0, cy = 0;
  Eigen::Matrix3d R = Eigen::Matrix3d::Identity();  // world -> camera rotation
  Eigen::Vector3d t = Eigen::Vector3d::Zero();      // world -> camera translation
  CameraModel model = CameraModel::kPinhole;
  std::vector<double> distortion;  // the model's coefficients, in COLMAP's order (above)
  // The image path exactly as the source stored it (nerfstudio file_path; COLMAP name and split
  // key, equal to `name` there). For nerfstudio `name` is its file name. find() accepts either.
  std::string file_path;
  // The COLMAP IMAGE_ID when read from images.{txt,bin} (0 otherwise). save_colmap_text keeps
  // these ids when every camera has a distinct one, so points3D tracks stay valid.
  int64_t colmap_image_id = 0;

  Eigen::Vector3d center() const { return -R.transpose() * t; }
  // A lens model other than pinhole with at least one non-zero coefficient: images from this
  // camera are not pinhole images, and rendering it as a pinhole is an approximation.
  bool has_distortion() const;
  // "OPENCV k1=0.5 k2=0 p1=0 p2=0" / "PINHOLE", for messages and listings.
  std::string model_text() const;
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

// An entry of a camera file that could not be read as a camera (non-strict loading).
struct RejectedCamera {
  int index = 0;        // entry index in the file: list index, frames[i], image line / record #i
  std::string name;     // its image name, or "" when it could not be read
  std::string message;  // why, naming the file and the field
};

struct CameraSet {
  std::vector<Camera> cameras;
  std::string source;  // the file or folder it was loaded from (empty if built in memory)
  // Entries left out because they were invalid (CameraLoadOptions::strict off). find() on one of
  // their names reports why instead of "no camera named".
  std::vector<RejectedCamera> rejected;

  // Camera by name: an exact `name`, then an exact `file_path`, then the file name of the query
  // (so "images/frame_00001.png" finds "frame_00001.png"), then the name without its extension
  // ("frame_00001" finds "frame_00001.png"). An ambiguous name is an error listing the candidates;
  // an unknown one lists a few available names; a rejected one says why it was rejected.
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
  // On: the first invalid entry fails the whole load (the message names it). Off (default): an
  // invalid entry (bad intrinsics, pose, unsupported model, missing field) is left out and listed
  // in CameraSet::rejected, and the rest load; an error that breaks the file's structure (bad
  // JSON, a truncated binary file) still fails, and so does a file with no valid camera.
  bool strict = false;
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
Result<CameraSet> load_cameras_json(const std::string& path, const CameraLoadOptions& options = {});
// `folder` holds cameras.bin + images.bin or cameras.txt + images.txt (binary preferred).
Result<CameraSet> load_colmap_sparse(const std::string& folder, CameraFormat* format = nullptr,
                                     const CameraLoadOptions& options = {});
Result<CameraSet> load_colmap_text(const std::string& cameras_txt, const std::string& images_txt,
                                   const CameraLoadOptions& options = {});
Result<CameraSet> load_colmap_binary(const std::string& cameras_bin, const std::string& images_bin,
                                     const CameraLoadOptions& options = {});
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
  // (any model of the table above), pose converted from OpenGL c2w to OpenCV w2c.
  CameraSet closeups;
};

Result<CloseupSplit> load_closeup_split(const std::string& path,
                                        const CameraLoadOptions& options = {});

// ---- Listing (`macro cameras`) -------------------------------------------------------------
// A table of the set, one camera a line: name, size, model with its coefficients, centre in
// world coordinates; then the rejected entries by index and name with their reasons.
std::string describe_cameras(const CameraSet& set, CameraFormat format);

// ---- Distortion guard ----------------------------------------------------------------------
// OK for a camera without distortion; otherwise an error naming the camera, its model and
// coefficients, that `what` ("macro render") draws pinhole images, and `remedy` (what to run or
// pass instead).
Status refuse_distorted(const Camera& camera, const std::string& what, const std::string& remedy);

// ---- Writing (atomic)
// ------------------------------------------------------------------------------ Our JSON list:
// name, width, height, fx, fy, cx, cy, world_to_camera (4x4 row-major, OpenCV), and for distorted
// cameras "model" and "distortion". Numbers are written to round-trip exactly.
Status save_cameras_json(const CameraSet& set, const std::string& path);
// COLMAP text model in `folder` (created if missing): cameras.txt (one camera per distinct
// intrinsics), images.txt (empty 2D point lines), empty points3D.txt. Image names are the cameras'
// names; image ids are the cameras' colmap_image_id when all are distinct and positive, else 1..N
// in set order. The DL3DV layout uses <scene>/sparse/0 with images/ beside it.
Status save_colmap_text(const CameraSet& set, const std::string& folder);

}  // namespace macro::gs
