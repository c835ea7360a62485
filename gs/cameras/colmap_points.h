// COLMAP sparse 3D points (points3D.txt / points3D.bin), read and written.
//
//   points3D.txt: '#' comments, then per point one line
//                 "POINT3D_ID X Y Z R G B ERROR TRACK[] as (IMAGE_ID POINT2D_IDX)".
//   points3D.bin: little-endian (COLMAP src/colmap/scene/reconstruction_io.cc): u64 count; per
//   point
//                 u64 point3D_id, f64 x y z, u8 r g b, f64 error, u64 track_length, then
//                 track_length x (u32 image_id, u32 point2D_idx)          (>= 51 bytes per point)
//
// M = number of points, T = total track length. Every count is checked against the bytes left
// before anything is allocated; coordinates must be finite, ids unique, colours 0..255. Messages
// name the file, the line or the point, the field, what was expected and what was found.
// Tracks are kept as the file gives them (COLMAP image ids, 2D point indices); they are not checked
// against images.txt here.
#pragma once

#include <Eigen/Core>
#include <cstdint>
#include <string>
#include <vector>

#include "attention/runtime/status.h"

namespace macro::gs {

struct ColmapPoints {
  std::vector<int64_t> ids;               // [M] POINT3D_ID
  std::vector<Eigen::Vector3d> xyz;       // [M] world position (the COLMAP world frame)
  std::vector<uint8_t> rgb;               // [M*3]
  std::vector<double> error;              // [M] reprojection error
  std::vector<uint64_t> track_offsets;    // [M+1] point p observed by track_image_ids[o[p]..o[p+1])
  std::vector<uint32_t> track_image_ids;  // [T] COLMAP image ids
  std::vector<uint32_t> track_point2d;    // [T] POINT2D_IDX in that image
  std::string source;                     // the file it was read from

  size_t size() const { return xyz.size(); }
};

Result<ColmapPoints> load_colmap_points_text(const std::string& path);
Result<ColmapPoints> load_colmap_points_binary(const std::string& path);
// points3D.bin in `folder` if present, else points3D.txt; neither is an error naming the folder.
Result<ColmapPoints> load_colmap_points(const std::string& folder);

// The COLMAP model folder of a scene: the first of DIR, DIR/sparse/0, DIR/sparse,
// DIR/colmap/sparse/0 that holds cameras.{bin,txt} or images.{bin,txt} (load_cameras' order).
Result<std::string> find_colmap_model_folder(const std::string& dir);

// points3D.txt (atomic), in `points` order. Checks what the reader checks (finite positions, unique
// ids) and that the arrays have consistent sizes.
Status save_colmap_points_text(const ColmapPoints& points, const std::string& path);

}  // namespace macro::gs
