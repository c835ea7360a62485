// Projection of one Gaussian and its backward, in double (diff_project.h; maths in
// diff_render.h and docs/spec/gs-rasterizer.md §1.1, §1.2, §1.5).
//
// Legend (one Gaussian): p mean [3]; t = W p + t_cam [3]; q raw quaternion [4], qn = q/|q|;
// Rq rotation of qn [3,3]; s = exp(log s) [3]; M = Rq diag(s) [3,3]; J clamped Jacobian [2,3];
// T = J W [2,3]; A = T M [2,3]; Sigma = A A^T [2,2]; Sigma' = Sigma + eps I; conic = Sigma'^-1.
// Modes (diff_project.h): mip replaces s by s' = sqrt(s^2 + f^2) (f the 3D filter) and eps 0.3 by
// 0.1; antialiased and mip multiply the opacity by a compensation c2 of det Sigma / det Sigma',
// mip also by o3 = prod s / s'.
#include "gs/train/diff_project.h"

#include <algorithm>
#include <cmath>

#include "gs/constants.h"

namespace macro::gs::train {
namespace {

constexpr double kC0 = 0.28209479177387814;
constexpr double kC1 = 0.4886025119029199;
constexpr double kC2[5] = {1.0925484305920792, -1.0925484305920792, 0.31539156525252005,
                           -1.0925484305920792, 0.5462742152960396};
constexpr double kC3[7] = {-0.5900435899266435, 2.890611442640554,   -0.4570457994644658,
                           0.3731763325901154,  -0.4570457994644658, 1.445305721320277,
                           -0.5900435899266435};

// SH basis at the unit direction (x, y, z) up to `degree` (docs/spec/gs-rasterizer.md §1.5), and,
// if d is given, its partial derivatives d[k][0..2] w.r.t. x, y, z. Returns K.
int sh_basis(int degree, double x, double y, double z, double* b, double (*d)[3]) {
  b[0] = kC0;
  if (d) d[0][0] = d[0][1] = d[0][2] = 0;
  if (degree < 1) return 1;
  b[1] = -kC1 * y;
  b[2] = kC1 * z;
  b[3] = -kC1 * x;
  if (d) {
    d[1][0] = 0, d[1][1] = -kC1, d[1][2] = 0;
    d[2][0] = 0, d[2][1] = 0, d[2][2] = kC1;
    d[3][0] = -kC1, d[3][1] = 0, d[3][2] = 0;
  }
  if (degree < 2) return 4;
  const double xx = x * x, yy = y * y, zz = z * z;
  b[4] = kC2[0] * x * y;
  b[5] = kC2[1] * y * z;
  b[6] = kC2[2] * (2 * zz - xx - yy);
  b[7] = kC2[3] * x * z;
  b[8] = kC2[4] * (xx - yy);
  if (d) {
    d[4][0] = kC2[0] * y, d[4][1] = kC2[0] * x, d[4][2] = 0;
    d[5][0] = 0, d[5][1] = kC2[1] * z, d[5][2] = kC2[1] * y;
    d[6][0] = -2 * kC2[2] * x, d[6][1] = -2 * kC2[2] * y, d[6][2] = 4 * kC2[2] * z;
    d[7][0] = kC2[3] * z, d[7][1] = 0, d[7][2] = kC2[3] * x;
    d[8][0] = 2 * kC2[4] * x, d[8][1] = -2 * kC2[4] * y, d[8][2] = 0;
  }
  if (degree < 3) return 9;
  b[9] = kC3[0] * y * (3 * xx - yy);
  b[10] = kC3[1] * x * y * z;
  b[11] = kC3[2] * y * (4 * zz - xx - yy);
  b[12] = kC3[3] * z * (2 * zz - 3 * xx - 3 * yy);
  b[13] = kC3[4] * x * (4 * zz - xx - yy);
  b[14] = kC3[5] * z * (xx - yy);
  b[15] = kC3[6] * x * (xx - 3 * yy);
  if (d) {
    d[9][0] = kC3[0] * 6 * x * y, d[9][1] = kC3[0] * (3 * xx - 3 * yy), d[9][2] = 0;
    d[10][0] = kC3[1] * y * z, d[10][1] = kC3[1] * x * z, d[10][2] = kC3[1] * x * y;
    d[11][0] = kC3[2] * -2 * x * y, d[11][1] = kC3[2] * (4 * zz - xx - 3 * yy),
    d[11][2] = kC3[2] * 8 * y * z;
    d[12][0] = kC3[3] * -6 * x * z, d[12][1] = kC3[3] * -6 * y * z,
    d[12][2] = kC3[3] * (6 * zz - 3 * xx - 3 * yy);
    d[13][0] = kC3[4] * (4 * zz - 3 * xx - yy), d[13][1] = kC3[4] * -2 * x * y,
    d[13][2] = kC3[4] * 8 * x * z;
    d[14][0] = kC3[5] * 2 * x * z, d[14][1] = kC3[5] * -2 * y * z, d[14][2] = kC3[5] * (xx - yy);
    d[15][0] = kC3[6] * (3 * xx - 3 * yy), d[15][1] = kC3[6] * -6 * x * y, d[15][2] = 0;
  }
  return 16;
}

// The forward intermediates the backward reuses.
struct Forward {
  double p[3], t[3];
  double qn[4], q_norm;
  double Rq[9], s_raw[3], s[3], M[9];  // s_raw = exp(log s); s = s_raw, or s' in mip mode
  double f2;                           // squared 3D filter (mip), else 0
  double rx, ry;                       // t.x / t.z, t.y / t.z before the clamp
  bool clamp_x, clamp_y;               // the Jacobian clamp is active
  double txc, tyc;                     // clamped t.x, t.y (tz * clamp(rx))
  double J[4];                         // j00, j02, j11, j12
  double T[6], A[6];                   // [2,3]
  double sxx, sxy, syy;                // Sigma' (dilated)
  double det0;                         // det Sigma (undilated)
  double det, conic[3];
  double sig, o3, c2;       // sigmoid(logit), 3D-filter factor, 2D compensation
  bool c2_active;           // c2 depends on Sigma (not floored / clamped to a constant)
  double opacity;           // sig o3 c2
  double dir[3], dir_norm;  // unit direction mean - centre, |mean - centre|
  double basis[16];
  int K;
  double rgb_raw[3];
};

template <size_t N>
bool all_finite(const double (&v)[N]) {
  for (double x : v)
    if (!std::isfinite(x)) return false;
  return true;
}

// Fills f; false when the Gaussian is culled for depth or is invalid (non-finite, zero
// quaternion, det <= 0).
bool forward_one(const SplatParams& prm, size_t g, const CameraD& cam, const ProjectSettings& ps,
                 double near_plane, double far_plane, Forward* f) {
  const int sh_degree = ps.sh_degree;
  const double* R = cam.R;
  for (int a = 0; a < 3; ++a) f->p[a] = prm.means[g * 3 + a];
  for (int r = 0; r < 3; ++r)
    f->t[r] = R[3 * r] * f->p[0] + R[3 * r + 1] * f->p[1] + R[3 * r + 2] * f->p[2] + cam.t[r];
  const double tx = f->t[0], ty = f->t[1], tz = f->t[2];
  if (!std::isfinite(tx) || !std::isfinite(ty) || !(tz > near_plane && tz < far_plane))
    return false;

  const float* q = &prm.quats[g * 4];
  f->q_norm = std::sqrt(double(q[0]) * q[0] + double(q[1]) * q[1] + double(q[2]) * q[2] +
                        double(q[3]) * q[3]);
  if (!(f->q_norm > 0) || !std::isfinite(f->q_norm)) return false;
  for (int a = 0; a < 4; ++a) f->qn[a] = q[a] / f->q_norm;
  const double w = f->qn[0], x = f->qn[1], y = f->qn[2], z = f->qn[3];
  const double Rq[9] = {1 - 2 * (y * y + z * z), 2 * (x * y - w * z),     2 * (x * z + w * y),
                        2 * (x * y + w * z),     1 - 2 * (x * x + z * z), 2 * (y * z - w * x),
                        2 * (x * z - w * y),     2 * (y * z + w * x),     1 - 2 * (x * x + y * y)};
  const bool mip = ps.mode == RasterMode::kMip;
  f->f2 = 0;
  if (mip && ps.filter_3d) f->f2 = double(ps.filter_3d[g]) * double(ps.filter_3d[g]);
  f->o3 = 1;
  for (int a = 0; a < 3; ++a) {
    f->s_raw[a] = std::exp(double(prm.scales[g * 3 + a]));
    f->s[a] = f->f2 > 0 ? std::sqrt(f->s_raw[a] * f->s_raw[a] + f->f2) : f->s_raw[a];
    f->o3 *= f->f2 > 0 ? f->s_raw[a] / f->s[a] : 1.0;
  }
  for (int i = 0; i < 9; ++i) {
    f->Rq[i] = Rq[i];
    f->M[i] = Rq[i] * f->s[i % 3];
  }

  // Jacobian at the clamped position (gsplat persp_proj).
  f->rx = tx / tz;
  f->ry = ty / tz;
  f->clamp_x = f->rx < -cam.lim_x_neg || f->rx > cam.lim_x_pos;
  f->clamp_y = f->ry < -cam.lim_y_neg || f->ry > cam.lim_y_pos;
  f->txc = tz * std::min(cam.lim_x_pos, std::max(-cam.lim_x_neg, f->rx));
  f->tyc = tz * std::min(cam.lim_y_pos, std::max(-cam.lim_y_neg, f->ry));
  const double rz = 1 / tz, rz2 = rz * rz;
  f->J[0] = cam.fx * rz;
  f->J[1] = -cam.fx * f->txc * rz2;
  f->J[2] = cam.fy * rz;
  f->J[3] = -cam.fy * f->tyc * rz2;
  for (int k = 0; k < 3; ++k) {
    f->T[k] = f->J[0] * R[k] + f->J[1] * R[6 + k];
    f->T[3 + k] = f->J[2] * R[3 + k] + f->J[3] * R[6 + k];
  }
  for (int r = 0; r < 2; ++r)
    for (int k = 0; k < 3; ++k)
      f->A[3 * r + k] =
          f->T[3 * r] * f->M[k] + f->T[3 * r + 1] * f->M[3 + k] + f->T[3 * r + 2] * f->M[6 + k];
  const double* A = f->A;
  const double eps = mip ? double(raster::kMipKernelSize) : double(raster::kEps2d);
  const double sxx0 = A[0] * A[0] + A[1] * A[1] + A[2] * A[2];
  f->sxy = A[0] * A[3] + A[1] * A[4] + A[2] * A[5];
  const double syy0 = A[3] * A[3] + A[4] * A[4] + A[5] * A[5];
  f->det0 = sxx0 * syy0 - f->sxy * f->sxy;
  f->sxx = sxx0 + eps;
  f->syy = syy0 + eps;
  f->det = f->sxx * f->syy - f->sxy * f->sxy;
  if (!(f->det > 0) || !std::isfinite(f->det)) return false;
  f->conic[0] = f->syy / f->det;
  f->conic[1] = -f->sxy / f->det;
  f->conic[2] = f->sxx / f->det;
  f->sig = 1 / (1 + std::exp(-double(prm.opacities[g])));
  f->c2 = 1;
  f->c2_active = false;
  if (ps.mode == RasterMode::kAntialiased) {
    const double r = f->det0 / f->det, floor = double(raster::kAaCompFloor);
    f->c2_active = r > floor;
    f->c2 = std::sqrt(std::max(floor, r));
  } else if (mip) {
    const double e = double(raster::kMipDetEps);
    const double d0 = std::max(e, f->det0), d1 = std::max(e, f->det);
    f->c2_active = d0 > e && d1 > e;
    f->c2 = f->c2_active ? std::sqrt(d0 / (d1 + e) + e) : 0.0;
  }
  f->opacity = f->sig * f->o3 * f->c2;

  // Colour of the direction from the camera centre to the mean.
  double dir[3];
  for (int a = 0; a < 3; ++a) dir[a] = f->p[a] - cam.center[a];
  f->dir_norm = std::sqrt(dir[0] * dir[0] + dir[1] * dir[1] + dir[2] * dir[2]);
  const double inv = f->dir_norm > 0 ? 1 / f->dir_norm : 0;
  for (int a = 0; a < 3; ++a) f->dir[a] = dir[a] * inv;
  f->K = sh_basis(sh_degree, f->dir[0], f->dir[1], f->dir[2], f->basis, nullptr);
  const size_t R1 = size_t(prm.sh_rest());
  for (int c = 0; c < 3; ++c) {
    double v = f->basis[0] * prm.sh0[g * 3 + c];
    for (int k = 1; k < f->K; ++k) v += f->basis[k] * prm.shN[(g * R1 + size_t(k - 1)) * 3 + c];
    f->rgb_raw[c] = v + double(raster::kShOffset);
  }
  return all_finite(f->conic) && all_finite(f->rgb_raw) && std::isfinite(f->opacity);
}

}  // namespace

CameraD make_camera_d(const Camera& camera) {
  CameraD c{};
  for (int r = 0; r < 3; ++r) {
    for (int k = 0; k < 3; ++k) c.R[3 * r + k] = camera.R(r, k);
    c.t[r] = camera.t(r);
  }
  const Eigen::Vector3d centre = camera.center();
  for (int r = 0; r < 3; ++r) c.center[r] = centre(r);
  c.fx = camera.fx;
  c.fy = camera.fy;
  c.cx = camera.cx;
  c.cy = camera.cy;
  c.width = camera.width;
  c.height = camera.height;
  c.tiles_x = (camera.width + raster::kTile - 1) / raster::kTile;
  c.tiles_y = (camera.height + raster::kTile - 1) / raster::kTile;
  const double margin = double(raster::kJacobianFovMargin);
  const double tan_fovx = 0.5 * c.width / c.fx, tan_fovy = 0.5 * c.height / c.fy;
  c.lim_x_pos = (c.width - c.cx) / c.fx + margin * tan_fovx;
  c.lim_x_neg = c.cx / c.fx + margin * tan_fovx;
  c.lim_y_pos = (c.height - c.cy) / c.fy + margin * tan_fovy;
  c.lim_y_neg = c.cy / c.fy + margin * tan_fovy;
  return c;
}

ProjectInput project_input(const SplatParams& p, const CameraD& c, const ProjectSettings& ps) {
  ProjectInput in;
  in.means = p.means.data();
  in.quats = p.quats.data();
  in.scales = p.scales.data();
  in.opacities = p.opacities.data();
  in.sh0 = p.sh0.data();
  in.shN = p.shN.data();
  in.sh_rest = size_t(p.sh_rest());
  in.sh_degree = ps.sh_degree;
  in.mode = ps.mode;
  in.filter_3d = ps.filter_3d;
  in.near_plane = float(ps.near_plane);
  in.far_plane = float(std::min(ps.far_plane, 1e30));
  ProjectCameraF& f = in.cam;
  for (int i = 0; i < 9; ++i) f.R[i] = float(c.R[i]);
  for (int i = 0; i < 3; ++i) f.t[i] = float(c.t[i]), f.center[i] = float(c.center[i]);
  f.fx = float(c.fx), f.fy = float(c.fy), f.cx = float(c.cx), f.cy = float(c.cy);
  f.lim_x_pos = float(c.lim_x_pos), f.lim_x_neg = float(c.lim_x_neg);
  f.lim_y_pos = float(c.lim_y_pos), f.lim_y_neg = float(c.lim_y_neg);
  f.width = float(c.width), f.height = float(c.height);
  return in;
}

bool project_forward(const SplatParams& prm, size_t g, const CameraD& cam,
                     const ProjectSettings& ps, ProjectedD* out) {
  Forward f;
  if (!forward_one(prm, g, cam, ps, ps.near_plane, ps.far_plane, &f)) return false;
  if (!(f.opacity >= double(raster::kMinAlpha))) return false;
  out->x = cam.fx * f.t[0] / f.t[2] + cam.cx;
  out->y = cam.fy * f.t[1] / f.t[2] + cam.cy;
  out->a = f.conic[0];
  out->b = f.conic[1];
  out->c = f.conic[2];
  out->opacity = f.opacity;
  for (int c = 0; c < 3; ++c) out->rgb[c] = std::max(0.0, f.rgb_raw[c]);
  out->depth = f.t[2];
  // Outside d^2 = 2 ln(255 o) alpha < 1/255 (gs/constants.h, the same margins as gs/raster).
  const double cutoff =
      2 * std::log(f.opacity / double(raster::kMinAlpha)) * (1 + double(raster::kCutoffRelMargin)) +
      double(raster::kCutoffAbsMargin);
  out->sigma_skip = std::log(f.opacity / double(raster::kMinAlpha)) + 1e-9;
  out->ext_x = std::sqrt(cutoff * f.sxx);
  out->ext_y = std::sqrt(cutoff * f.syy);
  if (!std::isfinite(out->x) || !std::isfinite(out->y) || !std::isfinite(out->ext_x) ||
      !std::isfinite(out->ext_y))
    return false;
  raster::TileSplat& t = out->cover;
  t = raster::TileSplat{};
  t.x = float(out->x);
  t.y = float(out->y);
  t.a = float(out->a);
  t.b = float(out->b);
  t.c = float(out->c);
  t.ext_x = float(out->ext_x);
  t.ext_y = float(out->ext_y);
  // On the row at offset dy the ellipse spans dx in row_k dy +- sqrt(row_a0 - row_a1 dy^2)
  // (raster_kernels.h): row_k = sxy/syy, row_a0 = cutoff det/syy, row_a1 = det/syy^2.
  t.row_k = float(f.sxy / f.syy);
  t.row_a0 = float(cutoff * f.det / f.syy);
  t.row_a1 = float(f.det / (f.syy * f.syy));
  if (out->x + out->ext_x < 0.5 || out->x - out->ext_x > cam.width - 0.5 ||
      out->y + out->ext_y < 0.5 || out->y - out->ext_y > cam.height - 0.5)
    return false;
  return true;
}

void project_backward(const SplatParams& prm, size_t g, const CameraD& cam,
                      const ProjectSettings& ps, const ProjectedGrad& up, const GradRows& out) {
  const int sh_degree = ps.sh_degree;
  Forward f;
  const bool ok = forward_one(prm, g, cam, ps, -1e300, 1e300, &f);
  if (!ok) return;
  const double* R = cam.R;
  const double tx = f.t[0], ty = f.t[1], tz = f.t[2];
  const double rz = 1 / tz, rz2 = rz * rz;
  double v_t[3] = {0, 0, 0}, v_p[3] = {0, 0, 0};

  // Opacity: o = sig o3 c2, sig = sigmoid(logit).
  *out.opacity = float(up.opacity * f.o3 * f.c2 * f.sig * (1 - f.sig));
  const double v_c2 = up.opacity * f.sig * f.o3, v_o3 = up.opacity * f.sig * f.c2;

  // Colour: rgb = max(0, SH(dir) + 0.5); the clamp passes the gradient where rgb_raw >= 0.
  double v_raw[3];
  for (int c = 0; c < 3; ++c) v_raw[c] = f.rgb_raw[c] >= 0 ? up.rgb[c] : 0;
  const size_t R1 = size_t(prm.sh_rest());
  for (int c = 0; c < 3; ++c) out.sh0[c] = float(f.basis[0] * v_raw[c]);
  for (size_t j = 0; j < R1 * 3; ++j) out.shN[j] = 0.f;
  for (int k = 1; k < f.K; ++k)
    for (int c = 0; c < 3; ++c) out.shN[size_t(k - 1) * 3 + c] = float(f.basis[k] * v_raw[c]);
  if (f.K > 1 && f.dir_norm > 0) {
    double b[16], db[16][3];
    sh_basis(sh_degree, f.dir[0], f.dir[1], f.dir[2], b, db);
    double v_d[3] = {0, 0, 0};
    for (int k = 1; k < f.K; ++k) {
      double vb = 0;
      for (int c = 0; c < 3; ++c) vb += v_raw[c] * prm.shN[(g * R1 + size_t(k - 1)) * 3 + c];
      for (int a = 0; a < 3; ++a) v_d[a] += vb * db[k][a];
    }
    // dir = (p - centre) / |p - centre|: project out the radial part.
    const double dot = v_d[0] * f.dir[0] + v_d[1] * f.dir[1] + v_d[2] * f.dir[2];
    for (int a = 0; a < 3; ++a) v_p[a] += (v_d[a] - dot * f.dir[a]) / f.dir_norm;
  }

  // Pixel position of the mean: u = fx tx/tz + cx, v = fy ty/tz + cy (unclamped t).
  v_t[0] += cam.fx * rz * up.xy[0];
  v_t[1] += cam.fy * rz * up.xy[1];
  v_t[2] += -cam.fx * tx * rz2 * up.xy[0] - cam.fy * ty * rz2 * up.xy[1];

  // Conic = Sigma'^-1: dL/dSigma' = -C G C with G = [[va, vb/2], [vb/2, vc]].
  const double ca = f.conic[0], cb = f.conic[1], cc = f.conic[2];
  const double ga = up.conic[0], gb = 0.5 * up.conic[1], gc = up.conic[2];
  // C G
  const double cg00 = ca * ga + cb * gb, cg01 = ca * gb + cb * gc;
  const double cg10 = cb * ga + cc * gb, cg11 = cb * gb + cc * gc;
  // -(C G) C
  double V00 = -(cg00 * ca + cg01 * cb);
  double V01 = -(cg00 * cb + cg01 * cc);
  double V11 = -(cg10 * cb + cg11 * cc);
  // The compensation c2 = sqrt(r) (antialiased r = det0 / det; mip r = det0 / (det + 1e-6) +
  // 1e-6) through det0 = sxx0 syy0 - sxy^2 and det = sxx syy - sxy^2 (sxx = sxx0 + eps, alike):
  // d det0 = (syy0, -2 sxy, sxx0), d det = (syy, -2 sxy, sxx) w.r.t. (sxx0, sxy, syy0). The
  // symmetric V holds half of d/dsxy on each off-diagonal entry.
  if (f.c2_active && v_c2 != 0) {
    const bool mip = ps.mode == RasterMode::kMip;
    const double eps = mip ? double(raster::kMipKernelSize) : double(raster::kEps2d);
    const double a0 = f.sxx - eps, c0 = f.syy - eps;
    const double den = mip ? f.det + double(raster::kMipDetEps) : f.det;
    const double v_r = v_c2 * 0.5 / f.c2;
    const double v_det0 = v_r / den, v_det = -v_r * f.det0 / (den * den);
    V00 += v_det0 * c0 + v_det * f.syy;
    V11 += v_det0 * a0 + v_det * f.sxx;
    V01 += 0.5 * (v_det0 + v_det) * (-2 * f.sxy);
  }
  // Sigma = A A^T: dL/dA = (V + V^T) A = 2 V A.
  double vA[6];
  for (int k = 0; k < 3; ++k) {
    vA[k] = 2 * (V00 * f.A[k] + V01 * f.A[3 + k]);
    vA[3 + k] = 2 * (V01 * f.A[k] + V11 * f.A[3 + k]);
  }
  // A = T M: dL/dT = vA M^T [2,3], dL/dM = T^T vA [3,3].
  double vT[6], vM[9];
  for (int r = 0; r < 2; ++r)
    for (int j = 0; j < 3; ++j)
      vT[3 * r + j] =
          vA[3 * r] * f.M[3 * j] + vA[3 * r + 1] * f.M[3 * j + 1] + vA[3 * r + 2] * f.M[3 * j + 2];
  for (int i = 0; i < 3; ++i)
    for (int k = 0; k < 3; ++k) vM[3 * i + k] = f.T[i] * vA[k] + f.T[3 + i] * vA[3 + k];
  // M = Rq diag(s): dL/dRq = vM diag(s), dL/ds_k = sum_i Rq_ik vM_ik; log scale: times s.
  double vR[9];
  for (int i = 0; i < 9; ++i) vR[i] = vM[i] * f.s[i % 3];
  // Mip 3D filter: s' = sqrt(s^2 + f^2): ds'/dlog s = s^2 / s'; o3 = prod s / s':
  // d o3 / d log s_k = o3 f^2 / s'_k^2.
  for (int k = 0; k < 3; ++k) {
    const double vs = f.Rq[k] * vM[k] + f.Rq[3 + k] * vM[3 + k] + f.Rq[6 + k] * vM[6 + k];
    if (f.f2 > 0)
      out.scales[k] =
          float(vs * f.s_raw[k] * f.s_raw[k] / f.s[k] + v_o3 * f.o3 * f.f2 / (f.s[k] * f.s[k]));
    else
      out.scales[k] = float(vs * f.s[k]);
  }
  // T = J W (W = camera rotation): dL/dJ = vT W^T; only j00, j02, j11, j12 are variables.
  double vJ[6];
  for (int r = 0; r < 2; ++r)
    for (int j = 0; j < 3; ++j)
      vJ[3 * r + j] =
          vT[3 * r] * R[3 * j] + vT[3 * r + 1] * R[3 * j + 1] + vT[3 * r + 2] * R[3 * j + 2];
  const double vj00 = vJ[0], vj02 = vJ[2], vj11 = vJ[4], vj12 = vJ[5];
  // j00 = fx/tz, j02 = -fx txc/tz^2, j11 = fy/tz, j12 = -fy tyc/tz^2.
  v_t[2] += vj00 * (-cam.fx * rz2) + vj02 * (2 * cam.fx * f.txc * rz2 * rz) +
            vj11 * (-cam.fy * rz2) + vj12 * (2 * cam.fy * f.tyc * rz2 * rz);
  const double v_txc = vj02 * (-cam.fx * rz2), v_tyc = vj12 * (-cam.fy * rz2);
  // txc = tz clamp(tx/tz): d/dtx = 1 inside the limits; clamped, txc = tz lim (d/dtz = lim).
  if (f.clamp_x)
    v_t[2] += v_txc * (f.txc / tz);
  else
    v_t[0] += v_txc;
  if (f.clamp_y)
    v_t[2] += v_tyc * (f.tyc / tz);
  else
    v_t[1] += v_tyc;
  // t = W p + t_cam.
  for (int a = 0; a < 3; ++a) v_p[a] += R[a] * v_t[0] + R[3 + a] * v_t[1] + R[6 + a] * v_t[2];
  for (int a = 0; a < 3; ++a) out.means[a] = float(v_p[a]);

  // Rq of the unit quaternion (w, x, y, z), then the normalisation q / |q|.
  const double w = f.qn[0], x = f.qn[1], y = f.qn[2], z = f.qn[3];
  // dRq/dw, dRq/dx, dRq/dy, dRq/dz (row-major 3x3 each).
  const double dw[9] = {0, -2 * z, 2 * y, 2 * z, 0, -2 * x, -2 * y, 2 * x, 0};
  const double dx[9] = {0, 2 * y, 2 * z, 2 * y, -4 * x, -2 * w, 2 * z, 2 * w, -4 * x};
  const double dy[9] = {-4 * y, 2 * x, 2 * w, 2 * x, 0, 2 * z, -2 * w, 2 * z, -4 * y};
  const double dz[9] = {-4 * z, -2 * w, 2 * x, 2 * w, -4 * z, 2 * y, 2 * x, 2 * y, 0};
  double vq[4] = {0, 0, 0, 0};
  for (int i = 0; i < 9; ++i) {
    vq[0] += vR[i] * dw[i];
    vq[1] += vR[i] * dx[i];
    vq[2] += vR[i] * dy[i];
    vq[3] += vR[i] * dz[i];
  }
  const double qdot = vq[0] * w + vq[1] * x + vq[2] * y + vq[3] * z;
  for (int a = 0; a < 4; ++a) out.quats[a] = float((vq[a] - qdot * f.qn[a]) / f.q_norm);
}

}  // namespace macro::gs::train

namespace macro::gs::train {

std::vector<float> compute_filter_3d(const SplatParams& p, const std::vector<Camera>& cameras) {
  const size_t n = p.size();
  constexpr double kInitialDistance = 100000.0, kMinDepth = 0.2, kMargin = 0.15;
  std::vector<double> distance(n, kInitialDistance);
  std::vector<uint8_t> seen(n, 0);
  double focal = 0;
  for (const Camera& camera : cameras) {
    const CameraD cam = make_camera_d(camera);
    for (size_t g = 0; g < n; ++g) {
      double t[3];
      for (int r = 0; r < 3; ++r)
        t[r] = cam.R[3 * r] * p.means[g * 3] + cam.R[3 * r + 1] * p.means[g * 3 + 1] +
               cam.R[3 * r + 2] * p.means[g * 3 + 2] + cam.t[r];
      if (!(t[2] > kMinDepth)) continue;
      const double x = t[0] / t[2] * cam.fx + cam.cx, y = t[1] / t[2] * cam.fy + cam.cy;
      if (!(x >= -kMargin * cam.width && x <= (1 + kMargin) * cam.width &&
            y >= -kMargin * cam.height && y <= (1 + kMargin) * cam.height))
        continue;
      distance[g] = std::min(distance[g], t[2]);
      seen[g] = 1;
    }
    focal = std::max(focal, cam.fx);
  }
  double far = -1;
  for (size_t g = 0; g < n; ++g)
    if (seen[g]) far = std::max(far, distance[g]);
  std::vector<float> out(n);
  for (size_t g = 0; g < n; ++g) {
    const double d = seen[g] ? distance[g] : (far >= 0 ? far : kInitialDistance);
    out[g] = focal > 0 ? float(d / focal * std::sqrt(0.2)) : 0.f;
  }
  return out;
}

}  // namespace macro::gs::train
