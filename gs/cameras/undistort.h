// Undistortion of a camera and its images to a pinhole camera, as gsplat's COLMAP parser does it
// (docs/cameras.md §9), with OpenCV (core, imgproc, calib3d; only undistort.cpp includes it):
//
//   perspective models (SIMPLE_RADIAL, RADIAL, OPENCV, FULL_OPENCV):
//     K', roi = cv::getOptimalNewCameraMatrix(K, D, (W, H), alpha = 0)
//     maps    = cv::initUndistortRectifyMap(K, D, I, K', (W, H), CV_32FC1)
//   OPENCV_FISHEYE:
//     K'      = cv::fisheye::estimateNewCameraMatrixForUndistortRectify(K, D, (W, H), I,
//                                                                       balance = 0)
//     maps    = cv::fisheye::initUndistortRectifyMap(K, D, I, K', (W, H), CV_32FC1)
//     roi     = the rectangle left after peeling border rows / columns (the one with the most
//               pixels mapped outside the source first) until every pixel maps inside
//   then the image is cv::remap'ed (bilinear, black outside), cropped to roi = (x, y, w, h), and
//   the pinhole camera is K' with cx -= x, cy -= y at size w x h.
//
// Pixel centres: OpenCV puts pixel (i, j)'s centre at (j, i), our convention (camera.h) and
// COLMAP's at (j + 0.5, i + 0.5). Two ways to hand K over (KHandover):
//   kGsplat (the default): K goes to OpenCV as COLMAP stores it and K' comes back unchanged, as
//     gsplat's parser does: the images are the ones gsplat trains on. Where the lens bends they
//     sample the source up to half a pixel away from where the pinhole camera K' sees the point.
//   kCentred: K goes with cx - 0.5, cy - 0.5 and K' comes back with + 0.5, so the undistorted
//     image is exact in our convention (`macro undistort --k-handover centred`).
// Without distortion both give the input camera and identity maps.
// OpenCV runs single-threaded here (cv::setNumThreads(0)): the thread pool owns every worker.
#pragma once

#include <Eigen/Core>
#include <vector>

#include "attention/runtime/status.h"
#include "gs/cameras/camera.h"
#include "gs/image_io.h"

namespace macro::gs {

struct Undistortion {
  Camera source;             // the distorted camera
  Camera pinhole;            // the undistorted camera: PINHOLE, roi size, same pose and name
  int roi_x = 0, roi_y = 0;  // roi origin in the uncropped undistorted image (pixels)
  // For each output pixel (row i, column j) of the pinhole image: where its centre samples the
  // source image, in OpenCV pixel indices (source pixel (r, c) has its centre at (c, r)); add 0.5
  // for our convention. [H', W'] each, H' = pinhole.height, W' = pinhole.width.
  std::vector<float> map_x, map_y;
  // K' before the crop, as the pinhole camera uses it (kCentred: OpenCV's + 0.5).
  double new_fx = 0, new_fy = 0, new_cx = 0, new_cy = 0;
  // 0.5 for kGsplat, 0 for kCentred: the principal point the maps effectively use is the
  // camera's plus this (source and pinhole alike); source_position accounts for it.
  double centre_shift = 0;
};

enum class KHandover { kGsplat, kCentred };
// "gsplat" / "centred"; parse_k_handover is false on anything else.
const char* k_handover_name(KHandover h);
bool parse_k_handover(const std::string& text, KHandover* out);

// The pinhole camera and the sampling maps for `camera` (any model; a camera without distortion
// gives itself, as PINHOLE, and identity maps). An error when the camera is invalid or the
// distortion leaves no valid region (an empty roi), naming the camera.
Result<Undistortion> plan_undistortion(const Camera& camera,
                                       KHandover handover = KHandover::kGsplat);

// `image` (the distorted camera's image, source.width x source.height, 1..4 channels) sampled to
// the pinhole camera. An error names `name` when the size does not match.
Result<Image> undistort_image(const Undistortion& u, const Image& image, const std::string& name);

// The source-image position (our convention) the distortion model itself puts the centre of
// output pixel (i, j) at: the pinhole ray through it, distorted by lens.h's formulas, both
// principal points moved by `centre_shift` (so under kGsplat this is where the maps sample, not
// where the pinhole camera sees the point). The tests
// compare this with `map_x/map_y`; exposed for them.
Eigen::Vector2d source_position(const Undistortion& u, int i, int j);

}  // namespace macro::gs
