// macro view (enhance/view/): the API without sockets (bad requests, frames equal to `macro
// render`, close-ups saved and read back by the project's loaders, one job at a time), and the
// server as a process (HTTP errors leave it alive; SIGINT stops it cleanly).
#include <catch2/catch.hpp>
#include <nlohmann/json.hpp>

#include "enhance/view/view_api.h"
#include "enhance/view/view_session.h"
#include "gs/image_io.h"
#include "tests/cli_run.h"
#include "tests/view_fixture.h"

// After the project headers: httplib.h pulls in <resolv.h>, whose `_res` macro breaks Eigen.
#include <httplib.h>

using namespace macro;
using namespace macro::enhance::view;
using Json = nlohmann::json;

namespace {

std::unique_ptr<ViewSession> open_synthclose(const test::TempDir& dir) {
  test::copy_synthclose(dir.file("scene"));
  ViewOptions o;
  o.scene_dir = dir.file("scene");
  o.results_dir = dir.file("results");
  o.render_threads = 2;
  auto s = ViewSession::open(o);
  REQUIRE(s.is_ok());
  return std::move(*s);
}

Json body_json(const Reply& r) {
  return Json::parse(r.body, nullptr, false);
}

}  // namespace

TEST_CASE("view API: bad requests get a clear error status and the session keeps serving",
          "[view]") {
  test::TempDir dir("view-api-bad");
  auto s = open_synthclose(dir);
  struct Case {
    const char* method;
    const char* path;
    std::string body;
    int status;
    const char* says;
  };
  Json huge = camera_to_json(*s->find_camera("train_00.png"));
  huge["width"] = 100000;
  huge["height"] = 100000;
  Json bad_pose = camera_to_json(*s->find_camera("train_00.png"));
  bad_pose["world_to_camera"][0][0] = 7.0;  // not a rotation
  const Case cases[] = {
      {"POST", "/api/render", "{not json", 400, "malformed JSON"},
      {"POST", "/api/render", "[1, 2]", 400, "expected a JSON object"},
      {"POST", "/api/render", "{}", 400, "missing field 'camera'"},
      {"POST", "/api/render", R"({"camera": "no_such_camera.png"})", 404, "unknown camera"},
      {"POST", "/api/render", Json({{"camera", huge}}).dump(), 413, "larger than the viewer"},
      {"POST", "/api/render", Json({{"camera", bad_pose}}).dump(), 400, "camera"},
      {"POST", "/api/render", R"({"camera": {"width": "wide"}})", 400, "field 'width'"},
      {"POST", "/api/render", R"({"camera": "train_00.png", "scale": 3})", 400, "scale"},
      {"POST", "/api/render", std::string(kMaxRequestBytes + 10, ' '), 413, "larger than"},
      {"GET", "/api/render", "", 405, "expected POST"},
      {"GET", "/api/nothing", "", 404, "no such endpoint"},
      {"GET", "/api/results/../split.json", "", 404, "not a result name"},
      {"GET", "/api/results/plan-1/none.png", "", 404, "no such file"},
      {"POST", "/api/closeups", R"({"name": "../x.png", "camera": "train_00.png"})", 400,
       "must not start with '.'"},
      {"POST", "/api/closeups", R"({"name": "a/x.png", "camera": "train_00.png"})", 400,
       "only letters"},
      {"POST", "/api/closeups", R"({"name": "train_01.png", "camera": "train_00.png"})", 400,
       "training camera"},
      {"POST", "/api/closeups", R"({"name": "a.png", "camera": "train_00.png", "overwrite": 1})",
       400, "overwrite"},
      {"POST", "/api/plan", R"({"camera": 5})", 400, "expected a camera object"},
      {"POST", "/api/enhance", R"({"camera": "nope"})", 404, "unknown camera"},
  };
  for (const Case& c : cases) {
    INFO(c.method << " " << c.path << " " << c.body.substr(0, 80));
    const Reply r = handle_api(*s, c.method, c.path, c.body);
    CHECK(r.status == c.status);
    const Json j = body_json(r);
    REQUIRE(j.is_object());
    CHECK_THAT(j.value("error", std::string()), Catch::Contains(c.says));
  }
  // Still serving.
  CHECK(handle_api(*s, "GET", "/api/scene", "").status == 200);
  CHECK(handle_api(*s, "POST", "/api/render", R"({"camera": "train_00.png", "scale": 0.25})")
            .status == 200);
}

TEST_CASE("view API: a frame equals macro render of the same camera, at full and low resolution",
          "[view]") {
  test::TempDir dir("view-api-frame");
  auto s = open_synthclose(dir);
  const Reply r = handle_api(*s, "POST", "/api/render", R"({"camera": "closeup_01.png"})");
  REQUIRE(r.status == 200);
  CHECK(r.content_type == "image/png");
  const test::Run run =
      test::run_macro("render --quiet --scene " + dir.file("scene") +
                          " --camera closeup_01.png --out-png " + dir.file("render.png"),
                      dir);
  REQUIRE(run.rc == 0);
  CHECK(r.body == test::read_all(dir.file("render.png")));  // byte for byte
  // Half resolution: the intrinsics scaled with the image (Camera::resized).
  const Reply low =
      handle_api(*s, "POST", "/api/render", R"({"camera": "closeup_01.png", "scale": 0.5})");
  REQUIRE(low.status == 200);
  auto img =
      gs::decode_image(reinterpret_cast<const uint8_t*>(low.body.data()), low.body.size(), "frame");
  REQUIRE(img.is_ok());
  CHECK(img->width == 320);
  CHECK(img->height == 180);
}

TEST_CASE("view API: close-ups saved to the split JSON and to a cameras JSON load back", "[view]") {
  test::TempDir dir("view-api-save");
  auto s = open_synthclose(dir);
  const std::string split = dir.file("scene/split.json");
  CHECK(s->store().kind == CloseupStore::kSplit);
  gs::Camera cam = *s->find_camera("train_02.png");
  // Moved a little towards the scene, as a close-up is placed.
  Eigen::Matrix4d w2c = cam.world_to_camera();
  w2c(2, 3) -= 0.5;
  cam.set_world_to_camera(w2c);
  Json req = {{"name", "picked.png"}, {"camera", camera_to_json(cam)}};
  Reply r = handle_api(*s, "POST", "/api/closeups", req.dump());
  REQUIRE(r.status == 200);
  auto loaded = gs::load_closeup_split(split);
  REQUIRE(loaded.is_ok());
  auto back = loaded->closeups.find("picked.png");
  REQUIRE(back.is_ok());
  CHECK((back->R - cam.R).cwiseAbs().maxCoeff() < 1e-12);
  CHECK((back->t - cam.t).cwiseAbs().maxCoeff() < 1e-12);
  CHECK(loaded->closeups.find("closeup_01.png").is_ok());  // the others are kept
  // The same name again: 409 unless replaced on purpose.
  CHECK(handle_api(*s, "POST", "/api/closeups", req.dump()).status == 409);
  req["overwrite"] = true;
  CHECK(handle_api(*s, "POST", "/api/closeups", req.dump()).status == 200);
  // Another field of view does not fit the split's shared intrinsics.
  gs::Camera wide = cam;
  wide.fx = wide.fy = 300;
  r = handle_api(*s, "POST", "/api/closeups",
                 Json({{"name", "wide.png"}, {"camera", camera_to_json(wide)}}).dump());
  CHECK(r.status == 400);
  CHECK_THAT(body_json(r)["error"].get<std::string>(), Catch::Contains("share its intrinsics"));
  // Listed, and reopened by name as the loader reads it.
  r = handle_api(*s, "GET", "/api/closeups", "");
  REQUIRE(r.status == 200);
  const Json listing = body_json(r);
  bool listed = false;
  for (const Json& c : listing["closeups"]) listed |= c["name"] == "picked.png";
  CHECK(listed);
  CHECK(handle_api(*s, "POST", "/api/render", R"({"camera": "picked.png"})").status == 200);

  // A cameras JSON keeps the intrinsics too.
  CloseupStore store;
  store.kind = CloseupStore::kCameras;
  store.path = dir.file("closeups.json");
  bool exists = false;
  REQUIRE(save_closeup(store, "wide.png", wide, false, {}, &exists).is_ok());
  REQUIRE(save_closeup(store, "picked.png", cam, false, {}, &exists).is_ok());
  auto set = gs::load_cameras(store.path);
  REQUIRE(set.is_ok());
  REQUIRE(set->cameras.size() == 2);
  CHECK(set->cameras[0].fx == 300);
  CHECK(set->cameras[1].t == cam.t);  // exactly: the writer round-trips doubles
  CHECK_FALSE(save_closeup(store, "wide.png", wide, false, {}, &exists).is_ok());
  CHECK(exists);
}

TEST_CASE("view API: plan lists its images, one enhance at a time, the second refused", "[view]") {
  test::TempDir dir("view-api-jobs");
  auto s = open_synthclose(dir);
  Reply r = handle_api(*s, "POST", "/api/plan", R"({"camera": "closeup_01.png"})");
  REQUIRE(r.status == 200);
  Json plan = body_json(r);
  CHECK(plan["plan"]["references"].size() == 3);
  bool plane_map = false, crop = false;
  for (const Json& f : plan["files"]) {
    plane_map |= f.get<std::string>().find("plane_map.png") != std::string::npos;
    crop |= f.get<std::string>().find("crop_00") != std::string::npos;
    CHECK(handle_api(*s, "GET", "/api/results/" + f.get<std::string>(), "").status == 200);
  }
  CHECK(plane_map);
  CHECK(crop);

  r = handle_api(*s, "POST", "/api/enhance", R"({"camera": "closeup_01.png"})");
  REQUIRE(r.status == 202);
  CHECK(handle_api(*s, "POST", "/api/enhance", R"({"camera": "closeup_01.png"})").status == 409);
  CHECK(handle_api(*s, "POST", "/api/plan", R"({"camera": "closeup_01.png"})").status == 409);
  s->join_job();
  r = handle_api(*s, "GET", "/api/enhance", "");
  const Json job = body_json(r);
  REQUIRE(job["state"] == "done");
  CHECK(job["log"].size() >= 2);  // the stages, as `macro enhance` prints them
  auto enhanced =
      gs::read_image(s->results_dir() + "/" + job["result"]["enhanced"].get<std::string>());
  auto render = gs::read_image(s->results_dir() + "/" + job["result"]["render"].get<std::string>());
  REQUIRE(enhanced.is_ok());
  REQUIRE(render.is_ok());
  CHECK(enhanced->width == 640);
  CHECK(test::compare(enhanced->data, render->data).max_abs > 0);  // the transfer changed it
}

TEST_CASE("macro view: HTTP errors keep the server up, SIGINT stops it cleanly", "[view]") {
  test::TempDir dir("view-http");
  test::copy_synthclose(dir.file("scene"));
  test::ViewServer server;
  REQUIRE(server.start(dir.file("scene"), dir.path));
  httplib::Client cli("127.0.0.1", server.port);
  cli.set_read_timeout(30, 0);
  auto page = cli.Get("/");
  REQUIRE(page);
  CHECK(page->status == 200);
  CHECK_THAT(page->body, Catch::Contains("viewer.js"));
  auto bad = cli.Post("/api/render", "{oops", "application/json");
  REQUIRE(bad);
  CHECK(bad->status == 400);
  auto big = cli.Post("/api/render", std::string(3 << 20, 'x'), "application/json");
  if (big) CHECK(big->status == 413);  // or the connection is closed on it
  auto unknown = cli.Post("/api/render", R"({"camera": "nope.png"})", "application/json");
  REQUIRE(unknown);
  CHECK(unknown->status == 404);
  auto frame = cli.Post("/api/render", R"({"camera": "train_00.png"})", "application/json");
  REQUIRE(frame);
  CHECK(frame->status == 200);
  CHECK(frame->get_header_value("Content-Type") == "image/png");
  server.child.signal(SIGINT);
  CHECK(server.child.wait_for(20) == 0);
  INFO(server.log());
  CHECK_THAT(server.log(), Catch::Contains("stopped"));
}
