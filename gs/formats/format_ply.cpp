// Inria/gsplat .ply: decode (any property order and numeric type, binary LE/BE or ascii, extra
// properties and elements ignored, SH degree 0-3 from the f_rest count, Mip-Splatting filter_3D
// folded in) and encode (binary little-endian, the Inria layout, raw values).
//
// Legend: N Gaussians, K = (degree+1)^2 coefficients per channel, R = rest values per channel in
// the file (K-1 normally; more when the file holds extra bands we do not load).
//   file f_rest_j, j = c*R + (k-1), c in {R,G,B}, k = 1..K-1   (channel-major)
//   cloud sh[n][k][c]                                          (coefficient-major, RGB fastest)
#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>

#include "attention/runtime/progress.h"
#include "gs/formats/scene_formats.h"

namespace macro::gs::formats {
namespace {

// Point-cloud .ply (x y z red green blue, no f_dc): defaults for what a trained scene would hold.
constexpr float kPointCloudOpacity = 0.99f;        // near-opaque discs
constexpr float kPointCloudScaleFraction = 0.5f;   // isotropic scale = 0.5 * estimated spacing
constexpr float kPointCloudFallbackScale = 0.01f;  // a single point or a zero-size cloud

std::string missing(const std::string& file, const std::string& property) {
  return file + ": element 'vertex': missing property '" + property + "'";
}

// The SplatRenderMode comment (gsplat PR #1036) records an antialiased ("mip") training.
bool comment_says_antialiased(const std::vector<std::string>& comments) {
  for (const std::string& c : comments) {
    auto at = c.find("SplatRenderMode:");
    if (at == std::string::npos) continue;
    std::string mode = c.substr(at + 16);
    mode.erase(0, mode.find_first_not_of(" \t"));
    mode = mode.substr(0, mode.find_first_of(" \t"));
    if (mode == "mip" || mode == "antialiased") return true;
  }
  return false;
}

// Divisor that maps a stored colour to [0, 1]: 255 for uchar, 65535 for ushort, 1 for floats.
float colour_range(ply::Type t) {
  switch (t) {
    case ply::Type::kUint8:
      return 255.f;
    case ply::Type::kInt8:
      return 127.f;
    case ply::Type::kUint16:
      return 65535.f;
    case ply::Type::kInt16:
      return 32767.f;
    case ply::Type::kUint32:
      return 4294967295.f;
    case ply::Type::kInt32:
      return 2147483647.f;
    default:
      return 1.f;
  }
}

}  // namespace

Result<GaussianCloud> decode_ply(const ply::Header& header, const uint8_t* data, size_t size,
                                 const std::string& file, const LoadLimits& limits,
                                 LoadReport& report) {
  const int vertex_index = header.find_index("vertex");
  if (vertex_index < 0) return Status::error(file + ": PLY has no 'vertex' element");
  const ply::Element& vertex = header.elements[static_cast<size_t>(vertex_index)];
  if (vertex.count > limits.max_gaussians)
    return Status::error(file + ": element 'vertex': " + std::to_string(vertex.count) +
                         " Gaussians exceed the limit of " + std::to_string(limits.max_gaussians) +
                         " (--max-gaussians)");

  auto find = [&](const std::string& name) { return ply::find_scalar(vertex, name, file); };
  auto require = [&](const std::string& name) -> Result<int> {
    MACRO_ASSIGN_OR_RETURN(int i, find(name));
    if (i < 0) return Status::error(missing(file, name));
    return i;
  };

  // Semantic slots, each a property index (or -1 when optional and absent).
  int pos[3], dc[3], scale[3] = {-1, -1, -1}, rot[4] = {-1, -1, -1, -1}, opacity = -1;
  for (int a = 0; a < 3; ++a) {
    MACRO_ASSIGN_OR_RETURN(pos[a], require(std::string(1, "xyz"[a])));
  }
  MACRO_ASSIGN_OR_RETURN(int dc0, find("f_dc_0"));
  MACRO_ASSIGN_OR_RETURN(int red, find("red"));
  const bool point_cloud = dc0 < 0 && red >= 0;
  float colour_div = 1.f;
  if (point_cloud) {
    const char* names[3] = {"red", "green", "blue"};
    for (int c = 0; c < 3; ++c) {
      MACRO_ASSIGN_OR_RETURN(dc[c], require(names[c]));
    }
    colour_div = colour_range(vertex.properties[static_cast<size_t>(red)].type);
  } else {
    for (int c = 0; c < 3; ++c) {
      MACRO_ASSIGN_OR_RETURN(dc[c], require("f_dc_" + std::to_string(c)));
    }
  }
  if (point_cloud) {
    MACRO_ASSIGN_OR_RETURN(opacity, find("opacity"));
    for (int a = 0; a < 3; ++a) {
      MACRO_ASSIGN_OR_RETURN(scale[a], find("scale_" + std::to_string(a)));
    }
    for (int a = 0; a < 4; ++a) {
      MACRO_ASSIGN_OR_RETURN(rot[a], find("rot_" + std::to_string(a)));
    }
    // Partial sets are not defaults, they are broken files.
    if (scale[0] >= 0 || scale[1] >= 0 || scale[2] >= 0)
      for (int a = 0; a < 3; ++a)
        if (scale[a] < 0) return Status::error(missing(file, "scale_" + std::to_string(a)));
    if (rot[0] >= 0 || rot[1] >= 0 || rot[2] >= 0 || rot[3] >= 0)
      for (int a = 0; a < 4; ++a)
        if (rot[a] < 0) return Status::error(missing(file, "rot_" + std::to_string(a)));
  } else {
    MACRO_ASSIGN_OR_RETURN(opacity, require("opacity"));
    for (int a = 0; a < 3; ++a) {
      MACRO_ASSIGN_OR_RETURN(scale[a], require("scale_" + std::to_string(a)));
    }
    for (int a = 0; a < 4; ++a) {
      MACRO_ASSIGN_OR_RETURN(rot[a], require("rot_" + std::to_string(a)));
    }
  }
  MACRO_ASSIGN_OR_RETURN(int filter3d, find("filter_3D"));

  // f_rest_0 .. f_rest_{3R-1}, numbered without gaps.
  size_t n_rest = 0, n_rest_named = 0;
  for (const ply::Property& p : vertex.properties)
    if (p.name.rfind("f_rest_", 0) == 0) ++n_rest_named;
  std::vector<int> rest;
  while (true) {
    MACRO_ASSIGN_OR_RETURN(int i, find("f_rest_" + std::to_string(n_rest)));
    if (i < 0) break;
    rest.push_back(i);
    ++n_rest;
  }
  if (n_rest != n_rest_named)
    return Status::error(file + ": element 'vertex': f_rest_* properties must be numbered 0.." +
                         std::to_string(n_rest_named - 1) + " without gaps; 'f_rest_" +
                         std::to_string(n_rest) + "' is missing");
  if (n_rest % 3 != 0)
    return Status::error(file +
                         ": element 'vertex': expected a multiple of 3 f_rest_* properties "
                         "(R, G, B), found " +
                         std::to_string(n_rest));
  const size_t per_channel = n_rest / 3;
  const int degree = sh_degree_for_rest(per_channel);
  const size_t K = static_cast<size_t>((degree + 1) * (degree + 1));
  if (per_channel != K - 1) {
    report.ignored_sh_coeffs = per_channel - (K - 1);
    log_info("load", file + ": " + std::to_string(per_channel) +
                         " f_rest values per channel; loading SH degree " + std::to_string(degree) +
                         " and ignoring " + std::to_string(report.ignored_sh_coeffs));
  }

  MACRO_ASSIGN_OR_RETURN(auto elements, ply::locate_elements(header, data, size, file));
  const ply::ElementRows& rows = elements[static_cast<size_t>(vertex_index)];

  // Column order in each block: x y z, dc0..2, [opacity], [scale0..2], [rot0..3], [filter], rest.
  std::vector<int> columns;
  auto add = [&](int prop) {
    if (prop < 0) return -1;
    columns.push_back(prop);
    return static_cast<int>(columns.size()) - 1;
  };
  int c_pos[3], c_dc[3], c_scale[3], c_rot[4];
  for (int a = 0; a < 3; ++a) c_pos[a] = add(pos[a]);
  for (int a = 0; a < 3; ++a) c_dc[a] = add(dc[a]);
  const int c_opacity = add(opacity);
  for (int a = 0; a < 3; ++a) c_scale[a] = add(scale[a]);
  for (int a = 0; a < 4; ++a) c_rot[a] = add(rot[a]);
  const int c_filter = add(filter3d);
  // rest columns in cloud order (k, c): file index c*R + (k-1).
  const int c_rest0 = static_cast<int>(columns.size());
  for (size_t k = 1; k < K; ++k)
    for (size_t c = 0; c < 3; ++c) columns.push_back(rest[c * per_channel + (k - 1)]);

  GaussianCloud cloud;
  const size_t N = static_cast<size_t>(vertex.count);
  cloud.resize(N, degree);
  cloud.mip_filter_3d_applied = filter3d >= 0;
  cloud.trained_antialiased = comment_says_antialiased(header.comments);
  const float nan = std::numeric_limits<float>::quiet_NaN();
  const size_t n_cols = columns.size();

  // One Gaussian from its column values v[c] (c indexes `columns`).
  auto emit = [&](size_t i, const float* v) {
    // Any non-finite raw value marks the Gaussian (dropped by the sanitize pass).
    bool bad = false;
    for (size_t c = 0; c < n_cols; ++c) bad |= !std::isfinite(v[c]);
    float* p = &cloud.position[i * 3];
    float* s = &cloud.scale[i * 3];
    float* q = &cloud.rotation[i * 4];
    float* sh = &cloud.sh[i * K * 3];
    for (int a = 0; a < 3; ++a) p[a] = v[c_pos[a]];
    float o;
    if (point_cloud) {
      for (int c = 0; c < 3; ++c) sh[c] = (v[c_dc[c]] / colour_div - 0.5f) / kShC0;
      o = c_opacity >= 0 ? sigmoid(v[c_opacity]) : kPointCloudOpacity;
      for (int a = 0; a < 3; ++a) s[a] = c_scale[0] >= 0 ? std::exp(v[c_scale[a]]) : 0.f;
      if (c_rot[0] >= 0) {
        for (int a = 0; a < 4; ++a) q[a] = v[c_rot[a]];
      } else {
        q[0] = 1.f;
      }
    } else {
      for (int c = 0; c < 3; ++c) sh[c] = v[c_dc[c]];
      o = sigmoid(v[c_opacity]);
      for (int a = 0; a < 3; ++a) s[a] = std::exp(v[c_scale[a]]);
      for (int a = 0; a < 4; ++a) q[a] = v[c_rot[a]];
    }
    if (c_filter >= 0) {
      // Mip-Splatting 3D filter: s' = sqrt(s^2 + f^2), o' = o * sqrt(prod s^2 / prod s'^2).
      const double f2 = double(v[c_filter]) * v[c_filter];
      double ratio = 1.0;
      for (int a = 0; a < 3; ++a) {
        const double s2 = double(s[a]) * s[a];
        const double t2 = s2 + f2;
        ratio *= t2 > 0 ? s2 / t2 : 1.0;
        s[a] = static_cast<float>(std::sqrt(t2));
      }
      o = static_cast<float>(o * std::sqrt(ratio));
    }
    std::copy(v + c_rest0, v + c_rest0 + (K - 1) * 3, sh + 3);
    cloud.opacity[i] = bad ? nan : o;
  };

  bool all_float = !rows.variable_rows && !rows.swap_bytes;
  for (int prop : columns)
    all_float &= rows.stored_type[static_cast<size_t>(prop)] == ply::Type::kFloat32;
  std::vector<float> v(n_cols);
  if (all_float) {
    // The common layout (every used property a little-endian float): straight from each row.
    std::vector<size_t> offset(n_cols);
    for (size_t c = 0; c < n_cols; ++c)
      offset[c] = rows.stored_offset[static_cast<size_t>(columns[c])];
    const uint8_t* row = rows.begin;
    for (size_t i = 0; i < N; ++i, row += rows.stride) {
      for (size_t c = 0; c < n_cols; ++c) std::memcpy(&v[c], row + offset[c], 4);
      emit(i, v.data());
    }
  } else {
    // Any other types or byte order: typed column gathers per block of rows.
    MACRO_TRY(rows.for_each_block(columns, [&](size_t first, size_t n, const float* const* col) {
      for (size_t r = 0; r < n; ++r) {
        for (size_t c = 0; c < n_cols; ++c) v[c] = col[c][r];
        emit(first + r, v.data());
      }
    }));
  }

  if (point_cloud && c_scale[0] < 0 && N > 0) {
    // Isotropic default: half the spacing of N points spread over the bounding box's surface.
    float lo[3], hi[3];
    for (int a = 0; a < 3; ++a) lo[a] = hi[a] = cloud.position[static_cast<size_t>(a)];
    for (size_t i = 0; i < N; ++i)
      for (int a = 0; a < 3; ++a) {
        const float v = cloud.position[i * 3 + static_cast<size_t>(a)];
        if (std::isfinite(v)) lo[a] = std::min(lo[a], v), hi[a] = std::max(hi[a], v);
      }
    double diag2 = 0;
    for (int a = 0; a < 3; ++a) diag2 += double(hi[a] - lo[a]) * (hi[a] - lo[a]);
    float s = static_cast<float>(kPointCloudScaleFraction * std::sqrt(diag2) /
                                 std::sqrt(static_cast<double>(N)));
    if (!(s > 0) || !std::isfinite(s)) s = kPointCloudFallbackScale;
    std::fill(cloud.scale.begin(), cloud.scale.end(), s);
  }
  if (point_cloud)
    log_info("load", file +
                         ": a point cloud (red/green/blue, no f_dc): using default opacity, "
                         "scale and rotation where absent (docs/formats.md)");
  return cloud;
}

std::string inria_ply_header(size_t N, size_t R, const std::string& comment, bool filter_3d) {
  std::string h = "ply\nformat binary_little_endian 1.0\n";
  if (!comment.empty()) h += "comment " + comment + "\n";
  h += "element vertex " + std::to_string(N) + "\n";
  for (const char* name : {"x", "y", "z", "nx", "ny", "nz", "f_dc_0", "f_dc_1", "f_dc_2"})
    h += std::string("property float ") + name + "\n";
  for (size_t j = 0; j < 3 * R; ++j) h += "property float f_rest_" + std::to_string(j) + "\n";
  for (const char* name :
       {"opacity", "scale_0", "scale_1", "scale_2", "rot_0", "rot_1", "rot_2", "rot_3"})
    h += std::string("property float ") + name + "\n";
  if (filter_3d) h += "property float filter_3D\n";
  h += "end_header\n";
  return h;
}

Result<std::vector<uint8_t>> encode_ply(const GaussianCloud& cloud, const std::string& file) {
  const size_t N = cloud.size();
  const size_t K = static_cast<size_t>(cloud.sh_coeffs());
  const size_t R = K - 1;
  const std::string h =
      inria_ply_header(N, R, cloud.trained_antialiased ? "SplatRenderMode: mip" : "");
  const size_t floats = 9 + 3 * R + 8;
  std::vector<uint8_t> out(h.size() + N * floats * 4);
  std::memcpy(out.data(), h.data(), h.size());
  std::vector<float> row(floats);
  uint8_t* dst = out.data() + h.size();
  for (size_t i = 0; i < N; ++i) {
    float* v = row.data();
    const float* sh = &cloud.sh[i * K * 3];
    for (int a = 0; a < 3; ++a) *v++ = cloud.position[i * 3 + static_cast<size_t>(a)];
    for (int a = 0; a < 3; ++a) *v++ = 0.f;
    for (int c = 0; c < 3; ++c) *v++ = sh[c];
    for (size_t c = 0; c < 3; ++c)
      for (size_t k = 1; k < K; ++k) *v++ = sh[k * 3 + c];
    // logit in double so that sigmoid(logit(o)) returns o; o = 0 or 1 stay finite.
    const double o = std::clamp(static_cast<double>(cloud.opacity[i]), 1e-12, 1.0 - 1e-12);
    *v++ = static_cast<float>(std::log(o / (1.0 - o)));
    for (int a = 0; a < 3; ++a) {
      const float sc = std::max(cloud.scale[i * 3 + static_cast<size_t>(a)], kMinScale);
      *v++ = static_cast<float>(std::log(static_cast<double>(sc)));
    }
    for (int a = 0; a < 4; ++a) *v++ = cloud.rotation[i * 4 + static_cast<size_t>(a)];
    std::memcpy(dst, row.data(), floats * 4);  // little-endian host
    dst += floats * 4;
  }
  (void)file;
  return out;
}

}  // namespace macro::gs::formats
