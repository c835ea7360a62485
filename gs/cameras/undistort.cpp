// Undistortion with OpenCV (gs/cameras/undistort.h has the steps and the pixel convention).
// W, H: source size; W', H': roi (output) size.
#include "gs/cameras/undistort.h"

#include <algorithm>
#include <cmath>
#include <mutex>
#include <opencv2/calib3d.hpp>
#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>

#include "gs/cameras/lens.h"

namespace macro::gs {
namespace {

void single_threaded_opencv() {
  static std::once_flag once;
  std::call_once(once, [] { cv::setNumThreads(0); });
}

// The largest rectangle found by peeling the border line (top, bottom, left or right) with the
// most invalid pixels until none is left; `valid` is [H, W]. False if nothing is left.
bool valid_rectangle(const cv::Mat& valid, cv::Rect* out) {
  int x0 = 0, y0 = 0, x1 = valid.cols, y1 = valid.rows;  // [x0, x1) x [y0, y1)
  auto row_bad = [&](int y) {
    int n = 0;
    for (int x = x0; x < x1; ++x) n += valid.at<uint8_t>(y, x) == 0;
    return n;
  };
  auto col_bad = [&](int x) {
    int n = 0;
    for (int y = y0; y < y1; ++y) n += valid.at<uint8_t>(y, x) == 0;
    return n;
  };
  while (x0 < x1 && y0 < y1) {
    const int bad[4] = {row_bad(y0), row_bad(y1 - 1), col_bad(x0), col_bad(x1 - 1)};
    const int worst = int(std::max_element(bad, bad + 4) - bad);
    if (bad[worst] == 0) break;
    if (worst == 0) ++y0;
    if (worst == 1) --y1;
    if (worst == 2) ++x0;
    if (worst == 3) --x1;
  }
  if (x0 >= x1 || y0 >= y1) return false;
  *out = cv::Rect(x0, y0, x1 - x0, y1 - y0);
  return true;
}

}  // namespace

const char* k_handover_name(KHandover h) {
  return h == KHandover::kGsplat ? "gsplat" : "centred";
}

bool parse_k_handover(const std::string& text, KHandover* out) {
  if (text == "gsplat")
    *out = KHandover::kGsplat;
  else if (text == "centred")
    *out = KHandover::kCentred;
  else
    return false;
  return true;
}

Result<Undistortion> plan_undistortion(const Camera& camera, KHandover handover) {
  MACRO_TRY(camera.validate());
  single_threaded_opencv();
  Undistortion u;
  u.source = camera;
  const int W = camera.width, H = camera.height;
  const cv::Size size(W, H);
  // kCentred: OpenCV's pixel centres are at integer coordinates, so the principal point moves by
  // half a pixel on the way in and back on the way out. kGsplat hands K over as it is.
  const double shift = handover == KHandover::kCentred ? 0.5 : 0.0;
  u.centre_shift = 0.5 - shift;
  const cv::Matx33d K(camera.fx, 0, camera.cx - shift, 0, camera.fy, camera.cy - shift, 0, 0, 1);
  const std::vector<double> D = opencv_coefficients(camera);
  cv::Mat new_k, map_x, map_y;
  cv::Rect roi(0, 0, W, H);
  try {
    if (!camera.has_distortion()) {
      new_k = cv::Mat(K);
      cv::initUndistortRectifyMap(K, cv::noArray(), cv::noArray(), new_k, size, CV_32FC1, map_x,
                                  map_y);
    } else if (camera.model == CameraModel::kOpenCVFisheye) {
      cv::fisheye::estimateNewCameraMatrixForUndistortRectify(K, D, size, cv::Matx33d::eye(), new_k,
                                                              0.0);
      cv::fisheye::initUndistortRectifyMap(K, D, cv::Matx33d::eye(), new_k, size, CV_32FC1, map_x,
                                           map_y);
      cv::Mat valid =
          (map_x >= 0.f) & (map_x <= float(W - 1)) & (map_y >= 0.f) & (map_y <= float(H - 1));
      if (!valid_rectangle(valid, &roi)) roi = cv::Rect();
    } else {
      new_k = cv::getOptimalNewCameraMatrix(K, D, size, 0.0, size, &roi);
      cv::initUndistortRectifyMap(K, D, cv::noArray(), new_k, size, CV_32FC1, map_x, map_y);
    }
  } catch (const cv::Exception& e) {
    return Status::error("camera '" + camera.name + "' (" + camera.model_text() +
                         "): OpenCV could not undistort it: " + e.what());
  }
  const double nfx = new_k.at<double>(0, 0), nfy = new_k.at<double>(1, 1);
  const double ncx = new_k.at<double>(0, 2) + shift, ncy = new_k.at<double>(1, 2) + shift;
  roi &= cv::Rect(0, 0, W, H);
  if (roi.width <= 0 || roi.height <= 0 || !std::isfinite(nfx) || !(nfx > 0) ||
      !std::isfinite(nfy) || !(nfy > 0) || !std::isfinite(ncx) || !std::isfinite(ncy)) {
    return Status::error("camera '" + camera.name + "' (" + camera.model_text() + ", " +
                         std::to_string(W) + "x" + std::to_string(H) +
                         "): the distortion leaves no valid undistorted region (roi " +
                         std::to_string(roi.width) + "x" + std::to_string(roi.height) +
                         "); the coefficients are probably wrong");
  }
  u.new_fx = nfx;
  u.new_fy = nfy;
  u.new_cx = ncx;
  u.new_cy = ncy;
  u.roi_x = roi.x;
  u.roi_y = roi.y;
  Camera& p = u.pinhole;
  p = camera;
  p.model = CameraModel::kPinhole;
  p.distortion.clear();
  p.width = roi.width;
  p.height = roi.height;
  p.fx = nfx;
  p.fy = nfy;
  p.cx = ncx - roi.x;
  p.cy = ncy - roi.y;
  MACRO_TRY(p.validate());
  u.map_x.resize(size_t(roi.width) * roi.height);
  u.map_y.resize(u.map_x.size());
  for (int i = 0; i < roi.height; ++i) {
    for (int j = 0; j < roi.width; ++j) {
      u.map_x[size_t(i) * roi.width + j] = map_x.at<float>(roi.y + i, roi.x + j);
      u.map_y[size_t(i) * roi.width + j] = map_y.at<float>(roi.y + i, roi.x + j);
    }
  }
  return u;
}

Result<Image> undistort_image(const Undistortion& u, const Image& image, const std::string& name) {
  const Camera& s = u.source;
  if (image.width != s.width || image.height != s.height) {
    return Status::error(name + ": image is " + std::to_string(image.width) + "x" +
                         std::to_string(image.height) + ", camera '" + s.name + "' expects " +
                         std::to_string(s.width) + "x" + std::to_string(s.height));
  }
  if (image.channels < 1 || image.channels > 4) {
    return Status::error(name + ": " + std::to_string(image.channels) +
                         " channels, expected 1 to 4");
  }
  single_threaded_opencv();
  const int Wp = u.pinhole.width, Hp = u.pinhole.height;
  Image out(Wp, Hp, image.channels);
  const cv::Mat src(image.height, image.width, CV_32FC(image.channels),
                    const_cast<float*>(image.data.data()));
  const cv::Mat mx(Hp, Wp, CV_32FC1, const_cast<float*>(u.map_x.data()));
  const cv::Mat my(Hp, Wp, CV_32FC1, const_cast<float*>(u.map_y.data()));
  cv::Mat dst(Hp, Wp, CV_32FC(image.channels), out.data.data());
  try {
    cv::remap(src, dst, mx, my, cv::INTER_LINEAR, cv::BORDER_CONSTANT, cv::Scalar::all(0));
  } catch (const cv::Exception& e) {
    return Status::error(name + ": OpenCV remap failed: " + e.what());
  }
  MACRO_CHECK(dst.data == reinterpret_cast<uint8_t*>(out.data.data()));
  return out;
}

Eigen::Vector2d source_position(const Undistortion& u, int i, int j) {
  const Camera& p = u.pinhole;
  const Camera& s = u.source;
  const double c = u.centre_shift;
  const Eigen::Vector2d ideal((j + 0.5 - (p.cx + c)) / p.fx, (i + 0.5 - (p.cy + c)) / p.fy);
  const Eigen::Vector2d d = distort_normalized(s, ideal);
  return {s.fx * d.x() + s.cx + c, s.fy * d.y() + s.cy + c};
}

}  // namespace macro::gs
