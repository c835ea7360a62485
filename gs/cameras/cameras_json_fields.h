// Internal to the camera loaders: reading a JSON file and typed fields from it with messages that
// name the file, the object ("frames[3] 'images/frame_00004.png'") and the field. Not a public API.
#pragma once

#include <Eigen/Core>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "attention/runtime/status.h"
#include "gs/cameras/camera.h"

namespace macro::gs::detail {

using Json = nlohmann::ordered_json;  // keeps object keys in file order

// Reads and parses; a syntax error names the file, the byte position and the parser's message.
Result<Json> parse_json_file(const std::string& path);
Result<Json> parse_json_text(const std::string& text, const std::string& path);

// "string \"abc\"", "array of 3", "object", "null", ... for messages.
std::string describe_json(const Json& v);

bool has_field(const Json& obj, const char* key);
Result<double> number_field(const Json& obj, const char* key, const std::string& where);
Result<double> number_field_or(const Json& obj, const char* key, double fallback,
                               const std::string& where);
// A number with an integral value that fits in int (960 and 960.0 both accepted).
Result<int> int_field(const Json& obj, const char* key, const std::string& where);
Result<std::string> string_field(const Json& obj, const char* key, const std::string& where);
Result<std::vector<std::string>> string_list_field(const Json& obj, const char* key,
                                                   const std::string& where);
// A 4x4 (or, if allow_3x4, 3x4 completed with 0 0 0 1) list of rows of numbers.
Result<Eigen::Matrix4d> matrix_value(const Json& value, const std::string& what, bool allow_3x4);

// A `camera_model` string of nerfstudio / split intrinsics: PINHOLE, SIMPLE_PINHOLE, PERSPECTIVE
// (pinhole) or a model camera.h names. The error names `where` and the field.
Result<CameraModel> intrinsics_model(const std::string& name, const std::string& where);
// The intrinsics keys that hold a model's coefficients, in Camera::distortion order:
// SIMPLE_RADIAL k1; RADIAL k1 k2; OPENCV k1 k2 p1 p2 (k3 is added by the loaders when non-zero);
// FULL_OPENCV k1 k2 p1 p2 k3 k4 k5 k6; OPENCV_FISHEYE k1 k2 k3 k4.
std::vector<const char*> distortion_keys(CameraModel model);

}  // namespace macro::gs::detail
