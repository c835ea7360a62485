// Cameras (gs/cameras/camera.h): pose conventions with known answers, one reference rig written by hand in
// every input format, nerfstudio applied_transform round trips, the DL3DV-Closeup split, writers,
// resized/validate/find, and bad input with message checks.
#include <Eigen/Geometry>
#include <catch2/catch.hpp>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <functional>
#include <random>

#include "gs/cameras/camera.h"
#include "test_support.h"

using namespace macro;
using namespace macro::gs;

namespace {

void write_text(const std::string& path, const std::string& text) {
  std::filesystem::create_directories(std::filesystem::path(path).parent_path());
  std::ofstream f(path, std::ios::binary);
  f << text;
}

void write_bytes(const std::string& path, const std::vector<uint8_t>& bytes) {
  std::filesystem::create_directories(std::filesystem::path(path).parent_path());
  std::ofstream f(path, std::ios::binary);
  f.write(reinterpret_cast<const char*>(bytes.data()), std::streamsize(bytes.size()));
}

// Little-endian byte builder for COLMAP binary fixtures.
struct Bytes {
  std::vector<uint8_t> b;
  template <typename T>
  Bytes& put(T v) {
    uint8_t tmp[sizeof(T)];
    std::memcpy(tmp, &v, sizeof(T));
    b.insert(b.end(), tmp, tmp + sizeof(T));
    return *this;
  }
  Bytes& str(const std::string& s) {
    b.insert(b.end(), s.begin(), s.end());
    b.push_back(0);
    return *this;
  }
};

// The message of a failed result, or a marker that it did not fail.
template <typename T>
std::string error_of(const Result<T>& r) {
  return r.is_ok() ? std::string("<no error>") : r.status().message();
}
std::string error_of(const Status& s) {
  return s.is_ok() ? std::string("<no error>") : s.message();
}

using Catch::Matchers::Contains;

// ---- The reference rig: two cameras, same intrinsics ------------------------------------------
// "front.png": centre (0,0,-4), looking down +z at the origin: R = I, t = (0,0,4).
// "side.png":  centre (4,0,0), looking down -x: rows of R are the camera axes in world
//              coordinates, x = (0,0,-1), y = (0,-1,0), z = (-1,0,0); t = -R C = (0,0,4).
//              COLMAP quaternion: 180 degrees about (1,0,-1)/sqrt2 -> (0, 1/sqrt2, 0, -1/sqrt2).
// Intrinsics: 640x480, fx 500, fy 510, cx 320.5, cy 240.25.
constexpr double kFx = 500, kFy = 510, kCx = 320.5, kCy = 240.25;
const Eigen::Matrix3d kRside = (Eigen::Matrix3d() << 0, 0, -1, 0, -1, 0, -1, 0, 0).finished();
const Eigen::Vector3d kT(0, 0, 4);

// Hand-computed projections. front: X = (0.3,-0.2,0.5) -> x_c = (0.3,-0.2,4.5);
// side: X = (0.5,0.3,-0.2) -> x_c = (0.2,-0.3,3.5).
const Eigen::Vector3d kXfront(0.3, -0.2, 0.5), kXside(0.5, 0.3, -0.2);
const Eigen::Vector2d kUVfront(kFx * 0.3 / 4.5 + kCx, kFy * -0.2 / 4.5 + kCy);
const Eigen::Vector2d kUVside(kFx * 0.2 / 3.5 + kCx, kFy * -0.3 / 3.5 + kCy);

const char* kIntrinsicsJson =
    R"("w": 640, "h": 480, "fl_x": 500, "fl_y": 510, "cx": 320.5, "cy": 240.25)";
// OpenGL camera-to-world of the two cameras: [R^T | C] with columns 1 and 2 negated.
const char* kFrontGL = "[[1,0,0,0],[0,-1,0,0],[0,0,-1,-4],[0,0,0,1]]";
const char* kSideGL = "[[0,0,1,4],[0,1,0,0],[-1,0,0,0],[0,0,0,1]]";

void write_rig_json(const std::string& path) {
  write_text(path, R"([
 {"name": "front.png", "width": 640, "height": 480, "fx": 500, "fy": 510, "cx": 320.5, "cy": 240.25,
  "world_to_camera": [[1,0,0,0],[0,1,0,0],[0,0,1,4],[0,0,0,1]]},
 {"name": "side.png", "width": 640, "height": 480, "fx": 500, "fy": 510, "cx": 320.5, "cy": 240.25,
  "world_to_camera": [[0,0,-1,0],[0,-1,0,0],[-1,0,0,4],[0,0,0,1]]}
])");
}

void write_rig_colmap_text(const std::string& dir) {
  write_text(dir + "/cameras.txt",
             "# Camera list with one line of data per camera:\n"
             "#   CAMERA_ID, MODEL, WIDTH, HEIGHT, PARAMS[]\n"
             "# Number of cameras: 1\n"
             "1 PINHOLE 640 480 500 510 320.5 240.25\n");
  write_text(dir + "/images.txt",
             "# Image list with two lines of data per image:\n"
             "#   IMAGE_ID, QW, QX, QY, QZ, TX, TY, TZ, CAMERA_ID, NAME\n"
             "#   POINTS2D[] as (X, Y, POINT3D_ID)\n"
             "7 0 0.70710678118654752 0 -0.70710678118654752 0 0 4 1 side.png\n"
             "100.5 200.25 -1 12 13 5\n"
             "3 1 0 0 0 0 0 4 1 front.png\n"
             "\n");
}

Bytes rig_cameras_bin(int32_t model_id = 1, uint64_t count = 1) {
  Bytes c;
  c.put<uint64_t>(count).put<uint32_t>(1).put<int32_t>(model_id).put<uint64_t>(640).put<uint64_t>(
      480);
  for (double v : {kFx, kFy, kCx, kCy}) c.put<double>(v);
  return c;
}

Bytes rig_images_bin(uint32_t camera_id = 1, uint64_t points_of_side = 2) {
  Bytes im;
  im.put<uint64_t>(2);
  // side.png, with 2D points to skip
  im.put<uint32_t>(7);
  for (double v : {0.0, std::sqrt(0.5), 0.0, -std::sqrt(0.5), 0.0, 0.0, 4.0}) im.put<double>(v);
  im.put<uint32_t>(camera_id).str("side.png").put<uint64_t>(points_of_side);
  for (uint64_t p = 0; p < 2; ++p) im.put<double>(10.0 * p).put<double>(20.0).put<uint64_t>(p + 1);
  // front.png, no 2D points
  im.put<uint32_t>(3);
  for (double v : {1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 4.0}) im.put<double>(v);
  im.put<uint32_t>(camera_id).str("front.png").put<uint64_t>(0);
  return im;
}

void write_rig_colmap_binary(const std::string& dir) {
  write_bytes(dir + "/cameras.bin", rig_cameras_bin().b);
  write_bytes(dir + "/images.bin", rig_images_bin().b);
}

void write_rig_nerfstudio(const std::string& path) {
  write_text(path, std::string("{") + kIntrinsicsJson + R"(, "camera_model": "PINHOLE", "frames": [
  {"file_path": "images/front.png", "transform_matrix": )" +
                       kFrontGL + R"(},
  {"file_path": "images/side.png", "transform_matrix": )" +
                       kSideGL + R"(}]})");
}

void write_rig_split(const std::string& path) {
  write_text(path, std::string(R"({"scene": "abc", "data_factor": 4, "intrinsics": {)") +
                       kIntrinsicsJson + R"(, "camera_model": "PINHOLE"},
  "training_frames": ["t1.png"], "closeup_eval_pairs": [],
  "closeup_poses": {"front.png": )" +
                       kFrontGL + R"(, "side.png": )" + kSideGL + "}}");
}

void check_rig(const CameraSet& set) {
  REQUIRE(set.cameras.size() == 2);
  for (const char* name : {"front.png", "side.png"}) {
    INFO(set.source << " " << name);
    auto cam = set.find(name);
    REQUIRE(cam.is_ok());
    const bool side = std::string(name) == "side.png";
    const Eigen::Matrix3d R_expected = side ? kRside : Eigen::Matrix3d::Identity();
    CHECK((cam->R - R_expected).cwiseAbs().maxCoeff() < 1e-12);
    CHECK((cam->t - kT).cwiseAbs().maxCoeff() < 1e-12);
    CHECK(cam->width == 640);
    CHECK(cam->height == 480);
    CHECK(cam->fx == kFx);
    CHECK(cam->fy == kFy);
    CHECK(cam->cx == kCx);
    CHECK(cam->cy == kCy);
    const Eigen::Vector3d p = cam->project(side ? kXside : kXfront);
    const Eigen::Vector2d uv = side ? kUVside : kUVfront;
    CHECK(std::abs(p.x() - uv.x()) < 1e-9);
    CHECK(std::abs(p.y() - uv.y()) < 1e-9);
    CHECK(p.z() == Approx(side ? 3.5 : 4.5).margin(1e-12));
  }
}

Eigen::Matrix3d random_rotation(std::mt19937& rng) {
  std::normal_distribution<double> n;
  Eigen::Quaterniond q(n(rng), n(rng), n(rng), n(rng));
  q.normalize();
  return q.toRotationMatrix();
}

std::string matrix_json(const Eigen::Matrix4d& m, int rows = 4) {
  std::string s = "[";
  char buf[64];
  for (int r = 0; r < rows; ++r) {
    s += r ? ",[" : "[";
    for (int c = 0; c < 4; ++c) {
      std::snprintf(buf, sizeof buf, "%s%.17g", c ? "," : "", m(r, c));
      s += buf;
    }
    s += "]";
  }
  return s + "]";
}

Camera make_camera(const std::string& name, const Eigen::Matrix3d& R, const Eigen::Vector3d& t) {
  Camera c;
  c.name = name;
  c.width = 960;
  c.height = 540;
  c.fx = 420.49485042336295;
  c.fy = 420.15307214892454;
  c.cx = 480.0;
  c.cy = 270.0;
  c.R = R;
  c.t = t;
  return c;
}

}  // namespace

// ---- Conventions
// ----------------------------------------------------------------------------------

TEST_CASE("COLMAP quaternion to rotation, known answers and round trip", "[cameras]") {
  CHECK((rotation_from_quaternion_wxyz(1, 0, 0, 0) - Eigen::Matrix3d::Identity()).norm() < 1e-15);
  // 90 degrees about +z maps x -> y.
  const double h = std::sqrt(0.5);
  Eigen::Matrix3d rz;
  rz << 0, -1, 0, 1, 0, 0, 0, 0, 1;
  CHECK((rotation_from_quaternion_wxyz(h, 0, 0, h) - rz).norm() < 1e-15);
  // 180 degrees about x.
  CHECK((rotation_from_quaternion_wxyz(0, 1, 0, 0) -
         Eigen::Vector3d(1, -1, -1).asDiagonal().toDenseMatrix())
            .norm() < 1e-15);
  CHECK((rotation_from_quaternion_wxyz(0, h, 0, -h) - kRside).norm() < 1e-15);
  // -q is the same rotation; the inverse gives qw >= 0.
  CHECK((rotation_from_quaternion_wxyz(-h, 0, 0, -h) - rz).norm() < 1e-15);
  std::mt19937 rng(5);
  for (int i = 0; i < 100; ++i) {
    const Eigen::Matrix3d R = random_rotation(rng);
    const Eigen::Vector4d q = quaternion_wxyz_from_rotation(R);
    CHECK(q[0] >= 0);
    CHECK(std::abs(q.norm() - 1) < 1e-14);
    CHECK((rotation_from_quaternion_wxyz(q[0], q[1], q[2], q[3]) - R).norm() < 1e-13);
  }
}

TEST_CASE("OpenGL camera-to-world to OpenCV world-to-camera", "[cameras]") {
  // An OpenGL camera at (0,0,5) with identity rotation looks down -z, at the origin.
  Eigen::Matrix4d gl = Eigen::Matrix4d::Identity();
  gl(2, 3) = 5;
  const Eigen::Matrix4d w2c = opencv_w2c_from_opengl_c2w(gl);
  Eigen::Matrix4d expected;
  expected << 1, 0, 0, 0, 0, -1, 0, 0, 0, 0, -1, 5, 0, 0, 0, 1;
  CHECK((w2c - expected).norm() < 1e-15);
  // The origin is 5 in front of the camera, and world +y (up) is image up (negative v).
  Camera c;
  c.set_world_to_camera(w2c);
  CHECK((c.R * Eigen::Vector3d(0, 0, 0) + c.t - Eigen::Vector3d(0, 0, 5)).norm() < 1e-15);
  CHECK((c.R * Eigen::Vector3d(0, 1, 0)).y() < 0);
  CHECK((c.center() - Eigen::Vector3d(0, 0, 5)).norm() < 1e-15);
  // The rig's side camera, and the inverse map.
  Eigen::Matrix4d side_gl;
  side_gl << 0, 0, 1, 4, 0, 1, 0, 0, -1, 0, 0, 0, 0, 0, 0, 1;
  const Eigen::Matrix4d side = opencv_w2c_from_opengl_c2w(side_gl);
  CHECK((side.topLeftCorner<3, 3>() - kRside).norm() < 1e-15);
  CHECK((side.topRightCorner<3, 1>() - kT).norm() < 1e-15);
  CHECK((opengl_c2w_from_opencv_w2c(side) - side_gl).norm() < 1e-15);
  std::mt19937 rng(9);
  for (int i = 0; i < 20; ++i) {
    Eigen::Matrix4d m = Eigen::Matrix4d::Identity();
    m.topLeftCorner<3, 3>() = random_rotation(rng);
    m.topRightCorner<3, 1>() = Eigen::Vector3d::Random() * 3;
    CHECK((opencv_w2c_from_opengl_c2w(opengl_c2w_from_opencv_w2c(m)) - m).norm() < 1e-13);
    CHECK((invert_rigid(m) * m - Eigen::Matrix4d::Identity()).norm() < 1e-13);
  }
}

// ---- One rig, every format --------------------------------------------------------------------

TEST_CASE("the same rig in every format gives the same R, t and pixels", "[cameras]") {
  test::TempDir tmp("cameras-rig");
  write_rig_json(tmp.file("rig.json"));
  write_rig_colmap_text(tmp.file("text/sparse/0"));
  write_rig_colmap_binary(tmp.file("bin/sparse/0"));
  write_rig_nerfstudio(tmp.file("ns/transforms.json"));
  write_rig_split(tmp.file("split.json"));

  struct Case {
    std::string path;
    CameraFormat format;
  };
  for (const Case& c : {Case{tmp.file("rig.json"), CameraFormat::kJson},
                        Case{tmp.file("text"), CameraFormat::kColmapText},
                        Case{tmp.file("text/sparse/0/images.txt"), CameraFormat::kColmapText},
                        Case{tmp.file("bin"), CameraFormat::kColmapBinary},
                        Case{tmp.file("bin/sparse/0"), CameraFormat::kColmapBinary},
                        Case{tmp.file("ns"), CameraFormat::kNerfstudio},
                        Case{tmp.file("ns/transforms.json"), CameraFormat::kNerfstudio},
                        Case{tmp.file("split.json"), CameraFormat::kCloseupSplit}}) {
    INFO(c.path);
    CameraFormat detected{};
    auto set = load_cameras(c.path, {}, &detected);
    REQUIRE(error_of(set) == "<no error>");
    CHECK(detected == c.format);
    check_rig(*set);
  }
  // COLMAP orders by name whatever the image ids.
  auto text = load_cameras(tmp.file("text"));
  REQUIRE(text.is_ok());
  CHECK(text->cameras[0].name == "front.png");
  CHECK(text->cameras[1].name == "side.png");
}

TEST_CASE("golden cameras.json files load as our JSON", "[cameras]") {
  const std::string dir = test::golden_dir() + "/raster";
  REQUIRE(std::filesystem::is_directory(dir));
  CameraFormat format{};
  auto garden = load_cameras(dir + "/garden-points-sh1/cameras.json", {}, &format);
  REQUIRE(error_of(garden) == "<no error>");
  CHECK(format == CameraFormat::kJson);
  REQUIRE(garden->cameras.size() == 3);
  auto cam0 = garden->find("cam0");
  REQUIRE(cam0.is_ok());
  CHECK(cam0->width == 324);
  CHECK(cam0->height == 210);
  CHECK(cam0->fx == 240.30616760253906);
  CHECK(cam0->cy == 105.03125);
  CHECK(cam0->R(1, 2) == -0.975534975528717);
  CHECK(cam0->t(2) == 1.195468783378601);
  CHECK(garden->find("closeup0").is_ok());
  // The folder form finds cameras.json.
  auto random = load_cameras(dir + "/random-sh3", {}, &format);
  REQUIRE(error_of(random) == "<no error>");
  CHECK(format == CameraFormat::kJson);
  CHECK(random->cameras.size() == 3);
}

// ---- nerfstudio -------------------------------------------------------------------------------

TEST_CASE("nerfstudio applied_transform: synthetic round trip to the COLMAP frame", "[cameras]") {
  test::TempDir tmp("cameras-ns");
  std::mt19937 rng(17);
  std::vector<Camera> truth;
  for (int i = 0; i < 6; ++i) {
    truth.push_back(make_camera("frame_0000" + std::to_string(i) + ".png", random_rotation(rng),
                                Eigen::Vector3d::Random() * 2));
  }
  // ns-process-data today: rows (0,2,1), row 2 negated, 3x4. Older tools: rows (1,0,2). A general
  // similarity with scale 2.5 and a translation, as 4x4.
  Eigen::Matrix4d current = Eigen::Matrix4d::Zero(), older = Eigen::Matrix4d::Zero();
  current(0, 0) = 1, current(1, 2) = 1, current(2, 1) = -1, current(3, 3) = 1;
  older(0, 1) = 1, older(1, 0) = 1, older(2, 2) = -1, older(3, 3) = 1;
  Eigen::Matrix4d similarity = Eigen::Matrix4d::Identity();
  similarity.topLeftCorner<3, 3>() = 2.5 * random_rotation(rng);
  similarity.topRightCorner<3, 1>() = Eigen::Vector3d(0.5, -1, 2);

  const Eigen::Vector3d X(0.1, 0.2, 0.3);  // a COLMAP-world point
  for (const auto& [A, rows] :
       {std::pair{current, 3}, std::pair{older, 3}, std::pair{similarity, 4}}) {
    const double s = std::cbrt(A.topLeftCorner<3, 3>().determinant());
    const Eigen::Matrix3d Q = A.topLeftCorner<3, 3>() / s;
    std::string frames;
    for (const Camera& c : truth) {
      // What ns-process-data writes: the COLMAP camera, OpenGL axes, moved by A.
      Eigen::Matrix4d gl = opengl_c2w_from_opencv_w2c(c.world_to_camera());
      Eigen::Matrix4d ns = Eigen::Matrix4d::Identity();
      ns.topLeftCorner<3, 3>() = Q * gl.topLeftCorner<3, 3>();
      ns.topRightCorner<3, 1>() = (A * gl.col(3)).head<3>();
      frames += std::string(frames.empty() ? "" : ",") + R"({"file_path": "images/)" + c.name +
                R"(", "transform_matrix": )" + matrix_json(ns) + "}";
    }
    const std::string path = tmp.file("transforms.json");
    write_text(path, R"({"w": 960, "h": 540, "fl_x": 420.49485042336295, "fl_y": 420.15307214892454,
      "cx": 480.0, "cy": 270.0, "applied_transform": )" +
                         matrix_json(A, rows) + R"(, "frames": [)" + frames + "]}");
    auto set = load_cameras(path);
    REQUIRE(error_of(set) == "<no error>");
    REQUIRE(set->cameras.size() == truth.size());
    for (size_t i = 0; i < truth.size(); ++i) {
      const Camera& got = set->cameras[i];
      CHECK(got.name == truth[i].name);
      CHECK(got.file_path == "images/" + truth[i].name);
      CHECK((got.R - truth[i].R).cwiseAbs().maxCoeff() < 1e-12);
      CHECK((got.t - truth[i].t).cwiseAbs().maxCoeff() < 1e-12);
      CHECK((got.project(X) - truth[i].project(X)).norm() < 1e-9);
    }
    // Kept in the transforms.json frame on request: the centre is A applied to the COLMAP centre.
    CameraLoadOptions keep;
    keep.undo_applied_transform = false;
    auto raw = load_cameras(path, keep);
    REQUIRE(raw.is_ok());
    const Eigen::Vector3d c_ns = (A * truth[0].center().homogeneous()).head<3>();
    CHECK((raw->cameras[0].center() - c_ns).norm() < 1e-12);
    CHECK((raw->cameras[0].center() - truth[0].center()).norm() > 1e-3);
  }
}

TEST_CASE("nerfstudio intrinsics: global, per frame, distortion, Blender camera_angle_x",
          "[cameras]") {
  test::TempDir tmp("cameras-nsi");
  const std::string gl = kFrontGL;
  write_text(tmp.file("a/transforms.json"), R"({
    "w": 640, "h": 480, "fl_x": 500, "fl_y": 510, "cx": 320.5, "cy": 240.25,
    "camera_model": "OPENCV", "k1": 0.1, "k2": -0.02, "p1": 0.003, "p2": -0.004,
    "frames": [
      {"file_path": "./images/a.png", "transform_matrix": )" +
                                                gl + R"(},
      {"file_path": "./images/b.png", "transform_matrix": )" +
                                                gl + R"(,
       "fl_x": 250, "fl_y": 255, "cx": 160.25, "cy": 120.125, "w": 320, "h": 240, "k1": 0.5},
      {"file_path": "./fish/c.png", "transform_matrix": )" +
                                                gl + R"(,
       "camera_model": "OPENCV_FISHEYE", "k1": 1, "k2": 2, "k3": 3, "k4": 4}]})");
  auto set = load_cameras(tmp.file("a"));
  REQUIRE(error_of(set) == "<no error>");
  const Camera& a = set->cameras[0];
  CHECK(a.model == CameraModel::kOpenCV);
  CHECK(a.distortion == std::vector<double>{0.1, -0.02, 0.003, -0.004});
  CHECK(a.fx == 500);
  const Camera& b = set->cameras[1];
  CHECK(b.width == 320);
  CHECK(b.height == 240);
  CHECK(b.fx == 250);
  CHECK(b.fy == 255);
  CHECK(b.cx == 160.25);
  CHECK(b.cy == 120.125);
  CHECK(b.distortion == std::vector<double>{0.5, -0.02, 0.003, -0.004});
  const Camera& c = set->cameras[2];
  CHECK(c.model == CameraModel::kOpenCVFisheye);
  CHECK(c.distortion == std::vector<double>{1, 2, 3, 4});
  // Names: the file name; the stored path (with or without "./") finds the same camera.
  CHECK(a.name == "a.png");
  CHECK(set->find("./images/b.png")->name == "b.png");
  CHECK(set->find("images/b.png")->name == "b.png");
  CHECK(set->find("fish/c.png")->name == "c.png");

  // Blender: camera_angle_x only, no w/h: the size comes from the PNG header, the path has no
  // extension, fy = fx, principal point at the centre.
  const std::vector<uint8_t> png = {0x89, 'P', 'N', 'G', '\r', '\n', 0x1a, '\n', 0, 0, 0, 13,
                                    'I',  'H', 'D', 'R', 0,    0,    3,    32,   0, 0, 2, 88};
  write_bytes(tmp.file("blender/train/r_0.png"), png);  // IHDR 800 x 600, big-endian
  write_text(tmp.file("blender/transforms_train.json"),
             R"({"camera_angle_x": 0.6911112070083618, "frames": [
                 {"file_path": "./train/r_0", "rotation": 0.0, "transform_matrix": )" +
                 gl + "}]}");
  auto blender = load_cameras(tmp.file("blender/transforms_train.json"));
  REQUIRE(error_of(blender) == "<no error>");
  const Camera& r0 = blender->cameras[0];
  CHECK(r0.name == "r_0");
  CHECK(r0.width == 800);
  CHECK(r0.height == 600);
  CHECK(r0.fx == Approx(0.5 * 800 / std::tan(0.5 * 0.6911112070083618)).epsilon(1e-14));
  CHECK(r0.fy == r0.fx);
  CHECK(r0.cx == 400);
  CHECK(r0.cy == 300);
  CHECK(r0.model == CameraModel::kPinhole);
}

// ---- DL3DV-Closeup split ----------------------------------------------------------------------

TEST_CASE("DL3DV-Closeup split: fields and close-up cameras", "[cameras]") {
  test::TempDir tmp("cameras-split");
  write_text(tmp.file("split.json"), std::string(R"({
    "scene": "093ef327b4e4f9d4", "data_factor": 4,
    "intrinsics": {"w": 960, "h": 540, "fl_x": 420.5, "fl_y": 420.25, "cx": 480.0, "cy": 270.0,
                   "k1": -0.002, "k2": 0.0004, "p1": -0.00025, "p2": 0.00093, "camera_model": "OPENCV"},
    "num_training_frames": 2, "num_closeup_pairs": 2,
    "training_frames": ["frame_00158.png", "frame_00101.png"],
    "closeup_eval_pairs": [
      {"training_frame": "frame_00158.png", "closeup_frame": "frame_00351.png",
       "depth_ratio": 2.1497, "iou": 0.8105, "angle_deg": 12.6, "pair_score": 2.3693},
      {"training_frame": "frame_00101.png", "closeup_frame": "frame_00319.png",
       "depth_ratio": 2.3806, "iou": 0.726, "angle_deg": 47.9, "pair_score": 2.0286}],
    "closeup_poses": {"frame_00351.png": )") +
                                         kSideGL + R"(, "frame_00319.png": )" + kFrontGL + "}}");
  auto split = load_closeup_split(tmp.file("split.json"));
  REQUIRE(error_of(split) == "<no error>");
  CHECK(split->scene == "093ef327b4e4f9d4");
  CHECK(split->data_factor == 4);
  CHECK(split->training_frames == std::vector<std::string>{"frame_00158.png", "frame_00101.png"});
  CHECK_FALSE(split->has_closeup_frames);
  REQUIRE(split->closeup_eval_pairs.size() == 2);
  CHECK(split->closeup_eval_pairs[1].training_frame == "frame_00101.png");
  CHECK(split->closeup_eval_pairs[1].closeup_frame == "frame_00319.png");
  CHECK(split->closeup_eval_pairs[1].depth_ratio == 2.3806);
  CHECK(split->closeup_eval_pairs[1].iou == 0.726);
  CHECK(split->closeup_eval_pairs[1].angle_deg == 47.9);
  CHECK(split->closeup_eval_pairs[1].pair_score == 2.0286);
  // File order, named by key, GL -> CV.
  const auto& cams = split->closeups.cameras;
  REQUIRE(cams.size() == 2);
  CHECK(cams[0].name == "frame_00351.png");
  CHECK((cams[0].R - kRside).norm() < 1e-15);
  CHECK((cams[0].t - kT).norm() < 1e-15);
  CHECK((cams[1].R - Eigen::Matrix3d::Identity()).norm() < 1e-15);
  CHECK(cams[1].model == CameraModel::kOpenCV);
  CHECK(cams[1].distortion == std::vector<double>{-0.002, 0.0004, -0.00025, 0.00093});
  CHECK(cams[1].fx == 420.5);
  CHECK(cams[1].fy == 420.25);
  CHECK(cams[1].width == 960);

  // MobileClose spelling: train_frames, closeup_frames.
  write_text(tmp.file("mobile.json"), std::string(R"({"intrinsics": {"w": 1071, "h": 1428,
      "fl_x": 1000, "fl_y": 1000, "cx": 535.5, "cy": 714},
    "train_frames": ["a.jpg"], "closeup_frames": ["z.jpg"], "closeup_poses": {"z.jpg": )") +
                                          kFrontGL + "}}");
  auto mobile = load_closeup_split(tmp.file("mobile.json"));
  REQUIRE(error_of(mobile) == "<no error>");
  CHECK(mobile->training_frames == std::vector<std::string>{"a.jpg"});
  CHECK(mobile->has_closeup_frames);
  CHECK(mobile->closeup_frames == std::vector<std::string>{"z.jpg"});
  CHECK(mobile->data_factor == 0);
  CHECK(mobile->closeups.cameras[0].model == CameraModel::kPinhole);
}

// ---- Writers ----------------------------------------------------------------------------------

TEST_CASE("writers round-trip: our JSON and COLMAP text", "[cameras]") {
  test::TempDir tmp("cameras-write");
  std::mt19937 rng(3);
  CameraSet set;
  set.cameras.push_back(make_camera("frame_00003.png", random_rotation(rng), {0.1, -2.5, 3.25}));
  set.cameras.push_back(make_camera("frame_00001.png", random_rotation(rng), {1e-3, 7, -0.3}));
  Camera d = make_camera("frame_00002.png", random_rotation(rng), {-1, 0, 2});
  d.model = CameraModel::kOpenCV;
  d.distortion = {-0.002007863491890884, 0.00040008103952520233, -0.00025085341170362024, 9.3e-4};
  set.cameras.push_back(d);

  // Our JSON: bit-exact.
  REQUIRE(error_of(save_cameras_json(set, tmp.file("cams.json"))) == "<no error>");
  auto json = load_cameras(tmp.file("cams.json"));
  REQUIRE(error_of(json) == "<no error>");
  REQUIRE(json->cameras.size() == 3);
  for (size_t i = 0; i < 3; ++i) {
    const Camera &a = set.cameras[i], &b = json->cameras[i];
    CHECK(a.name == b.name);
    CHECK(a.width == b.width);
    CHECK(a.height == b.height);
    CHECK(a.fx == b.fx);
    CHECK(a.fy == b.fy);
    CHECK(a.cx == b.cx);
    CHECK(a.cy == b.cy);
    CHECK(a.R == b.R);
    CHECK(a.t == b.t);
    CHECK(a.model == b.model);
    CHECK(a.distortion == b.distortion);
  }

  // COLMAP text: intrinsics and t exact (%.17g), R through a quaternion; sorted by name; the two
  // pinhole cameras share one camera id.
  const std::string sparse = tmp.file("scene/sparse/0");
  REQUIRE(error_of(save_colmap_text(set, sparse)) == "<no error>");
  CHECK(std::filesystem::exists(sparse + "/points3D.txt"));
  std::ifstream cams_txt(sparse + "/cameras.txt");
  int camera_lines = 0;
  for (std::string line; std::getline(cams_txt, line);)
    camera_lines += !line.empty() && line[0] != '#';
  CHECK(camera_lines == 2);
  for (const auto& e : std::filesystem::directory_iterator(sparse)) {
    CHECK(e.path().filename().string().find(".tmp") == std::string::npos);
  }
  CameraFormat format{};
  auto colmap = load_cameras(tmp.file("scene"), {}, &format);
  REQUIRE(error_of(colmap) == "<no error>");
  CHECK(format == CameraFormat::kColmapText);
  REQUIRE(colmap->cameras.size() == 3);
  for (const Camera& a : set.cameras) {
    auto b = colmap->find(a.name);
    REQUIRE(b.is_ok());
    CHECK(b->fx == a.fx);
    CHECK(b->fy == a.fy);
    CHECK(b->cx == a.cx);
    CHECK(b->cy == a.cy);
    CHECK(b->t == a.t);
    CHECK((b->R - a.R).cwiseAbs().maxCoeff() < 1e-14);
    CHECK(b->model == a.model);
    CHECK(b->distortion == a.distortion);
  }
  CHECK(colmap->cameras[0].name == "frame_00001.png");

  // A second write replaces the files atomically.
  set.cameras.resize(1);
  REQUIRE(save_colmap_text(set, sparse).is_ok());
  CHECK(load_cameras(sparse)->cameras.size() == 1);
}

// ---- resized, validate, find --------------------------------------------------------------------

TEST_CASE("Camera::resized scales the continuous image plane", "[cameras]") {
  Camera c = make_camera("c", Eigen::Matrix3d::Identity(), {0, 0, 2});
  c.width = 640, c.height = 480, c.fx = 500, c.fy = 510, c.cx = 320.5, c.cy = 240.25;
  const Camera h = c.resized(320, 120);
  CHECK(h.width == 320);
  CHECK(h.height == 120);
  CHECK(h.fx == 250);
  CHECK(h.cx == 160.25);
  CHECK(h.fy == 127.5);
  CHECK(h.cy == 60.0625);
  // Every point lands at the same fraction of the image: u' = u * sx, v' = v * sy.
  for (const Eigen::Vector3d& X : {Eigen::Vector3d(0.3, -0.2, 0.5), Eigen::Vector3d(-1, 1, 3)}) {
    const Eigen::Vector3d a = c.project(X), b = h.project(X);
    CHECK(b.x() == Approx(a.x() * 0.5).epsilon(1e-14));
    CHECK(b.y() == Approx(a.y() * 0.25).epsilon(1e-14));
  }
  // Upsampling: the image edges 0 and W stay the image edges.
  const Camera d = c.resized(1280, 960);
  CHECK(d.fx == 1000);
  CHECK(d.cx == 641);
}

TEST_CASE("Camera::validate names the camera, the field and the value", "[cameras]") {
  const Camera good = make_camera("cam7", Eigen::Matrix3d::Identity(), {0, 0, 1});
  CHECK(good.validate().is_ok());
  struct Case {
    std::function<void(Camera&)> edit;
    std::vector<std::string> expect;
  };
  const double nan = std::nan("");
  for (const Case& c : std::vector<Case>{
           {[](Camera& k) { k.width = 0; }, {"cam7", "size 0x540"}},
           {[](Camera& k) { k.height = -3; }, {"cam7", "960x-3"}},
           {[](Camera& k) { k.fx = 0; }, {"cam7", "fx = 0"}},
           {[](Camera& k) { k.fy = -420; }, {"cam7", "fy = -420"}},
           {[&](Camera& k) { k.fx = nan; }, {"cam7", "fx = nan"}},
           {[](Camera& k) { k.fy = INFINITY; }, {"cam7", "fy = inf"}},
           {[&](Camera& k) { k.cx = nan; }, {"cam7", "cx = nan"}},
           {[](Camera& k) { k.cy = -INFINITY; }, {"cam7", "cy = -inf"}},
           {[](Camera& k) { k.R *= 1.01; }, {"cam7", "not orthonormal", "||R^T R - I||"}},
           {[](Camera& k) { k.R(0, 1) = 0.3; }, {"cam7", "not orthonormal"}},
           {[](Camera& k) { k.R(2, 2) = -1; }, {"cam7", "determinant -1"}},
           {[&](Camera& k) { k.R(1, 1) = nan; }, {"cam7", "R(1,1) = nan"}},
           {[](Camera& k) { k.t[2] = INFINITY; }, {"cam7", "t[2] = inf"}},
           {[](Camera& k) { k.model = CameraModel::kOpenCV; }, {"cam7", "OPENCV needs 4"}},
           {[&](Camera& k) {
              k.model = CameraModel::kOpenCV, k.distortion = {0, nan, 0, 0};
            },
            {"cam7", "distortion[1] = nan"}},
       }) {
    Camera k = good;
    c.edit(k);
    const std::string msg = error_of(k.validate());
    for (const std::string& e : c.expect) CHECK_THAT(msg, Contains(e));
  }
}

TEST_CASE("CameraSet::find: names, paths, ambiguity, unknown names", "[cameras]") {
  CameraSet set;
  set.source = "scene/transforms.json";
  for (const char* p : {"images/a.png", "images/b.png", "train/r_0", "test/r_0", "images/c.png",
                        "images/d.png", "images/e.png"}) {
    Camera c = make_camera(std::filesystem::path(p).filename().string(),
                           Eigen::Matrix3d::Identity(), {0, 0, 1});
    c.file_path = p;
    set.cameras.push_back(c);
  }
  CHECK(set.find("b.png")->file_path == "images/b.png");
  CHECK(set.find("images/b.png")->name == "b.png");
  CHECK(set.find("./images/b.png")->name == "b.png");
  CHECK(set.find("other/folder/b.png")->name == "b.png");  // by file name as a last resort
  CHECK(set.find("test/r_0")->file_path == "test/r_0");
  CHECK(set.index_of("c.png") == 4);
  CHECK(set.index_of("zzz.png") == -1);
  const std::string amb = error_of(set.find("r_0"));
  CHECK_THAT(amb, Contains("ambiguous"));
  CHECK_THAT(amb, Contains("'train/r_0'"));
  CHECK_THAT(amb, Contains("'test/r_0'"));
  const std::string unknown = error_of(set.find("frame_9.png"));
  CHECK_THAT(unknown, Contains("scene/transforms.json"));
  CHECK_THAT(unknown, Contains("'frame_9.png'"));
  CHECK_THAT(unknown, Contains("7 cameras"));
  CHECK_THAT(unknown, Contains("'a.png', 'b.png'"));
  CHECK_THAT(unknown, Contains("..."));
}

// ---- Bad input --------------------------------------------------------------------------------

TEST_CASE("bad input: missing files and folders, unknown content", "[cameras]") {
  test::TempDir tmp("cameras-bad");
  CHECK_THAT(error_of(load_cameras(tmp.file("nope.json"))), Contains("nope.json: no such file"));
  std::filesystem::create_directories(tmp.file("empty"));
  const std::string empty = error_of(load_cameras(tmp.file("empty")));
  CHECK_THAT(empty, Contains("empty: no cameras found"));
  CHECK_THAT(empty, Contains("sparse/0"));
  write_text(tmp.file("half/sparse/0/cameras.txt"), "1 PINHOLE 4 4 1 1 2 2\n");
  CHECK_THAT(error_of(load_cameras(tmp.file("half"))),
             Contains("has cameras.txt but no images.txt"));
  write_text(tmp.file("other.json"), R"({"foo": 1})");
  CHECK_THAT(error_of(load_cameras(tmp.file("other.json"))), Contains("not a camera file"));
  write_text(tmp.file("notjson.txt"), "hello");
  CHECK_THAT(error_of(load_cameras(tmp.file("notjson.txt"))),
             Contains("notjson.txt: malformed JSON"));
  CHECK_THAT(error_of(load_colmap_binary(tmp.file("x/cameras.bin"), tmp.file("x/images.bin"))),
             Contains("cameras.bin"));
}

TEST_CASE("bad input: malformed JSON reports file and byte", "[cameras]") {
  test::TempDir tmp("cameras-badjson");
  write_text(tmp.file("broken.json"), "[{\"name\": \"a\", \"width\": 4,, }]");
  const std::string msg = error_of(load_cameras(tmp.file("broken.json")));
  CHECK_THAT(msg, Contains("broken.json: malformed JSON at byte 27"));
  CHECK_THAT(msg, Contains("syntax error"));
  write_text(tmp.file("nan.json"), R"({"frames": [{"file_path": "a.png", "fl_x": NaN}]})");
  const std::string nan = error_of(load_cameras(tmp.file("nan.json")));
  CHECK_THAT(nan, Contains("nan.json: malformed JSON at byte"));
  CHECK_THAT(nan, Contains("NaN/Infinity are not valid JSON"));
  write_text(tmp.file("trunc.json"), "{\"closeup_poses\": {\"a\": [[1,0");
  CHECK_THAT(error_of(load_cameras(tmp.file("trunc.json"))),
             Contains("trunc.json: malformed JSON"));
}

TEST_CASE("bad input: missing and mistyped fields name the field and the frame", "[cameras]") {
  test::TempDir tmp("cameras-fields");
  const std::string gl = kFrontGL;
  struct Case {
    std::string file, text;
    std::vector<std::string> expect;
  };
  for (const Case& c : std::vector<Case>{
           {"ours.json",
            R"([{"name": "cam3", "width": 4, "height": 4, "fy": 1, "cx": 2, "cy": 2,
              "world_to_camera": [[1,0,0,0],[0,1,0,0],[0,0,1,0],[0,0,0,1]]}])",
            {"ours.json: [0] 'cam3': missing field 'fx'"}},
           {"ours2.json",
            R"([{"name": "cam3", "width": "4", "height": 4, "fx": 1, "fy": 1, "cx": 2, "cy": 2}])",
            {"'cam3': field 'width': expected a number, found string \"4\""}},
           {"ours3.json",
            R"([{"name": "cam3", "width": 4, "height": 4, "fx": 1, "fy": 1, "cx": 2, "cy": 2,
              "world_to_camera": [[1,0,0,0],[0,1,0,0],[0,0,1,0]]}])",
            {"'cam3': world_to_camera: expected a 4x4 matrix", "array of 3"}},
           {"ours4.json",
            R"([{"name": "cam3", "width": 4, "height": 4, "fx": 1, "fy": 1, "cx": 2, "cy": 2,
              "world_to_camera": [[1,0,0,0],[0,1,0,0],[0,0,1,0],[0,0,1,1]]}])",
            {"'cam3': world_to_camera: last row is [0, 0, 1, 1]"}},
           {"ours5.json",
            R"([{"name": "cam3", "width": 4, "height": 4, "fx": 1, "fy": 1, "cx": 2, "cy": 2,
              "world_to_camera": [[1,0,0,0],[0,1,0.5,0],[0,0,1,0],[0,0,0,1]]}])",
            {"ours5.json: [0]: camera 'cam3': rotation is not orthonormal"}},
           {"ns.json",
            R"({"w": 4, "h": 4, "fl_y": 2, "cx": 2, "cy": 2, "frames": [
              {"file_path": "x/a.png", "fl_x": 2, "transform_matrix": )" +
                gl + R"(},
              {"file_path": "x/b.png", "transform_matrix": )" +
                gl + "}]}",
            {"ns.json: frames[1] 'x/b.png': missing field 'fl_x'"}},
           {"ns2.json",
            R"({"w": 4, "h": 4, "fl_x": 2, "fl_y": 2, "frames": [{"file_path": "x/a.png"}]})",
            {"frames[0] 'x/a.png': missing field 'transform_matrix'"}},
           {"ns3.json",
            R"({"w": 4, "h": 4, "fl_x": 2, "fl_y": 2, "frames": [{"transform_matrix": )" + gl +
                "}]}",
            {"ns3.json: frames[0]: missing field 'file_path'"}},
           {"ns4.json",
            R"({"fl_x": 2, "fl_y": 2, "frames": [{"file_path": "x/a.png", "transform_matrix": )" +
                gl + "}]}",
            {"frames[0] 'x/a.png': missing fields 'w' and 'h'"}},
           {"ns5.json",
            R"({"w": 4, "h": 4, "fl_x": 2, "fl_y": 2, "frames": [
              {"file_path": "x/a.png", "transform_matrix": [[1,0,0],[0,1,0],[0,0,1]]}]})",
            {"frames[0] 'x/a.png': transform_matrix: row 0: expected 4 numbers, found array of 3"}},
           {"split.json",
            R"({"intrinsics": {"w": 960, "h": 540, "fl_x": 1, "cx": 1, "cy": 1},
              "closeup_poses": {}})",
            {"split.json: intrinsics: missing field 'fl_y'"}},
           {"split2.json",
            R"({"intrinsics": {"w": 960, "h": 540, "fl_x": 1, "fl_y": 1, "cx": 1, "cy": 1},
              "closeup_poses": {"f1.png": [[1,0,0,0]]}})",
            {"split2.json: closeup_poses['f1.png']: expected a 4x4 matrix"}},
           {"split3.json",
            R"({"intrinsics": {"w": 960, "h": 540, "fl_x": 1, "fl_y": 1, "cx": 1, "cy": 1},
              "closeup_eval_pairs": [{"training_frame": "a", "closeup_frame": "b", "depth_ratio": 2,
              "angle_deg": 1, "pair_score": 1}], "closeup_poses": {}})",
            {"split3.json: closeup_eval_pairs[0] ('b'): missing field 'iou'"}},
           {"split4.json", R"({"closeup_poses": {}})", {"split4.json: missing field 'intrinsics'"}},
           {"split5.json",
            R"({"intrinsics": {"w": 960, "h": 540, "fl_x": 0, "fl_y": 1, "cx": 1, "cy": 1},
              "closeup_poses": {}})",
            {"split5.json: camera 'intrinsics': fx = 0"}},
       }) {
    INFO(c.file);
    write_text(tmp.file(c.file), c.text);
    CameraLoadOptions strict;  // a file with one valid frame loads otherwise (test_camera_models)
    strict.strict = true;
    const std::string msg = error_of(load_cameras(tmp.file(c.file), strict));
    for (const std::string& e : c.expect) CHECK_THAT(msg, Contains(e));
  }
}

TEST_CASE("bad input: focal length, rotation, NaN, models, camera ids in COLMAP text",
          "[cameras]") {
  test::TempDir tmp("cameras-colmap-bad");
  const std::string img_front = "3 1 0 0 0 0 0 4 1 front.png\n\n";
  struct Case {
    std::string cameras, images;
    std::vector<std::string> expect;
  };
  for (const Case& c : std::vector<Case>{
           {"1 PINHOLE 640 480 0 510 320 240\n", img_front, {"camera 'front.png': fx = 0"}},
           {"1 SIMPLE_PINHOLE 640 480 -5 320 240\n", img_front, {"camera 'front.png': fx = -5"}},
           {"1 PINHOLE 640 0 5 5 320 240\n", img_front, {"size 640x0"}},
           {"1 PINHOLE 640 480 5 5 320 240\n",
            "3 1 0 0 0 nan 0 4 1 front.png\n\n",
            {"images.txt line 1", "camera 'front.png': t[0] = nan"}},
           {"1 PINHOLE 640 480 5 5 320 240\n",
            "3 2 0 0 0 0 0 4 1 front.png\n\n",
            {"images.txt line 1 (image 3 'front.png'): quaternion", "norm 2"}},
           {"1 FOV 640 480 5 5 320 240 0.1\n",
            img_front,
            {"cameras.txt line 1: camera 1: camera model FOV is not supported", "OPENCV"}},
           {"1 FANCY 640 480 5 320 240\n", img_front, {"unknown camera model 'FANCY'"}},
           {"1 PINHOLE 640 480 5 5 320\n", img_front, {"PINHOLE expects 4 parameters, found 3"}},
           {"1 PINHOLE 640 480 5 5 320 abc\n",
            img_front,
            {"cameras.txt line 1: PARAMS[3]: expected a number, found 'abc'"}},
           {"1 PINHOLE 640 480 5 5 320 240\n2 PINHOLE 640 480 5 5 320 240\n",
            "3 1 0 0 0 0 0 4 7 front.png\n\n",
            {"images.txt line 1 (image 3 'front.png'): camera id 7 is not in",
             "cameras.txt (its ids: 1, 2)"}},
           {"1 PINHOLE 640 480 5 5 320 240\n",
            "3 1 0 0 0 0 0 4 1 a.png\n4 1 0 0 0 0 0 4 1 b.png\n",
            {"images.txt line 2: expected the 2D points line of image 3 'a.png'"}},
           {"1 PINHOLE 640 480 5 5 320 240\n",
            "3 1 0 0 0 0 0 4 1\n\n",
            {"images.txt line 1: expected IMAGE_ID QW QX QY QZ TX TY TZ CAMERA_ID NAME"}},
           {"1 PINHOLE 640 480 5 5 320 240\n1 PINHOLE 640 480 5 5 320 240\n",
            img_front,
            {"camera id 1 appears twice"}},
       }) {
    INFO(c.cameras << c.images);
    write_text(tmp.file("m/cameras.txt"), c.cameras);
    write_text(tmp.file("m/images.txt"), c.images);
    const std::string msg = error_of(load_cameras(tmp.file("m")));
    for (const std::string& e : c.expect) CHECK_THAT(msg, Contains(e));
  }
  // Non-rigid rotation and unknown model in nerfstudio.
  write_text(tmp.file("ns.json"), R"({"w": 4, "h": 4, "fl_x": 2, "fl_y": 2, "frames": [
      {"file_path": "a.png", "transform_matrix": [[2,0,0,0],[0,1,0,0],[0,0,1,0],[0,0,0,1]]}]})");
  CHECK_THAT(error_of(load_cameras(tmp.file("ns.json"))),
             Contains("camera 'a.png': rotation is not orthonormal"));
  write_text(tmp.file("ns2.json"),
             R"({"w": 4, "h": 4, "fl_x": 2, "fl_y": 2, "camera_model": "EQUIRECTANGULAR",
      "frames": [{"file_path": "a.png", "transform_matrix": [[1,0,0,0],[0,1,0,0],[0,0,1,0],[0,0,0,1]]}]})");
  CHECK_THAT(error_of(load_cameras(tmp.file("ns2.json"))),
             Contains("frames[0] 'a.png': field 'camera_model': camera model 'EQUIRECTANGULAR' is "
                      "not supported"));
  write_text(tmp.file("ns3.json"), R"({"w": 4, "h": 4, "fl_x": 2, "fl_y": 2,
      "applied_transform": [[1,0,0,0],[0,2,0,0],[0,0,1,0]], "frames": []})");
  CHECK_THAT(error_of(load_cameras(tmp.file("ns3.json"))),
             Contains("applied_transform: not a similarity"));
}

TEST_CASE("bad input: COLMAP binary truncated, lying counts, unknown models and ids", "[cameras]") {
  test::TempDir tmp("cameras-bin-bad");
  const std::string dir = tmp.file("m");
  const Bytes cams = rig_cameras_bin(), imgs = rig_images_bin();
  write_rig_colmap_binary(dir);
  REQUIRE(load_cameras(dir).is_ok());

  // Every truncation of either file fails with a message naming the file, never crashes.
  for (size_t n = 0; n < cams.b.size(); ++n) {
    write_bytes(dir + "/cameras.bin",
                std::vector<uint8_t>(cams.b.begin(), cams.b.begin() + long(n)));
    const std::string msg = error_of(load_cameras(dir));
    CHECK_THAT(msg, Contains("cameras.bin"));
  }
  write_bytes(dir + "/cameras.bin", cams.b);
  for (size_t n = 0; n < imgs.b.size(); ++n) {
    write_bytes(dir + "/images.bin",
                std::vector<uint8_t>(imgs.b.begin(), imgs.b.begin() + long(n)));
    const std::string msg = error_of(load_cameras(dir));
    CHECK_THAT(msg, Contains("images.bin"));
  }
  // Counts far beyond the file are refused before allocating.
  write_bytes(dir + "/images.bin", imgs.b);
  write_bytes(dir + "/cameras.bin", rig_cameras_bin(1, uint64_t(1) << 60).b);
  CHECK_THAT(error_of(load_cameras(dir)), Contains("camera count 1152921504606846976"));
  write_bytes(dir + "/cameras.bin", cams.b);
  write_bytes(dir + "/images.bin", rig_images_bin(1, uint64_t(-1) / 2).b);
  CHECK_THAT(error_of(load_cameras(dir)),
             Contains("'side.png' points2D count 9223372036854775807"));
  Bytes many = rig_images_bin();
  const uint64_t huge = uint64_t(1) << 62;
  std::memcpy(many.b.data(), &huge, 8);
  write_bytes(dir + "/images.bin", many.b);
  CHECK_THAT(error_of(load_cameras(dir)), Contains("image count 4611686018427387904"));
  // Trailing garbage.
  Bytes extra = rig_images_bin();
  extra.put<uint32_t>(0);
  write_bytes(dir + "/images.bin", extra.b);
  CHECK_THAT(error_of(load_cameras(dir)), Contains("4 unexpected bytes after 2 images"));
  // Models: FOV (7) named, an unknown id, OPENCV kept with distortion.
  write_bytes(dir + "/images.bin", imgs.b);
  write_bytes(dir + "/cameras.bin", rig_cameras_bin(7).put<double>(0.5).b);
  CHECK_THAT(error_of(load_cameras(dir)), Contains("camera model FOV (id 7) is not supported"));
  write_bytes(dir + "/cameras.bin", rig_cameras_bin(99).b);
  CHECK_THAT(error_of(load_cameras(dir)), Contains("unknown camera model id 99"));
  Bytes opencv = rig_cameras_bin(4);
  for (double k : {0.1, -0.2, 0.003, 0.004}) opencv.put<double>(k);
  write_bytes(dir + "/cameras.bin", opencv.b);
  auto distorted = load_cameras(dir);
  REQUIRE(error_of(distorted) == "<no error>");
  CHECK(distorted->cameras[0].model == CameraModel::kOpenCV);
  CHECK(distorted->cameras[0].distortion == std::vector<double>{0.1, -0.2, 0.003, 0.004});
  // An image pointing at a camera id that is not there.
  write_bytes(dir + "/cameras.bin", cams.b);
  write_bytes(dir + "/images.bin", rig_images_bin(5).b);
  CHECK_THAT(error_of(load_cameras(dir)), Contains("camera id 5 is not in"));
  // Random byte corruption: every outcome is a clean load of valid cameras or a message.
  std::mt19937 rng(11);
  int failures = 0;
  for (int trial = 0; trial < 300; ++trial) {
    Bytes c = cams, i = imgs;
    std::vector<uint8_t>& target = trial % 2 ? c.b : i.b;
    const int edits = 1 + int(rng() % 4);
    for (int e = 0; e < edits; ++e) target[rng() % target.size()] = uint8_t(rng());
    write_bytes(dir + "/cameras.bin", c.b);
    write_bytes(dir + "/images.bin", i.b);
    auto r = load_cameras(dir);
    if (r.is_ok()) {
      for (const Camera& cam : r->cameras) CHECK(cam.validate().is_ok());
    } else {
      ++failures;
      CHECK_THAT(r.status().message(), Contains(".bin"));
    }
  }
  CHECK(failures > 0);
}
