// macro view in a real browser: headless Chromium (Debian's `chromium`, driven through its
// DevTools protocol by tests/devtools_client.h; nothing downloaded) loads the page, the camera is
// moved with mouse and key events, a close-up is saved and reopened, plan and enhance are run, and
// what the page shows is checked: the canvas equals `macro render` of the same camera, the saved
// split JSON loads with the project's reader, screenshots show the frame and the render |
// enhanced comparison. Skipped, with a message, where /usr/bin/chromium (or $MACRO_CHROMIUM) is
// absent: .ci/install-deps.sh installs it.
#include <catch2/catch.hpp>
#include <nlohmann/json.hpp>

#include "attention/runtime/file_io.h"
#include "gs/cameras/camera.h"
#include "gs/image_io.h"
#include "tests/cli_run.h"
#include "tests/devtools_client.h"
#include "tests/view_fixture.h"

// After the project headers: httplib.h pulls in <resolv.h>, whose `_res` macro breaks Eigen.
#include <httplib.h>

using namespace macro;
using Json = nlohmann::json;

namespace {

std::string chromium_path() {
  if (const char* env = std::getenv("MACRO_CHROMIUM"); env && *env) return env;
  return "/usr/bin/chromium";
}

// base64 (the data: URLs and screenshots DevTools returns).
std::vector<uint8_t> base64_decode(const std::string& s) {
  auto val = [](char c) -> int {
    if (c >= 'A' && c <= 'Z') return c - 'A';
    if (c >= 'a' && c <= 'z') return c - 'a' + 26;
    if (c >= '0' && c <= '9') return c - '0' + 52;
    if (c == '+') return 62;
    if (c == '/') return 63;
    return -1;
  };
  std::vector<uint8_t> out;
  int bits = 0, acc = 0;
  for (char c : s) {
    const int v = val(c);
    if (v < 0) continue;
    acc = (acc << 6) | v;
    bits += 6;
    if (bits >= 8) {
      bits -= 8;
      out.push_back(uint8_t((acc >> bits) & 0xff));
    }
  }
  return out;
}

gs::Image decode(const std::vector<uint8_t>& png, const char* what) {
  auto img = gs::decode_image(png.data(), png.size(), what);
  REQUIRE(img.is_ok());
  return *img;
}

// The canvas pixels as a PNG, decoded.
gs::Image canvas_image(test::DevTools& dt) {
  const Json url = dt.eval("document.getElementById('frame').toDataURL('image/png')");
  REQUIRE(url.is_string());
  const std::string s = url.get<std::string>();
  return decode(base64_decode(s.substr(s.find(',') + 1)), "canvas");
}

// `macro render` of camera `name` from `cameras` (a file) or the scene folder's own files.
gs::Image macro_render(const test::TempDir& dir, const std::string& scene, const std::string& name,
                       const std::string& cameras = "") {
  const std::string out = dir.file("render-" + name + ".png");
  const test::Run run = test::run_macro("render --quiet --scene " + scene +
                                            (cameras.empty() ? "" : " --cameras " + cameras) +
                                            " --camera " + name + " --out-png " + out,
                                        dir);
  INFO(run.err);
  REQUIRE(run.rc == 0);
  auto img = gs::read_image(out);
  REQUIRE(img.is_ok());
  return *img;
}

// A region of a screenshot (page coordinates), decoded.
gs::Image screenshot(test::DevTools& dt, const std::string& element_id) {
  const Json rect = dt.eval("(() => { const r = document.getElementById('" + element_id +
                            "').getBoundingClientRect(); return {x: r.left + scrollX, y: r.top + "
                            "scrollY, w: r.width, h: r.height}; })()");
  REQUIRE(rect.is_object());
  const Json shot = dt.call("Page.captureScreenshot",
                            {{"format", "png"},
                             {"captureBeyondViewport", true},
                             {"clip",
                              {{"x", rect["x"]},
                               {"y", rect["y"]},
                               {"width", rect["w"]},
                               {"height", rect["h"]},
                               {"scale", 1}}}},
                            30000);
  REQUIRE(shot.contains("data"));
  return decode(base64_decode(shot["data"].get<std::string>()), "screenshot");
}

void mouse(test::DevTools& dt, const char* type, double x, double y, int buttons) {
  dt.call("Input.dispatchMouseEvent", {{"type", type},
                                       {"x", x},
                                       {"y", y},
                                       {"button", "left"},
                                       {"buttons", buttons},
                                       {"clickCount", 1}});
}

}  // namespace

TEST_CASE("macro view in headless Chromium: move, save, reopen, plan, enhance", "[view][browser]") {
  if (::access(chromium_path().c_str(), X_OK) != 0) {
    WARN("skipped: no Chromium at " + chromium_path() +
         " (install it with .ci/install-deps.sh, or set MACRO_CHROMIUM)");
    return;
  }
  test::TempDir dir("view-browser");
  const std::string scene = dir.file("scene");
  test::copy_synthclose(scene);
  test::ViewServer server;
  REQUIRE(server.start(scene, dir.path));
  const std::string page = "http://127.0.0.1:" + std::to_string(server.port) + "/";

  test::Child chrome;
  const std::string profile = dir.file("chrome-profile");
  REQUIRE(chrome.start(
      {chromium_path(), "--headless=new", "--no-sandbox", "--disable-gpu", "--no-first-run",
       "--no-default-browser-check", "--disable-extensions", "--disable-background-networking",
       "--disable-sync", "--force-device-scale-factor=1", "--window-size=1400,1000",
       "--remote-debugging-port=0", "--user-data-dir=" + profile, page},
      dir.file("chrome.out"), dir.file("chrome.err"), /*own_group=*/true));
  // The DevTools port, from the profile's DevToolsActivePort file.
  int devtools_port = 0;
  for (int i = 0; i < 600 && devtools_port == 0; ++i) {
    devtools_port = std::atoi(test::read_all(profile + "/DevToolsActivePort").c_str());
    if (devtools_port == 0) ::usleep(50000);
  }
  INFO(test::read_all(dir.file("chrome.err")));
  REQUIRE(devtools_port > 0);
  std::string ws;
  httplib::Client http("127.0.0.1", devtools_port);
  for (int i = 0; i < 200 && ws.empty(); ++i) {
    if (auto res = http.Get("/json/list"); res && res->status == 200) {
      for (const Json& t : Json::parse(res->body, nullptr, false))
        if (t.value("type", "") == "page" && t.value("url", "").rfind(page, 0) == 0)
          ws = t.value("webSocketDebuggerUrl", "");
    }
    if (ws.empty()) ::usleep(50000);
  }
  REQUIRE_FALSE(ws.empty());
  test::DevTools dt;
  std::string error;
  REQUIRE(dt.connect(ws, &error));

  // Loaded: the first camera's full-resolution frame, equal to `macro render` of it.
  REQUIRE(dt.wait_true("window.viewer && viewer.idle()", 30000));
  const Json first = dt.eval("viewer.camera()");
  REQUIRE(first.is_object());
  {
    const gs::Image shown = canvas_image(dt);
    const gs::Image want = macro_render(dir, scene, first["name"].get<std::string>());
    CHECK(shown.width == want.width);
    CHECK(test::compare(shown.data, want.data).max_abs == 0);
  }

  // Orbit with a mouse drag, then fly forward with the W key.
  const Json rect = dt.eval(
      "(() => { const r = document.getElementById('frame')"
      ".getBoundingClientRect(); return [r.left, r.top, r.width, r.height]; })()");
  const double cx = rect[0].get<double>() + rect[2].get<double>() / 2;
  const double cy = rect[1].get<double>() + rect[3].get<double>() / 2;
  mouse(dt, "mousePressed", cx, cy, 1);
  for (int k = 1; k <= 6; ++k) mouse(dt, "mouseMoved", cx + 8 * k, cy + 3 * k, 1);
  mouse(dt, "mouseReleased", cx + 48, cy + 18, 0);
  for (const char* type : {"keyDown", "keyUp"})
    dt.call("Input.dispatchKeyEvent", {{"type", type},
                                       {"key", "w"},
                                       {"code", "KeyW"},
                                       {"text", "w"},
                                       {"windowsVirtualKeyCode", 87}});
  REQUIRE(dt.wait_true("viewer.idle()", 30000));
  const Json moved = dt.eval("viewer.camera()");
  CHECK(moved["world_to_camera"] != first["world_to_camera"]);
  {
    // The canvas equals `macro render` of the camera the page reports (written as a cameras JSON).
    Json cam = moved;
    cam["name"] = "moved";
    REQUIRE(write_file_atomic(dir.file("moved.json"), Json::array({cam}).dump()).is_ok());
    const gs::Image shown = canvas_image(dt);
    const gs::Image want = macro_render(dir, scene + "/scene.spz", "moved", dir.file("moved.json"));
    CHECK(test::compare(shown.data, want.data).max_abs == 0);
  }

  // Save it as a close-up into the scene's split.json, then reopen it from the list.
  dt.eval("document.getElementById('closeup-name').value = 'browser_pick.png'");
  dt.eval("document.getElementById('save').click()");
  REQUIRE(
      dt.wait_true("[...document.getElementById('closeups').options].some(o => o.value === "
                   "'browser_pick.png')",
                   20000));
  auto split = gs::load_closeup_split(scene + "/split.json");
  REQUIRE(split.is_ok());
  auto saved = split->closeups.find("browser_pick.png");
  REQUIRE(saved.is_ok());
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 4; ++c)
      CHECK(std::abs(saved->world_to_camera()(r, c) -
                     moved["world_to_camera"][size_t(r)][size_t(c)].get<double>()) < 1e-9);
  dt.eval(
      "document.getElementById('cameras').value = 'train_03.png'; "
      "document.getElementById('cameras').dispatchEvent(new Event('change'))");
  REQUIRE(dt.wait_true("viewer.idle() && viewer.camera().name === 'train_03.png'", 20000));
  dt.eval(
      "document.getElementById('closeups').value = 'browser_pick.png'; "
      "document.getElementById('reopen').click()");
  REQUIRE(dt.wait_true("viewer.idle() && viewer.camera().name === 'browser_pick.png'", 20000));
  const gs::Image want_pick = macro_render(dir, scene, "browser_pick.png");  // via split.json
  CHECK(test::compare(canvas_image(dt).data, want_pick.data).max_abs == 0);
  dt.eval("document.getElementById('show-frusta').click()");  // the overlay off for screenshots
  {
    // What is on screen: the canvas region of a screenshot (composited; loose bound).
    const gs::Image shot = screenshot(dt, "frame");
    REQUIRE(shot.width == want_pick.width);
    REQUIRE(shot.height == want_pick.height);
    std::vector<float> rgb(shot.pixels() * 3);
    for (size_t p = 0; p < shot.pixels(); ++p)
      for (int c = 0; c < 3; ++c)
        rgb[p * 3 + size_t(c)] = shot.data[p * size_t(shot.channels) + size_t(c)];
    const test::Diff d = test::compare(rgb, want_pick.data);
    INFO("screenshot vs macro render: max " << d.max_abs << ", PSNR " << d.psnr);
    CHECK(d.psnr > 40);
  }
  // Plan: the plane map, the references and their crops are shown.
  dt.eval("document.getElementById('plan').click()");
  REQUIRE(
      dt.wait_true("!document.getElementById('plan-pane').hidden && [...document.querySelectorAll("
                   "'#plan-images img')].every(i => i.complete && i.naturalWidth > 0)",
                   30000));
  const Json summary = dt.eval("document.getElementById('plan-summary').textContent");
  CHECK_THAT(summary.get<std::string>(), Catch::Contains("references: train_"));
  CHECK(dt.eval("document.querySelectorAll('#plan-images img').length").get<int>() >= 5);
  CHECK(dt.eval("[...document.querySelectorAll('#plan-images figcaption')].some(f => "
                "f.textContent === 'plane_map.png')")
            .get<bool>());
  // Enhance (the transfer enhancer: no weights), with progress, then render | enhanced.
  dt.eval("document.getElementById('enhance').click()");
  REQUIRE(
      dt.wait_true("!document.getElementById('enhance-pane').hidden && "
                   "document.getElementById('cmp-enhanced').complete && "
                   "document.getElementById('cmp-render').complete && "
                   "document.getElementById('cmp-enhanced').naturalWidth > 0",
                   60000));
  CHECK_THAT(dt.eval("document.getElementById('job').textContent").get<std::string>(),
             Catch::Contains("transfer"));
  const Json result = dt.eval("viewer.state.enhance");
  httplib::Client app("127.0.0.1", server.port);
  auto fetch = [&](const std::string& rel) {
    auto res = app.Get(("/api/results/" + rel).c_str());
    REQUIRE(res);
    REQUIRE(res->status == 200);
    return decode(std::vector<uint8_t>(res->body.begin(), res->body.end()), rel.c_str());
  };
  const gs::Image enhanced = fetch(result["enhanced"].get<std::string>());
  const gs::Image render = fetch(result["render"].get<std::string>());
  CHECK(test::compare(render.data, want_pick.data).max_abs == 0);
  // The comparison on screen: left of the slider (at 50%) the render, right of it the enhanced.
  {
    const gs::Image shot = screenshot(dt, "compare");
    REQUIRE(shot.width == enhanced.width);
    REQUIRE(shot.height == enhanced.height);
    double err_left = 0, err_right = 0, err_right_vs_render = 0;
    const int w = shot.width, h = shot.height;
    for (int i = 0; i < h; ++i)
      for (int j = 0; j < w; ++j)
        for (int c = 0; c < 3; ++c) {
          const double s = shot.at(i, j, c);
          if (j < w / 2 - 2) err_left += std::abs(s - render.at(i, j, c));
          if (j > w / 2 + 2) {
            err_right += std::abs(s - enhanced.at(i, j, c));
            err_right_vs_render += std::abs(s - render.at(i, j, c));
          }
        }
    const double n = double(h) * (w / 2 - 2) * 3;
    INFO("mean abs: left vs render " << err_left / n << ", right vs enhanced " << err_right / n
                                     << ", right vs render " << err_right_vs_render / n);
    CHECK(err_left / n < 0.01);
    CHECK(err_right / n < 0.01);
    CHECK(err_right < err_right_vs_render);
  }
  dt.call("Browser.close");
  chrome.wait_for(10);
  server.child.signal(SIGINT);
  CHECK(server.child.wait_for(20) == 0);
}
