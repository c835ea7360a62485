// Scale-matched crops against the analytic geometry: >= 99% of pixels on the right plane, scale
// within 1% of the analytic ratio, crop centres within 1 px of the analytic projection centroid.
#include <catch2/catch.hpp>

#include "enhance/macro/crops.h"
#include "macro_synth_fixture.h"

using namespace macro;
using namespace macro::enhance;

namespace {

using Fixture = test::ThreePlaneCloseup;

}  // namespace

TEST_CASE("three-plane scene: >= 99% of pixels on the right plane", "[macro][crops]") {
  Fixture f;
  REQUIRE(f.planes.planes.size() == 3);
  const std::vector<int> order = test::planes_far_to_near(f.scene.geometry, f.cu);
  const int W = f.cu.width, H = f.cu.height;
  std::vector<int> truth(size_t(W) * H, -1);
  for (int i = 0; i < H; ++i)
    for (int j = 0; j < W; ++j)
      if (auto hit = gs::cast_pixel(f.scene.geometry, f.cu, i, j))
        truth[size_t(i) * W + j] = hit->index;
  // Every pixel that is valid in the render and hits a plane; and the interior ones (the 3x3
  // neighbourhood hits one plane: away from silhouettes, where one pixel mixes two surfaces).
  int64_t both = 0, agree = 0, inner = 0, inner_agree = 0;
  for (int i = 0; i < H; ++i)
    for (int j = 0; j < W; ++j) {
      const int32_t l = f.planes.labels[size_t(i) * W + j];
      const int t = truth[size_t(i) * W + j];
      if (l < 0 || t < 0) continue;
      ++both;
      const bool ok = order[size_t(l)] == t;
      agree += ok;
      bool interior = i > 0 && j > 0 && i < H - 1 && j < W - 1;
      for (int di = -1; di <= 1 && interior; ++di)
        for (int dj = -1; dj <= 1; ++dj)
          interior &= truth[size_t(i + di) * W + size_t(j + dj)] == t;
      if (!interior) continue;
      ++inner;
      inner_agree += ok;
    }
  INFO("all " << agree << " / " << both << ", interior " << inner_agree << " / " << inner);
  REQUIRE(inner > 10000);
  CHECK(double(inner_agree) >= 0.99 * double(inner));
  CHECK(double(agree) >= 0.97 * double(both));
}

TEST_CASE("crop scale and centre match the analytic answers", "[macro][crops]") {
  Fixture f;
  const std::vector<int> order = test::planes_far_to_near(f.scene.geometry, f.cu);
  std::vector<CropRejection> rej;
  const Size2 model{320, 176};
  // The analytic centroid below unprojects pixel centres (our convention): --pixel-coords centre.
  CropOptions centres;
  centres.pixel = PixelCoords::kCentre;
  const auto crops =
      compute_crops(f.cud, f.planes, f.refs, {"ref_a", "ref_b"}, model, centres, &rej);
  REQUIRE(crops.size() + rej.size() == 6);
  REQUIRE(crops.size() >= 5);
  // Bin-major view order.
  for (size_t k = 1; k < crops.size(); ++k)
    CHECK((crops[k].plane > crops[k - 1].plane ||
           (crops[k].plane == crops[k - 1].plane && crops[k].ref > crops[k - 1].ref)));
  const int W = f.cu.width, H = f.cu.height;
  for (const Crop& c : crops) {
    const gs::Camera& rc = f.refs[size_t(c.ref)];
    const int plane = order[size_t(c.plane)];
    // Analytic: lower median of the true depth over the plane's close-up pixels; the mean
    // projection of the true surface points that land in the reference, over (a) the pixels whose
    // ray hits the plane and (b) the pixels the render labelled with this plane.
    std::vector<double> t;
    double su = 0, sv = 0, lu = 0, lv = 0;
    int64_t n = 0, ln = 0;
    for (int i = 0; i < H; ++i)
      for (int j = 0; j < W; ++j) {
        auto hit = gs::cast_pixel(f.scene.geometry, f.cu, i, j);
        if (!hit) continue;
        const bool labelled = f.planes.labels[size_t(i) * W + j] == c.plane;
        if (hit->index != plane && !labelled) continue;
        const Eigen::Vector3d xc((j + 0.5 - f.cu.cx) / f.cu.fx * hit->t,
                                 (i + 0.5 - f.cu.cy) / f.cu.fy * hit->t, hit->t);
        const Eigen::Vector3d p = rc.project(f.cu.R.transpose() * (xc - f.cu.t));
        const bool inside =
            p.z() > 0 && p.x() >= 0 && p.x() < rc.width && p.y() >= 0 && p.y() < rc.height;
        if (hit->index == plane) {
          t.push_back(hit->t);
          if (inside) {
            su += p.x();
            sv += p.y();
            ++n;
          }
        }
        if (labelled && inside) {
          lu += p.x();
          lv += p.y();
          ++ln;
        }
      }
    std::sort(t.begin(), t.end());
    const double d_in = t[(t.size() - 1) / 2];
    const Eigen::Vector3d xw =
        f.cu.R.transpose() * (Eigen::Vector3d((W / 2.0 - f.cu.cx) / f.cu.fx * d_in,
                                              (H / 2.0 - f.cu.cy) / f.cu.fy * d_in, d_in) -
                              f.cu.t);
    const double d_ref = (rc.R * xw + rc.t).z();
    const double scale_analytic = (d_ref / d_in) * (f.cu.fx / rc.fx);  // W / crop width
    INFO("plane " << c.plane << " ref " << c.reference << " scale " << c.scale << " analytic "
                  << scale_analytic << " centre " << c.centre_u << "," << c.centre_v << " analytic "
                  << su / n << "," << sv / n << " same pixels " << lu / ln << "," << lv / ln);
    CHECK(std::abs(c.scale / scale_analytic - 1.0) < 0.01);
    // (b) the same pixel set with exact depths: within 1 px; (a) the analytic plane region,
    // which differs from the labels along silhouettes: within 2 px.
    CHECK(std::abs(c.centre_u - lu / double(ln)) < 1.0);
    CHECK(std::abs(c.centre_v - lv / double(ln)) < 1.0);
    CHECK(std::abs(c.centre_u - su / double(n)) < 2.0);
    CHECK(std::abs(c.centre_v - sv / double(n)) < 2.0);
    // Box: crop size W/scale x H/scale (focal-corrected) centred on the centroid, rounded.
    const double cw = W * (rc.fx / f.cu.fx) / (c.d_ref / c.d_in);
    CHECK(std::abs(c.box.width() - cw) <= 1.0);
    CHECK(std::abs(0.5 * (c.box.x0 + c.box.x1) - c.centre_u) <= 1.0);
    CHECK(c.view == model);
    CHECK(c.valid_fraction > 0);
    CHECK(c.valid_fraction <= 1);
  }
}

TEST_CASE("crop validity, canvas padding, per-plane scale and tight crops", "[macro][crops]") {
  Crop c;
  c.box = {-10, -5, 30, 15};  // 40 x 20, 10 columns and 5 rows outside a 100 x 100 reference
  c.view = {80, 40};
  const auto v = crop_view_validity(c, 100, 100);
  int64_t on = 0;
  for (uint8_t x : v) on += x;
  CHECK(on == 60 * 30);
  gs::Image ref(100, 100, 3);
  for (auto& x : ref.data) x = 0.5f;
  const gs::Image canvas = cut_crop_canvas(ref, c.box);
  CHECK(canvas.width == 40);
  CHECK(canvas.at(0, 0, 0) == 0.f);
  CHECK(canvas.at(10, 20, 1) == 0.5f);

  Fixture f;
  CropOptions per;
  per.scale = ScaleMode::kPerPlane;
  const auto a = compute_crops(f.cud, f.planes, f.refs, {"ref_a", "ref_b"}, {320, 176}, {});
  const auto b = compute_crops(f.cud, f.planes, f.refs, {"ref_a", "ref_b"}, {320, 176}, per);
  REQUIRE(a.size() == b.size());
  for (size_t k = 0; k < a.size(); ++k) CHECK(b[k].scale == Approx(a[k].scale).epsilon(0.15));
  CropOptions tight;
  tight.crop = CropMode::kTight;
  const auto t = compute_crops(f.cud, f.planes, f.refs, {"ref_a", "ref_b"}, {320, 176}, tight);
  REQUIRE(t.size() == a.size());
  int64_t full_tokens = 0, tight_tokens = 0;
  for (size_t k = 0; k < t.size(); ++k) {
    full_tokens += int64_t(a[k].view.w) * a[k].view.h;
    tight_tokens += int64_t(t[k].view.w) * t[k].view.h;
    CHECK(t[k].box.width() <= a[k].box.width() + 1);
    CHECK(t[k].scale == Approx(a[k].scale));
  }
  INFO("tight/full view pixels " << double(tight_tokens) / double(full_tokens));
  CHECK(tight_tokens < full_tokens);
}

namespace {

// A close-up W x H with power-of-two intrinsics (exact arithmetic), identity pose, flat depth z,
// one plane; the reference is the same camera at half the size.
struct FlatPair {
  gs::Camera cu, ref;
  DepthView cud;
  PlaneResult planes;
  FlatPair() {
    cu.name = "cu";
    cu.width = 32;
    cu.height = 16;
    cu.fx = cu.fy = 32;
    cu.cx = 16;
    cu.cy = 8;
    cu.R.setIdentity();
    cu.t.setZero();
    ref = cu.resized(16, 8);
    ref.name = "ref";
    cud.camera = cu;
    cud.depth.assign(size_t(cu.width) * cu.height, 2.f);
    planes.width = cu.width;
    planes.height = cu.height;
    planes.labels.assign(cud.depth.size(), 0);
    DepthPlane p;
    p.depth_median = 2.0;
    p.inv_depth_centroid = 0.5;
    p.pixels = int64_t(cud.depth.size());
    planes.planes = {p};
  }
};

}  // namespace

TEST_CASE("crop centroid: integer pixel indices (released) or pixel centres (ours)",
          "[macro][crops]") {
  FlatPair f;
  // Pixel (j, i) lands at u = (j + o) / 2, v = (i + o) / 2 in the half-size reference: the
  // centroid is the mean of the indices over 2, plus o / 2.
  CropOptions released;  // the default
  CHECK(released.pixel == PixelCoords::kIndex);
  auto a = compute_crops(f.cud, f.planes, {f.ref}, {"ref"}, {16, 8}, released);
  REQUIRE(a.size() == 1);
  CHECK(a[0].centre_u == 15.5 / 2);  // mean of j = 0..31 is 15.5
  CHECK(a[0].centre_v == 7.5 / 2);   // mean of i = 0..15 is 7.5
  CHECK(a[0].valid_pixels == 32 * 16);
  CropOptions ours;
  ours.pixel = PixelCoords::kCentre;
  auto b = compute_crops(f.cud, f.planes, {f.ref}, {"ref"}, {16, 8}, ours);
  REQUIRE(b.size() == 1);
  CHECK(b[0].centre_u == 8.0);
  CHECK(b[0].centre_v == 4.0);
  CHECK(*parse_pixel_coords("index") == PixelCoords::kIndex);
  CHECK(*parse_pixel_coords("centre") == PixelCoords::kCentre);
  CHECK_THAT(parse_pixel_coords("middle").status().message(), Catch::Contains("--pixel-coords"));
}

TEST_CASE(
    "crop padding mask: made at the reference size and resized (released) or at the model "
    "size (ours)",
    "[macro][crops]") {
  // A 5 x 2 reference, a box 3 wide starting 2 columns left of it, a 3 x 2 model. At the
  // reference size the canvas column of pixel x is floor(3x/5) = 0,0,1,1,2 -> reference column
  // -2,-2,-1,-1,0: only the last is inside. Resized nearest to 3 (columns 0, 1, 3): all padding.
  // Straight at the model size: floor(3x/3) = 0,1,2 -> -2,-1,0: the last is inside.
  Crop c;
  c.box = {-2, 0, 1, 2};
  c.view = {3, 2};
  const std::vector<uint8_t> at_ref = crop_reference_validity(c, 5, 2);
  CHECK(at_ref == std::vector<uint8_t>{0, 0, 0, 0, 1, 0, 0, 0, 0, 1});
  CHECK(resize_nearest(at_ref, 2, 5, 2, 3) == std::vector<uint8_t>{0, 0, 0, 0, 0, 0});
  CHECK(crop_model_validity(c, 5, 2, {3, 2}) == std::vector<uint8_t>{0, 0, 1, 0, 0, 1});
}
