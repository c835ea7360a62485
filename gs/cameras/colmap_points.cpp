// COLMAP points3D.txt / points3D.bin reader and text writer (see colmap_points.h).
#include "gs/cameras/colmap_points.h"

#include <algorithm>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <string_view>

#include "attention/runtime/file_io.h"

namespace macro::gs {
namespace {

bool is_space(char c) {
  return c == ' ' || c == '\t' || c == '\r' || c == '\v' || c == '\f';
}

// Next whitespace-separated token of `s` from `*pos`; empty at the end of the line.
std::string_view next_token(std::string_view s, size_t* pos) {
  size_t i = *pos;
  while (i < s.size() && is_space(s[i])) ++i;
  size_t j = i;
  while (j < s.size() && !is_space(s[j])) ++j;
  *pos = j;
  return s.substr(i, j - i);
}

bool parse_double(std::string_view s, double* v) {
  if (!s.empty() && s[0] == '+') s.remove_prefix(1);
  auto r = std::from_chars(s.data(), s.data() + s.size(), *v);
  return !s.empty() && r.ec == std::errc() && r.ptr == s.data() + s.size();
}

template <typename T>
bool parse_int(std::string_view s, T* v) {
  auto r = std::from_chars(s.data(), s.data() + s.size(), *v);
  return !s.empty() && r.ec == std::errc() && r.ptr == s.data() + s.size();
}

std::string clip(std::string_view s) {
  return std::string(s.substr(0, 40)) + (s.size() > 40 ? "..." : "");
}

// Unique ids and finite positions, shared by both readers and the writer.
Status check_points(const ColmapPoints& p, const std::string& path) {
  // As for an empty images file: a model without points cannot be used, so say so here.
  if (p.size() == 0) return Status::error(path + ": no 3D points (expected at least one)");
  for (size_t i = 0; i < p.size(); ++i) {
    if (!std::isfinite(p.xyz[i].x()) || !std::isfinite(p.xyz[i].y()) ||
        !std::isfinite(p.xyz[i].z()))
      return Status::error(path + ": point " + std::to_string(p.ids[i]) +
                           ": X Y Z: expected finite numbers, found a NaN or infinity");
  }
  std::vector<int64_t> sorted = p.ids;
  std::sort(sorted.begin(), sorted.end());
  const auto dup = std::adjacent_find(sorted.begin(), sorted.end());
  if (dup != sorted.end())
    return Status::error(path + ": POINT3D_ID " + std::to_string(*dup) + " appears twice");
  return Status::ok();
}

}  // namespace

Result<ColmapPoints> load_colmap_points_text(const std::string& path) {
  MACRO_ASSIGN_OR_RETURN(std::string text, read_text_file(path));
  ColmapPoints pts;
  pts.source = path;
  pts.track_offsets.push_back(0);
  static const char* const kXyz[] = {"X", "Y", "Z"};
  static const char* const kRgb[] = {"R", "G", "B"};
  size_t start = 0, line_no = 0;
  while (start < text.size()) {
    size_t end = text.find('\n', start);
    if (end == std::string::npos) end = text.size();
    const std::string_view line(text.data() + start, end - start);
    start = end + 1;
    ++line_no;
    size_t pos = 0;
    const std::string_view first = next_token(line, &pos);
    if (first.empty() || first[0] == '#') continue;
    const auto where = [&]() { return path + " line " + std::to_string(line_no); };
    const auto bad = [&](const std::string& field, std::string_view tok, const char* expected) {
      return Status::error(where() + ": " + field + ": expected " + expected + ", found '" +
                           (tok.empty() ? std::string("end of line") : clip(tok)) + "'");
    };
    int64_t id = 0;
    if (!parse_int(first, &id)) return bad("POINT3D_ID", first, "an integer");
    Eigen::Vector3d x;
    for (int k = 0; k < 3; ++k) {
      const std::string_view t = next_token(line, &pos);
      if (!parse_double(t, &x[k])) return bad(kXyz[k], t, "a number");
    }
    uint8_t rgb[3];
    for (int k = 0; k < 3; ++k) {
      const std::string_view t = next_token(line, &pos);
      int v = 0;
      if (!parse_int(t, &v) || v < 0 || v > 255) return bad(kRgb[k], t, "an integer 0..255");
      rgb[k] = uint8_t(v);
    }
    double err = 0;
    {
      const std::string_view t = next_token(line, &pos);
      if (!parse_double(t, &err)) return bad("ERROR", t, "a number");
    }
    for (size_t k = 0;; ++k) {
      const std::string_view t_img = next_token(line, &pos);
      if (t_img.empty()) break;
      const std::string_view t_idx = next_token(line, &pos);
      uint32_t image_id = 0, idx = 0;
      const std::string f = "TRACK[" + std::to_string(k) + "]";
      if (!parse_int(t_img, &image_id)) return bad(f + " IMAGE_ID", t_img, "an unsigned integer");
      if (!parse_int(t_idx, &idx)) return bad(f + " POINT2D_IDX", t_idx, "an unsigned integer");
      pts.track_image_ids.push_back(image_id);
      pts.track_point2d.push_back(idx);
    }
    pts.ids.push_back(id);
    pts.xyz.push_back(x);
    pts.rgb.insert(pts.rgb.end(), rgb, rgb + 3);
    pts.error.push_back(err);
    pts.track_offsets.push_back(pts.track_image_ids.size());
  }
  MACRO_TRY(check_points(pts, path));
  return pts;
}

Result<ColmapPoints> load_colmap_points_binary(const std::string& path) {
  MACRO_ASSIGN_OR_RETURN(std::vector<uint8_t> bytes, read_file(path));
  uint64_t pos = 0;
  const auto left = [&]() { return uint64_t(bytes.size()) - pos; };
  const auto truncated = [&](const std::string& what, uint64_t need) {
    return Status::error(path + ": " + what + ": file truncated at byte " + std::to_string(pos) +
                         ": needs " + std::to_string(need) + " bytes, " + std::to_string(left()) +
                         " left");
  };
  const auto read = [&](void* dst, uint64_t n) {
    std::memcpy(dst, bytes.data() + pos, n);  // x86-64 is little-endian, like the files
    pos += n;
  };
  if (left() < 8) return truncated("point count", 8);
  uint64_t count = 0;
  read(&count, 8);
  constexpr uint64_t kMinPoint = 8 + 24 + 3 + 8 + 8;  // 51 bytes without the track
  if (count > left() / kMinPoint)
    return Status::error(path + ": point count " + std::to_string(count) + " needs at least " +
                         std::to_string(kMinPoint) + " bytes each, only " + std::to_string(left()) +
                         " bytes left (truncated or not a COLMAP file)");
  ColmapPoints pts;
  pts.source = path;
  pts.ids.reserve(count);
  pts.xyz.reserve(count);
  pts.rgb.reserve(count * 3);
  pts.error.reserve(count);
  pts.track_offsets.reserve(count + 1);
  pts.track_offsets.push_back(0);
  for (uint64_t i = 0; i < count; ++i) {
    const std::string what = "point #" + std::to_string(i);
    if (left() < kMinPoint) return truncated(what, kMinPoint);
    uint64_t id = 0, track_len = 0;
    double xyz[3], err = 0;
    uint8_t rgb[3];
    read(&id, 8);
    read(xyz, 24);
    read(rgb, 3);
    read(&err, 8);
    read(&track_len, 8);
    if (id > uint64_t(INT64_MAX))
      return Status::error(path + ": " + what + ": point3D_id " + std::to_string(id) +
                           " is out of range");
    if (track_len > left() / 8)
      return Status::error(path + ": " + what + " (id " + std::to_string(id) + "): track length " +
                           std::to_string(track_len) + " needs " + std::to_string(track_len * 8) +
                           " bytes, only " + std::to_string(left()) + " left");
    for (uint64_t k = 0; k < track_len; ++k) {
      uint32_t image_id = 0, idx = 0;
      read(&image_id, 4);
      read(&idx, 4);
      pts.track_image_ids.push_back(image_id);
      pts.track_point2d.push_back(idx);
    }
    pts.ids.push_back(int64_t(id));
    pts.xyz.emplace_back(xyz[0], xyz[1], xyz[2]);
    pts.rgb.insert(pts.rgb.end(), rgb, rgb + 3);
    pts.error.push_back(err);
    pts.track_offsets.push_back(pts.track_image_ids.size());
  }
  if (left() != 0)
    return Status::error(path + ": " + std::to_string(left()) + " unexpected bytes after " +
                         std::to_string(count) + " points");
  MACRO_TRY(check_points(pts, path));
  return pts;
}

Result<ColmapPoints> load_colmap_points(const std::string& folder) {
  const std::string dir = folder.empty() || folder.back() == '/' ? folder : folder + "/";
  if (file_exists(dir + "points3D.bin")) return load_colmap_points_binary(dir + "points3D.bin");
  if (file_exists(dir + "points3D.txt")) return load_colmap_points_text(dir + "points3D.txt");
  return Status::error(folder +
                       ": no points3D.bin or points3D.txt (the sparse 3D points of the "
                       "COLMAP model are needed)");
}

Result<std::string> find_colmap_model_folder(const std::string& dir) {
  std::string d = dir;
  while (d.size() > 1 && d.back() == '/') d.pop_back();
  if (!is_directory(d)) return Status::error(dir + ": scene folder not found");
  for (const char* sub : {"", "/sparse/0", "/sparse", "/colmap/sparse/0"}) {
    const std::string f = d + sub;
    for (const char* name : {"/cameras.bin", "/cameras.txt", "/images.bin", "/images.txt"})
      if (file_exists(f + name)) return f;
  }
  return Status::error(dir +
                       ": no COLMAP model (looked for cameras.{bin,txt} / images.{bin,txt} in ., "
                       "sparse/0, sparse, colmap/sparse/0)");
}

Status save_colmap_points_text(const ColmapPoints& p, const std::string& path) {
  const size_t m = p.size();
  if (p.ids.size() != m || p.rgb.size() != 3 * m || p.error.size() != m ||
      p.track_offsets.size() != m + 1 || p.track_offsets.back() != p.track_image_ids.size() ||
      p.track_point2d.size() != p.track_image_ids.size())
    return Status::error(path + ": inconsistent point arrays (ids, rgb, error, tracks) for " +
                         std::to_string(m) + " points");
  MACRO_TRY(check_points(p, path));
  AtomicFile f;
  MACRO_TRY(f.open(path));
  std::string out =
      "# 3D point list with one line of data per point:\n"
      "#   POINT3D_ID, X, Y, Z, R, G, B, ERROR, TRACK[] as (IMAGE_ID, POINT2D_IDX)\n"
      "# Number of points: " +
      std::to_string(m) + "\n";
  char buf[64];
  for (size_t i = 0; i < m; ++i) {
    out += std::to_string(p.ids[i]);
    for (int k = 0; k < 3; ++k) {
      std::snprintf(buf, sizeof buf, " %.17g", p.xyz[i][k]);
      out += buf;
    }
    std::snprintf(buf, sizeof buf, " %d %d %d %.17g", p.rgb[3 * i], p.rgb[3 * i + 1],
                  p.rgb[3 * i + 2], p.error[i]);
    out += buf;
    for (uint64_t t = p.track_offsets[i]; t < p.track_offsets[i + 1]; ++t) {
      std::snprintf(buf, sizeof buf, " %u %u", p.track_image_ids[t], p.track_point2d[t]);
      out += buf;
    }
    out += '\n';
    if (out.size() > (1u << 20)) {
      MACRO_TRY(f.write(out));
      out.clear();
    }
  }
  MACRO_TRY(f.write(out));
  return f.commit();
}

}  // namespace macro::gs
