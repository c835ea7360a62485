// Project stage: every Gaussian -> screen-space conic, opacity, colour, depth and tile count.
//
// Legend: N Gaussians; K = (degree+1)^2 SH coefficients per channel.
// Math (gsplat fully_fused_projection, docs/spec/gs-rasterizer.md §1.2, §1.5, §1.7):
//   t = R p + t_cam; culled unless near < t.z < far
//   Sigma = (R_q S)(R_q S)^T; Sigma_2D = J W Sigma W^T J^T, J at the clamped tx/tz, ty/tz
//   dilation eps (0.3, mip 0.1); det <= 0 culled; conic = inverse
//   antialiased: o *= sqrt(max(0.005^2, det0/det)); mip: o *= sqrt(det0/(det+1e-6)+1e-6)
//   culled if o < 1/255; cutoff d^2 <= 2 ln(255 o) gives the ellipse that can reach alpha 1/255
//   rgb = max(0, SH(dir) + 0.5), dir = normalise(p - camera centre)
#include <atomic>
#include <cmath>
#include <cstring>

#include "gs/raster/raster_stages.h"

namespace macro::gs::raster {
static_assert(int(RasterMode::kClassic) == kModeClassic &&
              int(RasterMode::kAntialiased) == kModeAntialiased &&
              int(RasterMode::kMip) == kModeMip);
namespace {

// SH basis constants (Inria / gsplat sh_utils).
constexpr float kC1 = 0.4886025119029199f;
constexpr float kC2[5] = {1.0925484305920792f, -1.0925484305920792f, 0.31539156525252005f,
                          -1.0925484305920792f, 0.5462742152960396f};
constexpr float kC3[7] = {-0.5900435899266435f, 2.890611442640554f,   -0.4570457994644658f,
                          0.3731763325901154f,  -0.4570457994644658f, 1.445305721320277f,
                          -0.5900435899266435f};

// sh: [K,3] coefficients of one Gaussian; degree <= 3. Returns SH(dir) per channel (no +0.5).
inline void eval_sh(const float* sh, int degree, float x, float y, float z, float out[3]) {
  float basis[16];
  basis[0] = kShC0;
  int k = 1;
  if (degree >= 1) {
    basis[1] = -kC1 * y;
    basis[2] = kC1 * z;
    basis[3] = -kC1 * x;
    k = 4;
  }
  if (degree >= 2) {
    const float xx = x * x, yy = y * y, zz = z * z;
    basis[4] = kC2[0] * x * y;
    basis[5] = kC2[1] * y * z;
    basis[6] = kC2[2] * (2.f * zz - xx - yy);
    basis[7] = kC2[3] * x * z;
    basis[8] = kC2[4] * (xx - yy);
    k = 9;
    if (degree >= 3) {
      basis[9] = kC3[0] * y * (3.f * xx - yy);
      basis[10] = kC3[1] * x * y * z;
      basis[11] = kC3[2] * y * (4.f * zz - xx - yy);
      basis[12] = kC3[3] * z * (2.f * zz - 3.f * xx - 3.f * yy);
      basis[13] = kC3[4] * x * (4.f * zz - xx - yy);
      basis[14] = kC3[5] * z * (xx - yy);
      basis[15] = kC3[6] * x * (xx - 3.f * yy);
      k = 16;
    }
  }
  float r = 0.f, g = 0.f, b = 0.f;
  for (int i = 0; i < k; ++i) {
    r += basis[i] * sh[3 * i + 0];
    g += basis[i] * sh[3 * i + 1];
    b += basis[i] * sh[3 * i + 2];
  }
  out[0] = r;
  out[1] = g;
  out[2] = b;
}

inline bool finite3(const float* v) {
  return std::isfinite(v[0]) && std::isfinite(v[1]) && std::isfinite(v[2]);
}

enum Fate : uint8_t {
  kVisible = kFateVisible,
  kDepth = kFateDepth,
  kInvalid = kFateInvalid,
  kFaint = kFateFaint,
  kOffscreen = kFateOffscreen
};

Fate geometry_one(const ProjectInput& in, size_t g, TileSplat* s) {
  const CameraF& cam = *in.cam;
  const float* p = &in.position[3 * g];
  const float* sc = &in.scale[3 * g];
  const float* q = &in.rotation[4 * g];
  float opacity = in.opacity[g];
  if (!finite3(p) || !finite3(sc) || !finite3(q) || !std::isfinite(q[3]) || !std::isfinite(opacity))
    return Fate::kInvalid;

  // Camera space.
  const float* R = cam.R;
  const float tx = R[0] * p[0] + R[1] * p[1] + R[2] * p[2] + cam.t[0];
  const float ty = R[3] * p[0] + R[4] * p[1] + R[5] * p[2] + cam.t[1];
  const float tz = R[6] * p[0] + R[7] * p[1] + R[8] * p[2] + cam.t[2];
  if (!(tz > in.near_plane && tz < in.far_plane)) return Fate::kDepth;

  // Rotation of the Gaussian (normalised quaternion w, x, y, z) times its scales: M = R_q S.
  const float qn = std::sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]);
  if (!(qn > 0.f) || !std::isfinite(qn)) return Fate::kInvalid;
  const float iq = 1.f / qn;
  const float w = q[0] * iq, x = q[1] * iq, y = q[2] * iq, z = q[3] * iq;
  const float Rq[9] = {
      1.f - 2.f * (y * y + z * z), 2.f * (x * y - w * z),       2.f * (x * z + w * y),
      2.f * (x * y + w * z),       1.f - 2.f * (x * x + z * z), 2.f * (y * z - w * x),
      2.f * (x * z - w * y),       2.f * (y * z + w * x),       1.f - 2.f * (x * x + y * y)};

  // Jacobian of the perspective projection at the clamped position (gsplat persp_proj).
  const float rz = 1.f / tz, rz2 = rz * rz;
  const float txc = tz * std::min(cam.lim_x_pos, std::max(-cam.lim_x_neg, tx * rz));
  const float tyc = tz * std::min(cam.lim_y_pos, std::max(-cam.lim_y_neg, ty * rz));
  const float j00 = cam.fx * rz, j02 = -cam.fx * txc * rz2;
  const float j11 = cam.fy * rz, j12 = -cam.fy * tyc * rz2;
  // JW [2,3] = J R_cam.
  float JW[6];
  for (int k = 0; k < 3; ++k) {
    JW[k] = j00 * R[k] + j02 * R[6 + k];
    JW[3 + k] = j11 * R[3 + k] + j12 * R[6 + k];
  }
  // A [2,3] = JW R_q S;  Sigma_2D = A A^T.
  float A[6];
  for (int r = 0; r < 2; ++r)
    for (int k = 0; k < 3; ++k)
      A[3 * r + k] =
          (JW[3 * r] * Rq[k] + JW[3 * r + 1] * Rq[3 + k] + JW[3 * r + 2] * Rq[6 + k]) * sc[k];
  float sxx = A[0] * A[0] + A[1] * A[1] + A[2] * A[2];
  float sxy = A[0] * A[3] + A[1] * A[4] + A[2] * A[5];
  float syy = A[3] * A[3] + A[4] * A[4] + A[5] * A[5];
  const float det0 = sxx * syy - sxy * sxy;
  const float eps = in.mode == kModeMip ? kMipKernelSize : kEps2d;
  sxx += eps;
  syy += eps;
  const float det = sxx * syy - sxy * sxy;
  if (!(det > 0.f) || !std::isfinite(det) || !std::isfinite(sxx) || !std::isfinite(syy))
    return Fate::kInvalid;

  if (in.mode == kModeAntialiased) {
    opacity *= std::sqrt(std::max(kAaCompFloor, det0 / det));
  } else if (in.mode == kModeMip) {
    const float d0 = std::max(kMipDetEps, det0), d1 = std::max(kMipDetEps, det);
    float coef = std::sqrt(d0 / (d1 + kMipDetEps) + kMipDetEps);
    if (d0 <= kMipDetEps || d1 <= kMipDetEps) coef = 0.f;
    opacity *= coef;
  }
  if (!(opacity >= kMinAlpha)) return Fate::kFaint;
  const float cutoff =
      2.f * std::log(opacity / kMinAlpha) * (1.f + kCutoffRelMargin) + kCutoffAbsMargin;

  s->x = cam.fx * tx * rz + cam.cx;
  s->y = cam.fy * ty * rz + cam.cy;
  const float inv_det = 1.f / det;
  s->a = syy * inv_det;
  s->b = -sxy * inv_det;
  s->c = sxx * inv_det;
  s->opacity = opacity;
  s->z = tz;
  s->inv_z = rz;
  s->ext_x = std::sqrt(cutoff * sxx);
  s->ext_y = std::sqrt(cutoff * syy);
  // Row spans in terms of the covariance: -b/a = sxy/syy, cutoff/a = cutoff det/syy,
  // det(conic)/a^2 = det/syy^2.
  const float inv_syy = 1.f / syy;
  s->row_k = sxy * inv_syy;
  s->row_a0 = cutoff * det * inv_syy;
  s->row_a1 = det * inv_syy * inv_syy;
  if (!std::isfinite(s->x) || !std::isfinite(s->y) || !std::isfinite(s->a) ||
      !std::isfinite(s->b) || !std::isfinite(s->c) || !std::isfinite(s->ext_x) ||
      !std::isfinite(s->ext_y))
    return Fate::kInvalid;
  if (s->x + s->ext_x < 0.5f || s->x - s->ext_x > float(cam.width) - 0.5f ||
      s->y + s->ext_y < 0.5f || s->y - s->ext_y > float(cam.height) - 0.5f)
    return Fate::kOffscreen;

  return Fate::kVisible;
}

// Colour of a visible Gaussian; false if it is not finite.
bool colour_one(const GaussianCloud& cloud, size_t g, const CameraF& cam, int sh_degree,
                TileSplat* s) {
  const float* p = &cloud.position[3 * g];
  float dir[3] = {p[0] - cam.center[0], p[1] - cam.center[1], p[2] - cam.center[2]};
  const float dn = std::sqrt(dir[0] * dir[0] + dir[1] * dir[1] + dir[2] * dir[2]);
  const float inv = dn > 0.f ? 1.f / dn : 0.f;
  float rgb[3];
  const size_t K = size_t(cloud.sh_coeffs());
  eval_sh(&cloud.sh[g * K * 3], sh_degree, dir[0] * inv, dir[1] * inv, dir[2] * inv, rgb);
  if (!finite3(rgb)) return false;
  s->r = std::max(0.f, rgb[0] + kShOffset);
  s->g = std::max(0.f, rgb[1] + kShOffset);
  s->bl = std::max(0.f, rgb[2] + kShOffset);
  return true;
}

}  // namespace

void project_geometry_scalar(const ProjectInput& in, size_t begin, size_t end, TileSplat* out,
                             uint8_t* fate) {
  for (size_t g = begin; g < end; ++g) fate[g - begin] = geometry_one(in, g, &out[g]);
}

CameraF make_camera_f(const Camera& camera) {
  CameraF c{};
  for (int r = 0; r < 3; ++r) {
    for (int k = 0; k < 3; ++k) c.R[3 * r + k] = float(camera.R(r, k));
    c.t[r] = float(camera.t(r));
  }
  const Eigen::Vector3d centre = camera.center();
  for (int r = 0; r < 3; ++r) c.center[r] = float(centre(r));
  c.fx = float(camera.fx);
  c.fy = float(camera.fy);
  c.cx = float(camera.cx);
  c.cy = float(camera.cy);
  c.width = camera.width;
  c.height = camera.height;
  const float tan_fovx = 0.5f * float(c.width) / c.fx, tan_fovy = 0.5f * float(c.height) / c.fy;
  c.lim_x_pos = (float(c.width) - c.cx) / c.fx + kJacobianFovMargin * tan_fovx;
  c.lim_x_neg = c.cx / c.fx + kJacobianFovMargin * tan_fovx;
  c.lim_y_pos = (float(c.height) - c.cy) / c.fy + kJacobianFovMargin * tan_fovy;
  c.lim_y_neg = c.cy / c.fy + kJacobianFovMargin * tan_fovy;
  c.tiles_x = (camera.width + kTile - 1) / kTile;
  c.tiles_y = (camera.height + kTile - 1) / kTile;
  return c;
}

void project_stage(const GaussianCloud& cloud, const CameraF& cam, const ProjectParams& params,
                   const RasterKernels& kernels, const Projected& out, ThreadPool& pool,
                   ProjectCounts* counts, Progress* progress) {
  const size_t n = cloud.size();
  const ProjectInput in{
      cloud.position.data(), cloud.scale.data(), cloud.rotation.data(), cloud.opacity.data(), &cam,
      int(params.mode),      params.near_plane,  params.far_plane};
  std::atomic<uint64_t> visible{0}, depth{0}, invalid{0}, faint{0}, offscreen{0}, pairs{0};
  pool.parallel_for(
      n,
      [&](size_t begin, size_t end, int) {
        uint64_t c_vis = 0, c_depth = 0, c_inv = 0, c_faint = 0, c_off = 0, c_pairs = 0;
        uint8_t fates[kProjectBlock];
        for (size_t b = begin; b < end; b += kProjectBlock) {
          const size_t e = std::min(end, b + kProjectBlock);
          kernels.project_geometry(in, b, e, out.splats, fates);
          for (size_t g = b; g < e; ++g) {
            TileSplat& s = out.splats[g];
            uint8_t fate = fates[g - b];
            if (fate == kFateVisible && !colour_one(cloud, g, cam, params.sh_degree, &s))
              fate = kFateInvalid;
            uint32_t tiles = 0;
            if (fate == kFateVisible) {
              for_each_tile(s, cam, params.rule, [&](int, int) { ++tiles; });
              if (tiles == 0) fate = kFateOffscreen;
            }
            out.tiles[g] = tiles;
            if (tiles) std::memcpy(&out.depth_key[g], &s.z, 4);
            c_pairs += tiles;
            c_vis += fate == kFateVisible;
            c_depth += fate == kFateDepth;
            c_inv += fate == kFateInvalid;
            c_faint += fate == kFateFaint;
            c_off += fate == kFateOffscreen;
          }
        }
        visible += c_vis;
        depth += c_depth;
        invalid += c_inv;
        faint += c_faint;
        offscreen += c_off;
        pairs += c_pairs;
        if (progress) progress->advance(end - begin);
      },
      4096);
  counts->visible = visible;
  counts->culled_depth = depth;
  counts->culled_invalid = invalid;
  counts->culled_faint = faint;
  counts->culled_offscreen = offscreen;
  counts->pairs = pairs;
}

}  // namespace macro::gs::raster
