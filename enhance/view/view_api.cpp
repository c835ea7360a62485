// The viewer's API routes (see view_api.h and docs/viewer.md §2).
#include "enhance/view/view_api.h"

#include <cmath>

#include "attention/runtime/file_io.h"

namespace macro::enhance::view {
using Json = nlohmann::json;

namespace {
// Invalid UTF-8 (a name from a request) is replaced, never thrown on.
std::string dump(const Json& j) {
  return j.dump(-1, ' ', false, Json::error_handler_t::replace);
}
}  // namespace

Reply error_reply(int status, const std::string& message) {
  Reply r;
  r.status = status;
  r.body = dump(Json({{"error", message}}));
  return r;
}

namespace {

Reply json_reply(const Json& j, int status = 200) {
  Reply r;
  r.status = status;
  r.body = dump(j);
  return r;
}

// The request body as a JSON object, or the error reply.
bool parse_body(const std::string& body, Json* out, Reply* err) {
  if (body.size() > kMaxRequestBytes) {
    *err = error_reply(413, "request body of " + std::to_string(body.size()) +
                                " bytes is larger than " + std::to_string(kMaxRequestBytes));
    return false;
  }
  *out = Json::parse(body, nullptr, false);
  if (out->is_discarded()) {
    *err = error_reply(400, "request body: malformed JSON");
    return false;
  }
  if (!out->is_object()) {
    *err = error_reply(400, "request body: expected a JSON object");
    return false;
  }
  return true;
}

// body.camera: a camera's name (from the scene or the close-up file) or a camera object.
bool request_camera(ViewSession& s, const Json& body, const char* what, gs::Camera* out,
                    Reply* err) {
  if (!body.contains("camera")) {
    *err = error_reply(400, std::string(what) + ": missing field 'camera'");
    return false;
  }
  const Json& c = body["camera"];
  if (c.is_string()) {
    auto found = s.find_camera(c.get<std::string>());
    if (!found) {
      *err = error_reply(404, std::string(what) + ": unknown camera '" + c.get<std::string>() +
                                  "' (GET /api/scene and /api/closeups list them)");
      return false;
    }
    *out = *found;
    return true;
  }
  bool too_large = false;
  auto cam = camera_from_json(c, std::string(what) + ": camera", {}, &too_large);
  if (!cam) {
    *err = error_reply(too_large ? 413 : 400, cam.status().message());
    return false;
  }
  *out = *cam;
  return true;
}

Reply route_render(ViewSession& s, const Json& body) {
  Reply err;
  gs::Camera cam;
  if (!request_camera(s, body, "render", &cam, &err)) return err;
  double scale = 1;
  if (body.contains("scale")) {
    if (!body["scale"].is_number() || !(body["scale"].get<double>() > 0) ||
        body["scale"].get<double>() > 1)
      return error_reply(400, "render: field 'scale': expected a number in (0, 1]");
    scale = body["scale"].get<double>();
  }
  const FrameLimits limits;
  if (cam.width > limits.max_side || cam.height > limits.max_side ||
      (long long)cam.width * cam.height > limits.max_pixels)
    return error_reply(413, "render: camera '" + cam.name + "' is " + std::to_string(cam.width) +
                                "x" + std::to_string(cam.height) + ", over the frame limits");
  auto frame = s.render(scaled_camera(cam, scale));
  if (!frame) return error_reply(500, "render: " + frame.status().message());
  Reply r;
  r.content_type = "image/png";
  r.body.assign(frame->png.begin(), frame->png.end());
  char ms[64];
  std::snprintf(ms, sizeof ms, "%.2f", frame->ms_render);
  r.headers.push_back({"X-Render-Ms", ms});
  std::snprintf(ms, sizeof ms, "%.2f", frame->ms_encode);
  r.headers.push_back({"X-Encode-Ms", ms});
  r.headers.push_back(
      {"X-Frame-Size", std::to_string(frame->width) + "x" + std::to_string(frame->height)});
  r.headers.push_back({"Cache-Control", "no-store"});
  return r;
}

Reply route_closeups_get(ViewSession& s) {
  auto listed = s.closeups();
  if (!listed) return error_reply(500, listed.status().message());
  Json list = Json::array();
  for (const gs::Camera& c : listed->cameras) list.push_back(camera_to_json(c));
  return json_reply({{"file", s.store().path},
                     {"kind", closeup_store_kind_name(s.store().kind)},
                     {"closeups", list}});
}

Reply route_closeups_post(ViewSession& s, const Json& body) {
  if (!body.contains("name") || !body["name"].is_string())
    return error_reply(400, "save close-up: field 'name': expected a string");
  const std::string name = body["name"].get<std::string>();
  bool overwrite = false;
  if (body.contains("overwrite")) {
    if (!body["overwrite"].is_boolean())
      return error_reply(400, "save close-up: field 'overwrite': expected true or false");
    overwrite = body["overwrite"].get<bool>();
  }
  Reply err;
  gs::Camera cam;
  if (!request_camera(s, body, "save close-up", &cam, &err)) return err;
  bool exists = false;
  if (Status st = s.save_closeup(name, cam, overwrite, &exists); !st)
    return error_reply(exists ? 409 : 400, st.message());
  return json_reply({{"saved", name},
                     {"file", s.store().path},
                     {"kind", closeup_store_kind_name(s.store().kind)}});
}

Reply route_plan(ViewSession& s, const Json& body) {
  if (!s.can_plan()) return error_reply(400, "plan: needs a scene folder (macro view --scene-dir)");
  if (s.job_running()) return error_reply(409, "plan: a job is running; try again when it ends");
  Reply err;
  gs::Camera cam;
  if (!request_camera(s, body, "plan", &cam, &err)) return err;
  auto plan = s.plan(cam);
  if (!plan) return error_reply(s.job_running() ? 409 : 500, plan.status().message());
  return json_reply(*plan);
}

Reply route_enhance_post(ViewSession& s, const Json& body) {
  if (!s.can_plan())
    return error_reply(400, "enhance: needs a scene folder (macro view --scene-dir)");
  Reply err;
  gs::Camera cam;
  if (!request_camera(s, body, "enhance", &cam, &err)) return err;
  auto started = s.start_enhance(cam);
  if (!started) return error_reply(500, started.status().message());
  if (!*started) return error_reply(409, "enhance: a job is running; only one runs at a time");
  return json_reply({{"state", "running"}}, 202);
}

Reply route_enhance_get(ViewSession& s) {
  const JobState j = s.job();
  return json_reply({{"state", j.state},
                     {"closeup", j.closeup},
                     {"stage", j.stage},
                     {"log", j.log},
                     {"elapsed_ms", j.elapsed_ms},
                     {"error", j.error},
                     {"result", j.result}});
}

Reply route_result(ViewSession& s, const std::string& rel) {
  auto path = s.result_file(rel);
  if (!path) return error_reply(404, path.status().message());
  auto bytes = read_file(*path, 1ull << 30);
  if (!bytes) return error_reply(500, bytes.status().message());
  Reply r;
  const bool png = rel.size() > 4 && rel.compare(rel.size() - 4, 4, ".png") == 0;
  r.content_type = png ? "image/png" : "application/json";
  r.body.assign(bytes->begin(), bytes->end());
  const std::string file = rel.substr(rel.find('/') + 1);
  r.headers.push_back({"Content-Disposition", "inline; filename=\"" + file + "\""});
  return r;
}

}  // namespace

Reply handle_api(ViewSession& s, const std::string& method, const std::string& path,
                 const std::string& body) {
  const bool get = method == "GET", post = method == "POST";
  auto wrong_method = [&](const char* allowed) {
    Reply r = error_reply(405, method + " " + path + ": expected " + allowed);
    r.headers.push_back({"Allow", allowed});
    return r;
  };
  const std::string results = "/api/results/";
  if (path.rfind(results, 0) == 0) {
    if (!get) return wrong_method("GET");
    return route_result(s, path.substr(results.size()));
  }
  if (path == "/api/scene") return get ? json_reply(s.scene_json()) : wrong_method("GET");
  if (path == "/api/enhance" && get) return route_enhance_get(s);
  if (path == "/api/closeups" && get) return route_closeups_get(s);
  const bool known = path == "/api/render" || path == "/api/closeups" || path == "/api/plan" ||
                     path == "/api/enhance";
  if (!known) return error_reply(404, path + ": no such endpoint (docs/viewer.md lists them)");
  if (!post)
    return wrong_method(path == "/api/render" || path == "/api/plan" ? "POST" : "GET, POST");
  Json j;
  Reply err;
  if (!parse_body(body, &j, &err)) return err;
  if (path == "/api/render") return route_render(s, j);
  if (path == "/api/closeups") return route_closeups_post(s, j);
  if (path == "/api/plan") return route_plan(s, j);
  return route_enhance_post(s, j);
}

}  // namespace macro::enhance::view
