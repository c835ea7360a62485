// Pre-activation splat parameters <-> Inria .ply, and their activation (splat_params.h).
#include "gs/formats/splat_params.h"

#include <algorithm>
#include <cmath>
#include <cstring>

#include "attention/runtime/file_io.h"
#include "gs/formats/ply_reader.h"
#include "gs/formats/scene_formats.h"

namespace macro::gs {

void SplatParams::resize(size_t n, int degree) {
  sh_degree = degree;
  means.assign(n * 3, 0.f);
  scales.assign(n * 3, 0.f);
  quats.assign(n * 4, 0.f);
  opacities.assign(n, 0.f);
  sh0.assign(n * 3, 0.f);
  shN.assign(n * size_t(sh_rest()) * 3, 0.f);
}

Status SplatParams::check_shapes() const {
  if (sh_degree < 0 || sh_degree > 3)
    return Status::error("splat parameters: sh_degree " + std::to_string(sh_degree) +
                         ", expected 0..3");
  const size_t n = size();
  auto check = [&](const char* field, size_t got, size_t per) -> Status {
    if (got != n * per)
      return Status::error(std::string("splat parameters: '") + field + "' holds " +
                           std::to_string(got) + " floats, expected " + std::to_string(n * per) +
                           " for " + std::to_string(n) + " Gaussians");
    return Status::ok();
  };
  MACRO_TRY(check("means", means.size(), 3));
  MACRO_TRY(check("scales", scales.size(), 3));
  MACRO_TRY(check("quats", quats.size(), 4));
  MACRO_TRY(check("sh0", sh0.size(), 3));
  MACRO_TRY(check("shN", shN.size(), size_t(sh_rest()) * 3));
  return Status::ok();
}

Result<SplatParams> decode_splat_params(const uint8_t* data, size_t size, const std::string& name,
                                        const LoadLimits& limits, std::vector<float>* filter_3d) {
  if (size == 0) return Status::error(name + ": empty file");
  if (!ply::looks_like_ply(data, size))
    return Status::error(name + ": expected an Inria-layout .ply (a PLY header), found none");
  MACRO_ASSIGN_OR_RETURN(ply::Header header, ply::parse_header(data, size, name));
  if (formats::is_compressed_ply(header))
    return Status::error(name +
                         ": a SuperSplat compressed .ply holds quantised values, not trainable "
                         "parameters; expected the Inria layout");
  const int vertex_index = header.find_index("vertex");
  if (vertex_index < 0) return Status::error(name + ": PLY has no 'vertex' element");
  const ply::Element& vertex = header.elements[size_t(vertex_index)];
  if (vertex.count > limits.max_gaussians)
    return Status::error(name + ": element 'vertex': " + std::to_string(vertex.count) +
                         " Gaussians exceed the limit of " + std::to_string(limits.max_gaussians) +
                         " (--max-gaussians)");
  auto require = [&](const std::string& prop) -> Result<int> {
    MACRO_ASSIGN_OR_RETURN(int i, ply::find_scalar(vertex, prop, name));
    if (i < 0)
      return Status::error(name + ": element 'vertex': missing property '" + prop +
                           "' (expected the Inria layout: x y z f_dc_0..2 f_rest_* opacity "
                           "scale_0..2 rot_0..3)");
    return i;
  };
  MACRO_ASSIGN_OR_RETURN(int filter3d, ply::find_scalar(vertex, "filter_3D", name));
  if (filter3d >= 0 && filter_3d == nullptr)
    return Status::error(name +
                         ": element 'vertex' has 'filter_3D' (a Mip-Splatting file, e.g. from "
                         "macro train --mode mip): its scales and opacities need that 3D filter; "
                         "use it in mip mode (--mode mip)");
  if (filter_3d) filter_3d->clear();

  // Columns in this order: x y z, f_dc_0..2, opacity, scale_0..2, rot_0..3, then shN in
  // coefficient-major order (file index c*R + k-1).
  std::vector<int> columns;
  for (const char* prop : {"x", "y", "z", "f_dc_0", "f_dc_1", "f_dc_2", "opacity", "scale_0",
                           "scale_1", "scale_2", "rot_0", "rot_1", "rot_2", "rot_3"}) {
    MACRO_ASSIGN_OR_RETURN(int i, require(prop));
    columns.push_back(i);
  }
  size_t n_rest_named = 0;
  for (const ply::Property& p : vertex.properties)
    if (p.name.rfind("f_rest_", 0) == 0) ++n_rest_named;
  std::vector<int> rest;
  for (size_t j = 0; j < n_rest_named; ++j) {
    MACRO_ASSIGN_OR_RETURN(int i, ply::find_scalar(vertex, "f_rest_" + std::to_string(j), name));
    if (i < 0)
      return Status::error(name + ": element 'vertex': f_rest_* properties must be numbered 0.." +
                           std::to_string(n_rest_named - 1) + " without gaps; 'f_rest_" +
                           std::to_string(j) + "' is missing");
    rest.push_back(i);
  }
  int degree = -1;
  for (int d = 0; d <= 3; ++d)
    if (n_rest_named == size_t(3 * ((d + 1) * (d + 1) - 1))) degree = d;
  if (degree < 0)
    return Status::error(name + ": element 'vertex': " + std::to_string(n_rest_named) +
                         " f_rest_* properties, expected 0, 9, 24 or 45 (SH degree 0..3)");
  const size_t R = size_t((degree + 1) * (degree + 1) - 1);
  for (size_t k = 0; k < R; ++k)
    for (size_t c = 0; c < 3; ++c) columns.push_back(rest[c * R + k]);
  const size_t filter_column = columns.size();
  if (filter3d >= 0) columns.push_back(filter3d);
  static const char* const kFixedNames[14] = {"x",      "y",       "z",       "f_dc_0",  "f_dc_1",
                                              "f_dc_2", "opacity", "scale_0", "scale_1", "scale_2",
                                              "rot_0",  "rot_1",   "rot_2",   "rot_3"};

  MACRO_ASSIGN_OR_RETURN(auto elements, ply::locate_elements(header, data, size, name));
  const ply::ElementRows& rows = elements[size_t(vertex_index)];
  SplatParams p;
  const size_t N = size_t(vertex.count);
  p.resize(N, degree);
  if (filter3d >= 0) filter_3d->assign(N, 0.f);
  std::string error;
  MACRO_TRY(rows.for_each_block(columns, [&](size_t first, size_t n, const float* const* col) {
    for (size_t r = 0; r < n && error.empty(); ++r) {
      const size_t i = first + r;
      for (size_t c = 0; c < columns.size(); ++c) {
        if (std::isfinite(col[c][r])) continue;
        const std::string prop =
            c < 14               ? kFixedNames[c]
            : c == filter_column ? "filter_3D"
                                 : "f_rest_" + std::to_string(((c - 14) % 3) * R + (c - 14) / 3);
        error = name + ": vertex " + std::to_string(i) + ": property '" + prop +
                "' is not finite (" + std::to_string(col[c][r]) + ")";
        return;
      }
      for (int a = 0; a < 3; ++a) p.means[i * 3 + a] = col[a][r];
      for (int a = 0; a < 3; ++a) p.sh0[i * 3 + a] = col[3 + a][r];
      p.opacities[i] = col[6][r];
      for (int a = 0; a < 3; ++a) p.scales[i * 3 + a] = col[7 + a][r];
      double q2 = 0;
      for (int a = 0; a < 4; ++a) {
        p.quats[i * 4 + a] = col[10 + a][r];
        q2 += double(col[10 + a][r]) * col[10 + a][r];
      }
      if (!(q2 > 0)) {
        error = name + ": vertex " + std::to_string(i) +
                ": rot_0..rot_3 is the zero quaternion, which has no rotation";
        return;
      }
      for (size_t j = 0; j < R * 3; ++j) p.shN[i * R * 3 + j] = col[14 + j][r];
      if (filter3d >= 0) {
        if (col[filter_column][r] < 0) {
          error = name + ": vertex " + std::to_string(i) + ": property 'filter_3D' is negative (" +
                  std::to_string(col[filter_column][r]) + ")";
          return;
        }
        (*filter_3d)[i] = col[filter_column][r];
      }
    }
  }));
  if (!error.empty()) return Status::error(error);
  return p;
}

Result<SplatParams> read_splat_params(const std::string& path, const LoadLimits& limits,
                                      std::vector<float>* filter_3d) {
  MACRO_ASSIGN_OR_RETURN(std::vector<uint8_t> bytes, read_file(path, limits.max_file_bytes));
  return decode_splat_params(bytes.data(), bytes.size(), path, limits, filter_3d);
}

std::vector<uint8_t> encode_splat_params(const SplatParams& p,
                                         const std::vector<float>* filter_3d) {
  const size_t N = p.size();
  const size_t R = size_t(p.sh_rest());
  const bool with_filter = filter_3d != nullptr;
  MACRO_CHECK(!with_filter || filter_3d->size() == N);
  const std::string h = formats::inria_ply_header(N, R, "", with_filter);
  const size_t floats = 9 + 3 * R + 8 + (with_filter ? 1 : 0);
  std::vector<uint8_t> out(h.size() + N * floats * 4);
  std::memcpy(out.data(), h.data(), h.size());
  std::vector<float> row(floats);
  uint8_t* dst = out.data() + h.size();
  for (size_t i = 0; i < N; ++i) {
    float* v = row.data();
    for (int a = 0; a < 3; ++a) *v++ = p.means[i * 3 + a];
    for (int a = 0; a < 3; ++a) *v++ = 0.f;
    for (int a = 0; a < 3; ++a) *v++ = p.sh0[i * 3 + a];
    for (size_t c = 0; c < 3; ++c)
      for (size_t k = 0; k < R; ++k) *v++ = p.shN[(i * R + k) * 3 + c];
    *v++ = p.opacities[i];
    for (int a = 0; a < 3; ++a) *v++ = p.scales[i * 3 + a];
    for (int a = 0; a < 4; ++a) *v++ = p.quats[i * 4 + a];
    if (with_filter) *v++ = (*filter_3d)[i];
    std::memcpy(dst, row.data(), floats * 4);  // little-endian host
    dst += floats * 4;
  }
  return out;
}

Status write_splat_params(const SplatParams& params, const std::string& path,
                          const std::vector<float>* filter_3d) {
  MACRO_TRY(params.check_shapes().with_context(path));
  if (filter_3d && filter_3d->size() != params.size())
    return Status::error(path + ": the 3D filter holds " + std::to_string(filter_3d->size()) +
                         " values for " + std::to_string(params.size()) + " Gaussians");
  const std::vector<uint8_t> bytes = encode_splat_params(params, filter_3d);
  return write_file_atomic(path, bytes.data(), bytes.size());
}

GaussianCloud to_cloud(const SplatParams& p) {
  GaussianCloud c;
  const size_t N = p.size();
  c.resize(N, p.sh_degree);
  const size_t K = size_t(p.sh_coeffs());
  for (size_t i = 0; i < N; ++i) {
    for (int a = 0; a < 3; ++a) {
      c.position[i * 3 + a] = p.means[i * 3 + a];
      c.scale[i * 3 + a] = float(std::exp(double(p.scales[i * 3 + a])));
      c.sh[i * K * 3 + a] = p.sh0[i * 3 + a];
    }
    const float* q = &p.quats[i * 4];
    const double qn = std::sqrt(double(q[0]) * q[0] + double(q[1]) * q[1] + double(q[2]) * q[2] +
                                double(q[3]) * q[3]);
    for (int a = 0; a < 4; ++a) c.rotation[i * 4 + a] = qn > 0 ? float(q[a] / qn) : 0.f;
    c.opacity[i] = float(1.0 / (1.0 + std::exp(-double(p.opacities[i]))));
    if (K > 1)  // (degree 0: shN is empty, no element to point at)
      std::copy_n(p.shN.data() + i * (K - 1) * 3, (K - 1) * 3, c.sh.data() + i * K * 3 + 3);
  }
  return c;
}

Result<SplatParams> from_cloud(const GaussianCloud& c, const std::string& name) {
  if (c.mip_filter_3d_applied)
    return Status::error(name +
                         ": its Mip-Splatting 3D filter is folded in; train from the .ply with "
                         "its filter_3D property in mip mode instead");
  if (c.sh_degree < 0 || c.sh_degree > 3)
    return Status::error(name + ": SH degree " + std::to_string(c.sh_degree) + ", expected 0..3");
  const size_t N = c.size();
  const size_t K = size_t(c.sh_coeffs());
  if (c.position.size() != 3 * N || c.scale.size() != 3 * N || c.rotation.size() != 4 * N ||
      c.sh.size() != K * 3 * N)
    return Status::error(name + ": inconsistent Gaussian arrays");
  SplatParams p;
  p.resize(N, c.sh_degree);
  for (size_t i = 0; i < N; ++i) {
    for (int a = 0; a < 3; ++a) {
      p.means[i * 3 + a] = c.position[i * 3 + a];
      p.scales[i * 3 + a] = float(std::log(std::max(double(c.scale[i * 3 + a]), 1e-12)));
      p.sh0[i * 3 + a] = c.sh[i * K * 3 + a];
    }
    for (int a = 0; a < 4; ++a) p.quats[i * 4 + a] = c.rotation[i * 4 + a];
    if (p.quats[i * 4] == 0 && p.quats[i * 4 + 1] == 0 && p.quats[i * 4 + 2] == 0 &&
        p.quats[i * 4 + 3] == 0)
      p.quats[i * 4] = 1;
    const double o = std::clamp(double(c.opacity[i]), 1e-6, 1 - 1e-6);
    p.opacities[i] = float(std::log(o / (1 - o)));
    if (K > 1)
      std::copy_n(c.sh.data() + i * K * 3 + 3, (K - 1) * 3, p.shN.data() + i * (K - 1) * 3);
  }
  return p;
}

}  // namespace macro::gs
