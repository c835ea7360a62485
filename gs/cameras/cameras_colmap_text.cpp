// COLMAP sparse text model: cameras.txt and images.txt.
//   cameras.txt: "CAMERA_ID MODEL WIDTH HEIGHT PARAMS..." per line, '#' comments.
//   images.txt:  per image two lines, "IMAGE_ID QW QX QY QZ TX TY TZ CAMERA_ID NAME" and then its
//                2D points "X Y POINT3D_ID ..." (possibly empty). Like COLMAP's own reader, blank
//                and '#' lines are skipped only where an image line is expected; the line after an
//                image line is always its points line. A points line that is not X Y ID triples is
//                reported (it usually means a file written without points lines).
#include <charconv>
#include <cstdint>
#include <string_view>

#include "attention/runtime/file_io.h"
#include "gs/cameras/camera.h"
#include "gs/cameras/cameras_colmap.h"

namespace macro::gs {
namespace {

using detail::ColmapCameraRecord;
using detail::ColmapImageRecord;

std::vector<std::string_view> split_lines(std::string_view text) {
  std::vector<std::string_view> lines;
  size_t start = 0;
  while (start < text.size()) {
    size_t end = text.find('\n', start);
    if (end == std::string_view::npos) end = text.size();
    std::string_view line = text.substr(start, end - start);
    if (!line.empty() && line.back() == '\r') line.remove_suffix(1);
    lines.push_back(line);
    start = end + 1;
  }
  return lines;
}

bool is_space(char c) {
  return c == ' ' || c == '\t' || c == '\r' || c == '\v' || c == '\f';
}

std::string_view trim(std::string_view s) {
  while (!s.empty() && is_space(s.front())) s.remove_prefix(1);
  while (!s.empty() && is_space(s.back())) s.remove_suffix(1);
  return s;
}

// Whitespace tokens; `rest` (if given) receives the untrimmed remainder after `max_tokens` tokens.
std::vector<std::string_view> tokens(std::string_view s, size_t max_tokens = SIZE_MAX,
                                     std::string_view* rest = nullptr) {
  std::vector<std::string_view> out;
  size_t i = 0;
  while (i < s.size() && out.size() < max_tokens) {
    while (i < s.size() && is_space(s[i])) ++i;
    if (i == s.size()) break;
    size_t j = i;
    while (j < s.size() && !is_space(s[j])) ++j;
    out.push_back(s.substr(i, j - i));
    i = j;
  }
  if (rest) *rest = trim(s.substr(std::min(i, s.size())));
  return out;
}

bool parse_double(std::string_view s, double* v) {
  if (!s.empty() && s[0] == '+') s.remove_prefix(1);
  auto r = std::from_chars(s.data(), s.data() + s.size(), *v);
  return r.ec == std::errc() && r.ptr == s.data() + s.size();
}

bool parse_int(std::string_view s, int64_t* v) {
  auto r = std::from_chars(s.data(), s.data() + s.size(), *v);
  return r.ec == std::errc() && r.ptr == s.data() + s.size();
}

std::string at_line(const std::string& path, size_t line) {
  return path + " line " + std::to_string(line + 1);
}

Status bad_token(const std::string& where, const char* field, std::string_view tok,
                 const char* expected) {
  return Status::error(where + ": " + field + ": expected " + expected + ", found '" +
                       std::string(tok) + "'");
}

// One cameras.txt line after its CAMERA_ID: model, size and parameters into `c`.
Status parse_camera_fields(const std::vector<std::string_view>& tok, const std::string& where,
                           ColmapCameraRecord& c) {
  const std::string model(tok[1]);
  c.model = detail::colmap_model_by_name(model);
  if (!c.model) {
    return Status::error(where + ": camera " + std::to_string(c.id) + ": unknown camera model '" +
                         model + "' (supported: " + detail::colmap_supported_models() + ")");
  }
  if (!c.model->supported) {
    return Status::error(where + ": camera " + std::to_string(c.id) + ": camera model " + model +
                         " is not supported (supported: " + detail::colmap_supported_models() +
                         ")");
  }
  if (!parse_int(tok[2], &c.width)) return bad_token(where, "WIDTH", tok[2], "an integer");
  if (!parse_int(tok[3], &c.height)) return bad_token(where, "HEIGHT", tok[3], "an integer");
  const size_t np = tok.size() - 4;
  if (np != size_t(c.model->num_params)) {
    return Status::error(where + ": camera " + std::to_string(c.id) + ": " + model + " expects " +
                         std::to_string(c.model->num_params) + " parameters, found " +
                         std::to_string(np));
  }
  c.params.resize(np);
  for (size_t k = 0; k < np; ++k) {
    if (!parse_double(tok[4 + k], &c.params[k])) {
      return bad_token(where, ("PARAMS[" + std::to_string(k) + "]").c_str(), tok[4 + k],
                       "a number");
    }
  }
  return Status::ok();
}

// A line whose CAMERA_ID reads is one camera; when the rest is bad it is kept with `error` set
// (non-strict), so only the images using it are rejected.
Result<std::vector<ColmapCameraRecord>> parse_cameras_txt(const std::string& path, bool strict) {
  MACRO_ASSIGN_OR_RETURN(std::string text, read_text_file(path));
  std::vector<ColmapCameraRecord> cams;
  const auto lines = split_lines(text);
  for (size_t li = 0; li < lines.size(); ++li) {
    const std::string_view line = trim(lines[li]);
    if (line.empty() || line[0] == '#') continue;
    const std::string where = at_line(path, li);
    const auto tok = tokens(line);
    ColmapCameraRecord c;
    c.where = where;
    if (tok.empty() || !parse_int(tok[0], &c.id))
      return bad_token(where, "CAMERA_ID", tok.empty() ? "" : tok[0], "an integer");
    Status s = tok.size() < 4
                   ? Status::error(where + ": expected CAMERA_ID MODEL WIDTH HEIGHT PARAMS..., " +
                                   "found " + std::to_string(tok.size()) + " fields")
                   : parse_camera_fields(tok, where, c);
    if (!s) {
      if (strict) return s;
      c.model = nullptr;
      c.params.clear();
      c.error = s.message();
    }
    cams.push_back(std::move(c));
  }
  return cams;
}

// True if the line is a COLMAP 2D points line: X Y POINT3D_ID triples (or empty).
bool is_points_line(std::string_view line) {
  const auto tok = tokens(line);
  if (tok.size() % 3 != 0) return false;
  for (size_t i = 0; i < tok.size(); ++i) {
    double v;
    if (!parse_double(tok[i], &v)) return false;
  }
  return true;
}

// One image line of images.txt into `im`.
Status parse_image_line(std::string_view line, const std::string& where, ColmapImageRecord& im) {
  static const char* kFields[] = {"IMAGE_ID", "QW", "QX", "QY",       "QZ",
                                  "TX",       "TY", "TZ", "CAMERA_ID"};
  std::string_view rest;
  const auto tok = tokens(line, 9, &rest);
  if (tok.size() == 9) im.name = std::string(rest);
  if (tok.size() < 9 || rest.empty()) {
    return Status::error(where +
                         ": expected IMAGE_ID QW QX QY QZ TX TY TZ CAMERA_ID NAME, found '" +
                         std::string(line.substr(0, 80)) + "'");
  }
  if (!parse_int(tok[0], &im.id)) return bad_token(where, kFields[0], tok[0], "an integer");
  for (int k = 0; k < 4; ++k) {
    if (!parse_double(tok[1 + k], &im.q[k]))
      return bad_token(where, kFields[1 + k], tok[1 + k], "a number");
  }
  for (int k = 0; k < 3; ++k) {
    if (!parse_double(tok[5 + k], &im.t[k]))
      return bad_token(where, kFields[5 + k], tok[5 + k], "a number");
  }
  if (!parse_int(tok[8], &im.camera_id)) return bad_token(where, kFields[8], tok[8], "an integer");
  return Status::ok();
}

// Image lines that do not read are rejected (non-strict) with their position among the image
// entries; their points line is skipped all the same. A bad points line breaks the file's
// two-line structure and is always an error.
Result<std::vector<ColmapImageRecord>> parse_images_txt(const std::string& path, bool strict,
                                                        std::vector<RejectedCamera>* rejected) {
  MACRO_ASSIGN_OR_RETURN(std::string text, read_text_file(path));
  std::vector<ColmapImageRecord> images;
  const auto lines = split_lines(text);
  int entry = 0;  // image entries seen, valid or not
  for (size_t li = 0; li < lines.size(); ++li) {
    const std::string_view line = trim(lines[li]);
    if (line.empty() || line[0] == '#') continue;
    ColmapImageRecord im;
    im.where = at_line(path, li);
    Status s = parse_image_line(line, im.where, im);
    // The next line, whatever it holds, is this image's 2D points line.
    if (li + 1 < lines.size()) {
      ++li;
      if (!is_points_line(lines[li])) {
        return Status::error(at_line(path, li) + ": expected the 2D points line of image " +
                             std::to_string(im.id) + " '" + im.name +
                             "' (X Y POINT3D_ID triples, possibly empty), found '" +
                             std::string(trim(lines[li]).substr(0, 80)) + "'");
      }
    }
    const int index = entry++;
    if (!s) {
      if (strict) return s;
      rejected->push_back({index, im.name, s.message()});
      continue;
    }
    images.push_back(std::move(im));
  }
  return images;
}

}  // namespace

Result<CameraSet> load_colmap_text(const std::string& cameras_txt, const std::string& images_txt,
                                   const CameraLoadOptions& options) {
  MACRO_ASSIGN_OR_RETURN(auto cams, parse_cameras_txt(cameras_txt, options.strict));
  std::vector<RejectedCamera> rejected;
  MACRO_ASSIGN_OR_RETURN(auto images, parse_images_txt(images_txt, options.strict, &rejected));
  // A model without images gives no cameras; every caller needs at least one, so an empty file
  // (or one holding only comments) is refused here, naming it, instead of failing later as "no
  // camera named ...".
  if (images.empty() && rejected.empty())
    return Status::error(images_txt + ": no images: a COLMAP model needs at least one " +
                         "registered image (line 'IMAGE_ID QW QX QY QZ TX TY TZ CAMERA_ID NAME')");
  const size_t slash = cameras_txt.find_last_of('/');
  const std::string folder =
      slash == std::string::npos ? cameras_txt : cameras_txt.substr(0, slash);
  return detail::assemble_colmap(cams, images, cameras_txt, folder, options, std::move(rejected));
}

}  // namespace macro::gs
