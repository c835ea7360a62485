// JSON reading helpers shared by the camera loaders (gs/cameras/cameras_json_fields.h).
#include "gs/cameras/cameras_json_fields.h"

#include <cmath>
#include <cstdio>
#include <limits>

#include "attention/runtime/file_io.h"

namespace macro::gs::detail {

Result<Json> parse_json_text(const std::string& text, const std::string& path) {
  try {
    return Json::parse(text);
  } catch (const nlohmann::json::parse_error& e) {
    std::string msg = path + ": malformed JSON at byte " + std::to_string(e.byte) + ": " + e.what();
    // Python's json.dump writes NaN / Infinity, which JSON does not allow.
    size_t at = e.byte > 0 ? e.byte - 1 : 0;
    if (at < text.size() &&
        (text.compare(at, 3, "NaN") == 0 || text.compare(at, 8, "Infinity") == 0 ||
         text.compare(at, 9, "-Infinity") == 0)) {
      msg += " (NaN/Infinity are not valid JSON numbers)";
    }
    return Status::error(msg);
  } catch (const std::exception& e) {
    return Status::error(path + ": cannot parse JSON: " + e.what());
  }
}

Result<Json> parse_json_file(const std::string& path) {
  MACRO_ASSIGN_OR_RETURN(std::string text, read_text_file(path, 1ull << 30));
  return parse_json_text(text, path);
}

std::string describe_json(const Json& v) {
  if (v.is_null()) return "null";
  if (v.is_boolean()) return std::string("boolean ") + (v.get<bool>() ? "true" : "false");
  if (v.is_number()) return "number " + v.dump();
  if (v.is_string()) {
    std::string s = v.get<std::string>();
    if (s.size() > 40) s = s.substr(0, 40) + "...";
    return "string \"" + s + "\"";
  }
  if (v.is_array()) return "array of " + std::to_string(v.size());
  if (v.is_object()) return "object";
  return "value";
}

bool has_field(const Json& obj, const char* key) {
  return obj.is_object() && obj.contains(key);
}

namespace {
Status missing(const char* key, const std::string& where) {
  return Status::error(where + ": missing field '" + key + "'");
}
Status wrong(const char* key, const char* expected, const Json& v, const std::string& where) {
  return Status::error(where + ": field '" + key + "': expected " + expected + ", found " +
                       describe_json(v));
}
}  // namespace

Result<double> number_field(const Json& obj, const char* key, const std::string& where) {
  if (!obj.is_object())
    return Status::error(where + ": expected an object, found " + describe_json(obj));
  auto it = obj.find(key);
  if (it == obj.end()) return missing(key, where);
  if (!it->is_number()) return wrong(key, "a number", *it, where);
  return it->get<double>();
}

Result<double> number_field_or(const Json& obj, const char* key, double fallback,
                               const std::string& where) {
  if (!has_field(obj, key)) return fallback;
  return number_field(obj, key, where);
}

Result<int> int_field(const Json& obj, const char* key, const std::string& where) {
  MACRO_ASSIGN_OR_RETURN(double v, number_field(obj, key, where));
  if (!(v == std::floor(v)) || v < std::numeric_limits<int>::min() ||
      v > std::numeric_limits<int>::max()) {
    return wrong(key, "an integer", obj.at(key), where);
  }
  return static_cast<int>(v);
}

Result<std::string> string_field(const Json& obj, const char* key, const std::string& where) {
  if (!obj.is_object())
    return Status::error(where + ": expected an object, found " + describe_json(obj));
  auto it = obj.find(key);
  if (it == obj.end()) return missing(key, where);
  if (!it->is_string()) return wrong(key, "a string", *it, where);
  return it->get<std::string>();
}

Result<std::vector<std::string>> string_list_field(const Json& obj, const char* key,
                                                   const std::string& where) {
  if (!obj.is_object())
    return Status::error(where + ": expected an object, found " + describe_json(obj));
  auto it = obj.find(key);
  if (it == obj.end()) return missing(key, where);
  if (!it->is_array()) return wrong(key, "a list of strings", *it, where);
  std::vector<std::string> out;
  out.reserve(it->size());
  for (size_t i = 0; i < it->size(); ++i) {
    const Json& e = (*it)[i];
    if (!e.is_string()) {
      return Status::error(where + ": field '" + key + "'[" + std::to_string(i) +
                           "]: expected a string, found " + describe_json(e));
    }
    out.push_back(e.get<std::string>());
  }
  return out;
}

Result<Eigen::Matrix4d> matrix_value(const Json& value, const std::string& what, bool allow_3x4) {
  const char* expected =
      allow_3x4 ? "a 4x4 or 3x4 matrix (list of rows)" : "a 4x4 matrix (list of rows)";
  const size_t rows = value.is_array() ? value.size() : 0;
  if (!(rows == 4 || (allow_3x4 && rows == 3))) {
    return Status::error(what + ": expected " + expected + ", found " + describe_json(value));
  }
  Eigen::Matrix4d m = Eigen::Matrix4d::Identity();
  for (size_t r = 0; r < rows; ++r) {
    const Json& row = value[r];
    if (!row.is_array() || row.size() != 4) {
      return Status::error(what + ": row " + std::to_string(r) + ": expected 4 numbers, found " +
                           describe_json(row));
    }
    for (size_t c = 0; c < 4; ++c) {
      if (!row[c].is_number()) {
        return Status::error(what + ": element [" + std::to_string(r) + "][" + std::to_string(c) +
                             "]: expected a number, found " + describe_json(row[c]));
      }
      m(r, c) = row[c].get<double>();
    }
  }
  if (rows == 4) {
    const Eigen::RowVector4d last = m.row(3);
    if (!((last - Eigen::RowVector4d(0, 0, 0, 1)).cwiseAbs().maxCoeff() <= 1e-6)) {
      char buf[128];
      std::snprintf(buf, sizeof buf, "[%.9g, %.9g, %.9g, %.9g]", last(0), last(1), last(2),
                    last(3));
      return Status::error(what + ": last row is " + buf + ", expected [0, 0, 0, 1]");
    }
  }
  return m;
}

Result<CameraModel> intrinsics_model(const std::string& name, const std::string& where) {
  if (name == "PINHOLE" || name == "SIMPLE_PINHOLE" || name == "PERSPECTIVE")
    return CameraModel::kPinhole;
  CameraModel m;
  if (camera_model_from_name(name, &m)) return m;
  return Status::error(where + ": field 'camera_model': camera model '" + name +
                       "' is not supported (supported: PINHOLE, SIMPLE_PINHOLE, SIMPLE_RADIAL, "
                       "RADIAL, OPENCV, FULL_OPENCV, OPENCV_FISHEYE)");
}

std::vector<const char*> distortion_keys(CameraModel model) {
  switch (model) {
    case CameraModel::kPinhole:
      return {};
    case CameraModel::kSimpleRadial:
      return {"k1"};
    case CameraModel::kRadial:
      return {"k1", "k2"};
    case CameraModel::kOpenCV:
      return {"k1", "k2", "p1", "p2"};
    case CameraModel::kFullOpenCV:
      return {"k1", "k2", "p1", "p2", "k3", "k4", "k5", "k6"};
    case CameraModel::kOpenCVFisheye:
      return {"k1", "k2", "k3", "k4"};
  }
  return {};
}

}  // namespace macro::gs::detail
