// The bundled real close-up scene (data/scenes/buddha, CC BY 4.0): its split, its trained
// reconstruction and the harness scoring it against the real close-up photos.
#include <catch2/catch.hpp>

#include <filesystem>

#include "attention/runtime/file_io.h"
#include "enhance/bench/bench_harness.h"
#include "enhance/metrics/metrics.h"
#include "enhance/scene_input.h"
#include "gs/cameras/camera.h"
#include "gs/formats/scene_io.h"
#include "gs/image_io.h"
#include "gs/raster/rasterizer.h"
#include "tests/test_support.h"

namespace fs = std::filesystem;
using namespace macro;
using namespace macro::enhance;

TEST_CASE("real scene buddha: split, reconstruction and close-up photos fit together", "[bench]") {
  const std::string dir = test::source_dir() + "/data/scenes/buddha";
  REQUIRE(file_exists(dir + "/split.json"));
  CHECK(file_exists(dir + "/LICENSE.md"));
  CHECK(read_text_file(dir + "/README.md")->find("CC BY 4.0") != std::string::npos);
  auto split = gs::load_closeup_split(dir + "/split.json");
  REQUIRE(split.is_ok());
  CHECK(split->closeup_eval_pairs.size() == 3);
  CHECK(split->training_frames.size() == 3);
  // The reconstruction is the only splat; it was trained on the training frames alone.
  auto ply = find_scene_ply(dir);
  REQUIRE(ply.is_ok());
  CHECK(fs::path(*ply).filename() == "scene.spz");
  auto cloud = gs::load_scene(*ply);
  REQUIRE(cloud.is_ok());
  CHECK(cloud->size() > 21402);  // grew from the SfM points
  CHECK(cloud->sh_degree == 3);
  // It reproduces a training photo closely and a close-up photo far less well.
  auto cams = gs::load_cameras(dir + "/sparse/0");
  REQUIRE(cams.is_ok());
  auto score = [&](const std::string& frame, const std::string& photo_dir) {
    auto cam = cams->find(frame);
    REQUIRE(cam.is_ok());
    auto r = gs::render(*cloud, *cam);
    REQUIRE(r.is_ok());
    auto photo = gs::read_image(photo_dir + "/" + frame);
    REQUIRE(photo.is_ok());
    gs::Image img(r->width, r->height, 3);
    img.data = r->color;
    auto p = psnr(img, *photo);
    REQUIRE(p.is_ok());
    return *p;
  };
  const double train = score(split->training_frames.front(), dir + "/images");
  const double close = score(split->closeup_eval_pairs.front().closeup_frame, dir + "/closeup_gt");
  INFO("training view " << train << " dB, close-up " << close << " dB");
  CHECK(train > 30);
  CHECK(close < train - 8);
  // The harness finds the three pairs and their real ground truth.
  auto items = build_work_list(dir, {"3dgs"}, {{}}, default_method_registry());
  REQUIRE(items.is_ok());
  CHECK(items->size() == 3);
  // Its training log gives the reconstruction's cost to every record.
  const auto cost = training_log_seconds(dir + "/train_log.jsonl");
  REQUIRE(cost.has_value());
  CHECK(*cost > 60);
  const std::string log = *read_text_file(dir + "/train_log.jsonl");
  CHECK(log.find("\"step\": 6999,") != std::string::npos);
  CHECK(log.find("\"train_views\": [\"00018.png\", \"00047.png\", \"00052.png\"]") !=
        std::string::npos);
}
