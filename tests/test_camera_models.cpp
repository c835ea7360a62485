// Camera models beyond pinhole/OPENCV in every format, non-strict loading (one bad entry leaves
// the others usable; CameraLoadOptions::strict keeps the all-or-nothing rule), names without
// extension, the `macro cameras` listing and the distortion guard. Formats and conventions are
// tested in test_cameras.cpp; undistortion in test_undistort.cpp.
#include <catch2/catch.hpp>
#include <cmath>
#include <filesystem>
#include <fstream>

#include "gs/cameras/camera.h"
#include "test_support.h"

using namespace macro;
using namespace macro::gs;
using Catch::Matchers::Contains;

namespace {

void write_text(const std::string& path, const std::string& text) {
  std::filesystem::create_directories(std::filesystem::path(path).parent_path());
  std::ofstream f(path, std::ios::binary);
  f << text;
}

template <typename T>
std::string error_of(const Result<T>& r) {
  return r.is_ok() ? std::string("<no error>") : r.status().message();
}

const char* kIdentityPose = "[[1,0,0,0],[0,1,0,0],[0,0,1,0],[0,0,0,1]]";

std::string json_camera(const std::string& name, double fx, const std::string& extra = "") {
  return R"({"name": ")" + name + R"(", "width": 64, "height": 48, "fx": )" + std::to_string(fx) +
         R"(, "fy": 50, "cx": 32, "cy": 24, "world_to_camera": [[1,0,0,0],[0,1,0,0],[0,0,1,-2],[0,0,0,1]])" +
         extra + "}";
}

}  // namespace

TEST_CASE("camera models: SIMPLE_RADIAL, RADIAL, FULL_OPENCV in COLMAP and the JSON formats",
          "[cameras]") {
  test::TempDir tmp("camera-models");
  write_text(tmp.file("m/cameras.txt"),
             "1 SIMPLE_RADIAL 640 480 500 320 240 -0.1\n"
             "2 RADIAL 640 480 510 321 241 0.1 -0.02\n"
             "3 FULL_OPENCV 640 480 500 505 320 240 0.1 0.2 0.001 0.002 0.3 0.4 0.5 0.6\n");
  write_text(tmp.file("m/images.txt"),
             "1 1 0 0 0 0 0 4 1 a.png\n\n2 1 0 0 0 0 0 4 2 b.png\n\n3 1 0 0 0 0 0 4 3 c.png\n\n");
  auto set = load_cameras(tmp.file("m"));
  REQUIRE(error_of(set) == "<no error>");
  REQUIRE(set->cameras.size() == 3);
  const Camera& a = set->cameras[0];
  CHECK(a.model == CameraModel::kSimpleRadial);
  CHECK(a.fx == 500);
  CHECK(a.fy == 500);
  CHECK(a.cx == 320);
  CHECK(a.distortion == std::vector<double>{-0.1});
  CHECK(a.has_distortion());
  CHECK(a.model_text() == "SIMPLE_RADIAL k=-0.1");
  CHECK(set->cameras[1].model == CameraModel::kRadial);
  CHECK(set->cameras[1].fy == 510);
  CHECK(set->cameras[1].distortion == std::vector<double>{0.1, -0.02});
  CHECK(set->cameras[2].model == CameraModel::kFullOpenCV);
  CHECK(set->cameras[2].distortion ==
        std::vector<double>{0.1, 0.2, 0.001, 0.002, 0.3, 0.4, 0.5, 0.6});

  // The COLMAP writer keeps the models (SIMPLE_RADIAL with fx != fy becomes the same OPENCV;
  // OPENCV with k3 the same FULL_OPENCV) and reads back the same coefficients.
  CameraSet w = *set;
  Camera d = a;
  d.name = "d.png";
  d.fy = 501;
  Camera e = a;
  e.name = "e.png";
  e.model = CameraModel::kOpenCV;
  e.distortion = {0.1, 0.2, 0.01, 0.02, 0.05};
  w.cameras.push_back(d);
  w.cameras.push_back(e);
  REQUIRE(save_colmap_text(w, tmp.file("out")).is_ok());
  std::ifstream txt(tmp.file("out/cameras.txt"));
  const std::string text((std::istreambuf_iterator<char>(txt)), std::istreambuf_iterator<char>());
  CHECK_THAT(text, Contains("SIMPLE_RADIAL 640 480 500 320 240 -0.10000000000000001"));
  CHECK_THAT(text, Contains("RADIAL 640 480 510 321 241"));
  auto back = load_cameras(tmp.file("out"));
  REQUIRE(error_of(back) == "<no error>");
  REQUIRE(back->cameras.size() == 5);
  CHECK(back->cameras[3].model == CameraModel::kOpenCV);
  CHECK(back->cameras[3].distortion == std::vector<double>{-0.1, 0, 0, 0});
  CHECK(back->cameras[4].model == CameraModel::kFullOpenCV);
  CHECK(back->cameras[4].distortion == std::vector<double>{0.1, 0.2, 0.01, 0.02, 0.05, 0, 0, 0});

  // nerfstudio, the split and our JSON accept the same models by name.
  write_text(tmp.file("ns.json"), std::string(R"({"w": 64, "h": 48, "fl_x": 50, "fl_y": 50,
      "camera_model": "SIMPLE_RADIAL", "k1": -0.05, "frames": [
      {"file_path": "a.png", "transform_matrix": )") +
                                      kIdentityPose + R"(},
      {"file_path": "b.png", "camera_model": "FULL_OPENCV", "k1": 0.1, "k2": 0.2, "k3": 0.3,
       "k4": 0.4, "k5": 0.5, "k6": 0.6, "p1": 0.01, "p2": 0.02, "transform_matrix": )" +
                                      kIdentityPose + "}]}");
  auto ns = load_cameras(tmp.file("ns.json"));
  REQUIRE(error_of(ns) == "<no error>");
  CHECK(ns->cameras[0].model == CameraModel::kSimpleRadial);
  CHECK(ns->cameras[0].distortion == std::vector<double>{-0.05});
  CHECK(ns->cameras[1].distortion == std::vector<double>{0.1, 0.2, 0.01, 0.02, 0.3, 0.4, 0.5, 0.6});
  write_text(tmp.file("split.json"),
             std::string(R"({"intrinsics": {"w": 64, "h": 48, "fl_x": 50, "fl_y": 50, "cx": 32,
      "cy": 24, "camera_model": "RADIAL", "k1": 0.01, "k2": 0.002},
      "closeup_poses": {"x.png": )") +
                 kIdentityPose + "}}");
  auto split = load_closeup_split(tmp.file("split.json"));
  REQUIRE(error_of(split) == "<no error>");
  CHECK(split->closeups.cameras[0].model == CameraModel::kRadial);
  CHECK(split->closeups.cameras[0].distortion == std::vector<double>{0.01, 0.002});
  write_text(
      tmp.file("ours.json"),
      "[" + json_camera("a.png", 50, R"(, "model": "RADIAL", "distortion": [0.1, 0.2])") + "]");
  auto ours = load_cameras(tmp.file("ours.json"));
  REQUIRE(error_of(ours) == "<no error>");
  CHECK(ours->cameras[0].model == CameraModel::kRadial);
  // A wrong coefficient count is named.
  write_text(
      tmp.file("bad.json"),
      "[" + json_camera("a.png", 50, R"(, "model": "RADIAL", "distortion": [0.1, 0.2, 3])") + "]");
  CHECK_THAT(error_of(load_cameras(tmp.file("bad.json"))),
             Contains("camera 'a.png': RADIAL takes at most 2 distortion parameters, found 3"));
}

TEST_CASE("non-strict loading: a bad entry is left out and named, strict refuses the file",
          "[cameras]") {
  test::TempDir tmp("camera-entries");
  CameraLoadOptions strict;
  strict.strict = true;
  // Our JSON: entry 1 has fx = 0, entry 2 misses a field.
  write_text(tmp.file("ours.json"), "[" + json_camera("a.png", 50) + ", " +
                                        json_camera("bad.png", 0) + R"(, {"name": "c.png"}, )" +
                                        json_camera("d.png", 40) + "]");
  auto set = load_cameras(tmp.file("ours.json"));
  REQUIRE(error_of(set) == "<no error>");
  REQUIRE(set->cameras.size() == 2);
  CHECK(set->cameras[1].name == "d.png");
  REQUIRE(set->rejected.size() == 2);
  CHECK(set->rejected[0].index == 1);
  CHECK(set->rejected[0].name == "bad.png");
  CHECK_THAT(set->rejected[0].message, Contains("ours.json: [1]: camera 'bad.png': fx = 0"));
  CHECK(set->rejected[1].index == 2);
  CHECK_THAT(set->rejected[1].message, Contains("[2] 'c.png': missing field 'width'"));
  CHECK(set->find("a.png").is_ok());
  const std::string why = error_of(set->find("bad.png"));
  CHECK_THAT(why, Contains("'bad.png' (entry 1) was left out as invalid"));
  CHECK_THAT(why, Contains("fx = 0"));
  CHECK_THAT(error_of(load_cameras(tmp.file("ours.json"), strict)),
             Contains("[1]: camera 'bad.png': fx = 0"));

  // COLMAP text: an unsupported model on camera 2 rejects only its image; a bad quaternion and a
  // malformed image line reject theirs.
  write_text(tmp.file("m/cameras.txt"),
             "1 PINHOLE 64 48 50 50 32 24\n2 FOV 64 48 50 50 32 24 0.1\n");
  write_text(tmp.file("m/images.txt"),
             "1 1 0 0 0 0 0 4 1 a.png\n\n2 1 0 0 0 0 0 4 2 b.png\n\n"
             "3 2 0 0 0 0 0 4 1 c.png\n\n4 1 0 0 x 0 0 4 1 d.png\n1 2 3\n"
             "5 1 0 0 0 0 0 4 1 e.png\n\n");
  auto colmap = load_cameras(tmp.file("m"));
  REQUIRE(error_of(colmap) == "<no error>");
  REQUIRE(colmap->cameras.size() == 2);
  CHECK(colmap->cameras[1].name == "e.png");
  REQUIRE(colmap->rejected.size() == 3);
  CHECK(colmap->rejected[0].index == 1);
  CHECK(colmap->rejected[0].name == "b.png");
  CHECK_THAT(colmap->rejected[0].message,
             Contains("its camera 2 is invalid: " + tmp.file("m/cameras.txt") +
                      " line 2: camera 2: camera model FOV is not supported"));
  CHECK(colmap->rejected[1].index == 2);
  CHECK_THAT(colmap->rejected[1].message, Contains("quaternion"));
  CHECK(colmap->rejected[2].index == 3);
  CHECK(colmap->rejected[2].name == "d.png");
  CHECK_THAT(colmap->rejected[2].message, Contains("images.txt line 7: QZ: expected a number"));
  CHECK_THAT(error_of(load_cameras(tmp.file("m"), strict)),
             Contains("camera model FOV is not supported"));

  // nerfstudio: a frame without transform_matrix; the split: a bad pose.
  write_text(tmp.file("ns.json"), std::string(R"({"w": 64, "h": 48, "fl_x": 50, "frames": [
      {"file_path": "images/a.png", "transform_matrix": )") +
                                      kIdentityPose + R"(},
      {"file_path": "images/b.png"}]})");
  auto ns = load_cameras(tmp.file("ns.json"));
  REQUIRE(error_of(ns) == "<no error>");
  REQUIRE(ns->rejected.size() == 1);
  CHECK(ns->rejected[0].index == 1);
  CHECK(ns->rejected[0].name == "b.png");
  CHECK_THAT(ns->rejected[0].message, Contains("frames[1] 'images/b.png': missing field"));
  write_text(tmp.file("split.json"),
             std::string(R"({"intrinsics": {"w": 64, "h": 48, "fl_x": 50, "fl_y": 50, "cx": 32,
      "cy": 24}, "closeup_poses": {"x.png": )") +
                 kIdentityPose + R"(, "y.png": [[1,0,0]]}})");
  auto split = load_cameras(tmp.file("split.json"));
  REQUIRE(error_of(split) == "<no error>");
  REQUIRE(split->rejected.size() == 1);
  CHECK(split->rejected[0].name == "y.png");
  CHECK_THAT(error_of(load_cameras(tmp.file("split.json"), strict)), Contains("'y.png'"));

  // No valid entry at all: the first reason, and how many more.
  write_text(tmp.file("none.json"),
             "[" + json_camera("a.png", 0) + ", " + json_camera("b.png", -1) + "]");
  const std::string none = error_of(load_cameras(tmp.file("none.json")));
  CHECK_THAT(none, Contains("camera 'a.png': fx = 0"));
  CHECK_THAT(none, Contains("and 1 more invalid entries"));
}

TEST_CASE("CameraSet::find: a name without its extension, unless ambiguous", "[cameras]") {
  CameraSet set;
  set.source = "cams.json";
  for (const char* n :
       {"frame_00001.png", "frame_00002.png", "frame_00002.jpg", "sub/frame_3.png"}) {
    Camera c;
    c.name = n;
    set.cameras.push_back(c);
  }
  CHECK(set.index_of("frame_00001") == 0);
  CHECK(set.index_of("frame_3") == 3);
  CHECK(set.index_of("images/frame_00001") == 0);
  CHECK(set.index_of("frame_0000") == -1);
  const std::string amb = error_of(set.find("frame_00002"));
  CHECK_THAT(amb, Contains("ambiguous"));
  CHECK_THAT(amb, Contains("'frame_00002.png', 'frame_00002.jpg'"));
  CHECK(set.index_of("frame_00002.jpg") == 2);
}

TEST_CASE("describe_cameras lists name, size, model and centre, the distortion guard",
          "[cameras]") {
  CameraSet set;
  set.source = "scene/sparse/0";
  Camera a;
  a.name = "a.png";
  a.width = 640;
  a.height = 480;
  a.fx = a.fy = 500;
  a.t = Eigen::Vector3d(1, 2, 3);  // centre -t (R = I)
  Camera b = a;
  b.name = "b.png";
  b.model = CameraModel::kOpenCV;
  b.distortion = {0.5, 0, 0, 0};
  set.cameras = {a, b};
  set.rejected.push_back({2, "c.png", "cameras.txt line 3: bad"});
  const std::string text = describe_cameras(set, CameraFormat::kColmapText);
  CHECK_THAT(text, Contains("scene/sparse/0: 2 cameras (COLMAP text), 1 invalid entry left out"));
  CHECK_THAT(text, Contains("a.png  640x480      PINHOLE"));
  CHECK_THAT(text, Contains("-1 -2 -3"));
  CHECK_THAT(text, Contains("OPENCV k1=0.5 k2=0 p1=0 p2=0"));
  CHECK_THAT(text, Contains("entry 2 'c.png': cameras.txt line 3: bad"));

  CHECK_FALSE(a.has_distortion());
  CHECK(refuse_distorted(a, "macro render", "fix").is_ok());
  Camera zero = b;
  zero.distortion = {0, 0, 0, 0};
  CHECK_FALSE(zero.has_distortion());  // OPENCV with zero coefficients is a pinhole
  const Status s = refuse_distorted(b, "macro render", "run macro undistort");
  REQUIRE_FALSE(s.is_ok());
  CHECK_THAT(s.message(), Contains("camera 'b.png' is OPENCV k1=0.5"));
  CHECK_THAT(s.message(), Contains("macro render draws pinhole images"));
  CHECK_THAT(s.message(), Contains("run macro undistort"));
}
