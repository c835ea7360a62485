// Scale-matched reference crops (see crops.h).
#include "enhance/macro/crops.h"

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>

namespace macro::enhance {

const char* scale_mode_name(ScaleMode m) {
  return m == ScaleMode::kPerPlane ? "per-plane" : "axis";
}
const char* crop_mode_name(CropMode m) {
  switch (m) {
    case CropMode::kFull:
      return "full";
    case CropMode::kTight:
      return "tight";
    case CropMode::kComposite:
      return "composite";
  }
  return "?";
}
Result<ScaleMode> parse_scale_mode(const std::string& t) {
  if (t == "axis" || t == "released") return ScaleMode::kOpticalAxis;
  if (t == "per-plane") return ScaleMode::kPerPlane;
  return Status::error("--scale: expected axis or per-plane, found '" + t + "'");
}
Result<CropMode> parse_crop_mode(const std::string& t) {
  if (t == "full" || t == "released") return CropMode::kFull;
  if (t == "tight") return CropMode::kTight;
  if (t == "composite") return CropMode::kComposite;
  return Status::error("--crop: expected full, tight or composite, found '" + t + "'");
}

namespace {

struct PlaneAccum {
  double su = 0, sv = 0;
  int64_t n = 0;
  int bx0 = INT32_MAX, by0 = INT32_MAX, bx1 = -1, by1 = -1;  // close-up bbox of valid pixels
  std::vector<float> z_cu, z_ref;                            // per-plane scale only
};

int round_half_even(double x) {
  return int(std::nearbyint(x));
}

}  // namespace

std::vector<Crop> compute_crops(const DepthView& cu, const PlaneResult& planes,
                                const std::vector<gs::Camera>& refs,
                                const std::vector<std::string>& ref_names, Size2 model,
                                const CropOptions& opt, std::vector<CropRejection>* rejected,
                                ThreadPool& pool) {
  const gs::Camera& a = cu.camera;
  const int W = a.width, H = a.height;
  const int P = int(planes.planes.size());
  MACRO_CHECK(planes.width == W && planes.height == H && cu.depth.size() == size_t(W) * H);
  MACRO_CHECK(ref_names.size() == refs.size());
  // acc[ref][plane], reduced over fixed row chunks in order (independent of the thread count).
  std::vector<std::vector<PlaneAccum>> acc(refs.size(), std::vector<PlaneAccum>(size_t(P)));
  for (size_t r = 0; r < refs.size(); ++r) {
    const gs::Camera& c = refs[r];
    const Eigen::Matrix3d M = c.R * a.R.transpose();
    const Eigen::Vector3d b = c.t - M * a.t;
    const double o = pixel_offset(opt.pixel);
    const size_t chunk = 16, chunks = (size_t(H) + chunk - 1) / chunk;
    std::vector<std::vector<PlaneAccum>> part(chunks, std::vector<PlaneAccum>(size_t(P)));
    pool.parallel_for(chunks, [&](size_t c0, size_t c1, int) {
      for (size_t ci = c0; ci < c1; ++ci)
        for (int i = int(ci * chunk); i < std::min(H, int((ci + 1) * chunk)); ++i)
          for (int j = 0; j < W; ++j) {
            const size_t k = size_t(i) * W + j;
            const int32_t l = planes.labels[k];
            const double z = cu.depth[k];
            if (l < 0 || !(z > 0)) continue;
            const Eigen::Vector3d q =
                M * Eigen::Vector3d((j + o - a.cx) / a.fx * z, (i + o - a.cy) / a.fy * z, z) + b;
            if (!(q.z() > 0)) continue;
            const double u = c.fx * q.x() / q.z() + c.cx, v = c.fy * q.y() / q.z() + c.cy;
            if (!(u >= 0 && u < c.width && v >= 0 && v < c.height)) continue;
            PlaneAccum& pa = part[ci][size_t(l)];
            pa.su += u;
            pa.sv += v;
            ++pa.n;
            pa.bx0 = std::min(pa.bx0, j);
            pa.by0 = std::min(pa.by0, i);
            pa.bx1 = std::max(pa.bx1, j + 1);
            pa.by1 = std::max(pa.by1, i + 1);
            if (opt.scale == ScaleMode::kPerPlane) {
              pa.z_cu.push_back(float(z));
              pa.z_ref.push_back(float(q.z()));
            }
          }
    });
    for (size_t ci = 0; ci < chunks; ++ci)
      for (int p = 0; p < P; ++p) {
        PlaneAccum& d = acc[r][size_t(p)];
        const PlaneAccum& s = part[ci][size_t(p)];
        d.su += s.su;
        d.sv += s.sv;
        d.n += s.n;
        d.bx0 = std::min(d.bx0, s.bx0);
        d.by0 = std::min(d.by0, s.by0);
        d.bx1 = std::max(d.bx1, s.bx1);
        d.by1 = std::max(d.by1, s.by1);
        d.z_cu.insert(d.z_cu.end(), s.z_cu.begin(), s.z_cu.end());
        d.z_ref.insert(d.z_ref.end(), s.z_ref.begin(), s.z_ref.end());
      }
  }
  auto reject = [&](int p, int r, const std::string& why) {
    if (rejected) rejected->push_back({p, r, why});
  };
  std::vector<Crop> out;
  for (int p = 0; p < P; ++p)
    for (size_t r = 0; r < refs.size(); ++r) {
      const gs::Camera& c = refs[r];
      PlaneAccum& pa = acc[r][size_t(p)];
      if (pa.n == 0) {
        reject(p, int(r), "no close-up pixel of the plane projects into the reference");
        continue;
      }
      Crop cr;
      cr.plane = p;
      cr.ref = int(r);
      cr.reference = ref_names[r];
      cr.valid_pixels = pa.n;
      cr.centre_u = pa.su / double(pa.n);
      cr.centre_v = pa.sv / double(pa.n);
      cr.d_in = planes.planes[size_t(p)].depth_median;
      if (opt.scale == ScaleMode::kOpticalAxis) {
        const Eigen::Vector3d xc((W / 2.0 - a.cx) / a.fx * cr.d_in,
                                 (H / 2.0 - a.cy) / a.fy * cr.d_in, cr.d_in);
        const Eigen::Vector3d xw = a.R.transpose() * (xc - a.t);
        cr.d_ref = (c.R * xw + c.t).z();
      } else {
        auto median = [](std::vector<float>& v) {
          std::nth_element(v.begin(), v.begin() + std::ptrdiff_t((v.size() - 1) / 2), v.end());
          return double(v[(v.size() - 1) / 2]);
        };
        cr.d_in = median(pa.z_cu);
        cr.d_ref = median(pa.z_ref);
      }
      if (!(cr.d_in > 0) || !(cr.d_ref > 0)) {
        reject(p, int(r), "non-positive plane depth in the close-up or the reference");
        continue;
      }
      const double s = cr.d_ref / cr.d_in;
      double cw = W * (c.fx / a.fx) / s, ch = H * (c.fy / a.fy) / s;
      cr.scale = W / cw;
      double ccx = cr.centre_u, ccy = cr.centre_v;
      if (opt.crop == CropMode::kTight) {
        // The plane's close-up bounding box mapped by the same scale: its size divided by s, its
        // centre offset from the frame centre carried over (exact for a fronto-parallel plane).
        const double kx = cw / W, ky = ch / H;  // reference pixels per close-up pixel
        ccx += (0.5 * (pa.bx0 + pa.bx1) - W / 2.0) * kx;
        ccy += (0.5 * (pa.by0 + pa.by1) - H / 2.0) * ky;
        cw = (pa.bx1 - pa.bx0) * kx;
        ch = (pa.by1 - pa.by0) * ky;
      }
      if (cw > kMaxCropFactor * c.width || ch > kMaxCropFactor * c.height || cw < 1 || ch < 1) {
        reject(p, int(r),
               "crop " + std::to_string(cw) + "x" + std::to_string(ch) +
                   " px outside [1, 5x the reference]");
        continue;
      }
      cr.box = {round_half_even(ccx - cw / 2), round_half_even(ccy - ch / 2),
                round_half_even(ccx + cw / 2), round_half_even(ccy + ch / 2)};
      if (cr.box.width() < 1 || cr.box.height() < 1) {
        reject(p, int(r), "crop rounds to an empty box");
        continue;
      }
      const int ox = std::max(0, std::min(cr.box.x1, c.width) - std::max(cr.box.x0, 0));
      const int oy = std::max(0, std::min(cr.box.y1, c.height) - std::max(cr.box.y0, 0));
      cr.valid_fraction = double(ox) * oy / (double(cr.box.width()) * cr.box.height());
      if (!(cr.valid_fraction > 0)) {
        reject(p, int(r), "crop lies entirely outside the reference");
        continue;
      }
      if (opt.crop == CropMode::kTight) {
        const double kv = double(model.w) / W;
        auto up8 = [](double v) { return std::max(8, int(std::ceil(v / 8.0)) * 8); };
        cr.view = {std::min(model.w, up8((pa.bx1 - pa.bx0) * kv)),
                   std::min(model.h, up8((pa.by1 - pa.by0) * double(model.h) / H))};
      } else {
        cr.view = model;
      }
      out.push_back(cr);
    }
  return out;
}

std::vector<uint8_t> crop_view_validity(const Crop& crop, int ref_w, int ref_h) {
  const int vw = crop.view.w, vh = crop.view.h;
  const int bw = crop.box.width(), bh = crop.box.height();
  std::vector<uint8_t> col(static_cast<size_t>(vw)), row(static_cast<size_t>(vh));
  for (int x = 0; x < vw; ++x) {
    const int rx = crop.box.x0 + nearest_index(x, bw, vw);
    col[size_t(x)] = rx >= 0 && rx < ref_w;
  }
  for (int y = 0; y < vh; ++y) {
    const int ry = crop.box.y0 + nearest_index(y, bh, vh);
    row[size_t(y)] = ry >= 0 && ry < ref_h;
  }
  std::vector<uint8_t> m(size_t(vw) * vh);
  for (int y = 0; y < vh; ++y)
    for (int x = 0; x < vw; ++x) m[size_t(y) * vw + x] = row[size_t(y)] & col[size_t(x)];
  return m;
}

std::vector<uint8_t> crop_reference_validity(const Crop& crop, int ref_w, int ref_h) {
  const int bw = crop.box.width(), bh = crop.box.height();
  std::vector<uint8_t> col(static_cast<size_t>(ref_w)), row(static_cast<size_t>(ref_h));
  for (int x = 0; x < ref_w; ++x) {
    const int rx = crop.box.x0 + nearest_index(x, bw, ref_w);
    col[size_t(x)] = rx >= 0 && rx < ref_w;
  }
  for (int y = 0; y < ref_h; ++y) {
    const int ry = crop.box.y0 + nearest_index(y, bh, ref_h);
    row[size_t(y)] = ry >= 0 && ry < ref_h;
  }
  std::vector<uint8_t> m(size_t(ref_w) * size_t(ref_h));
  for (int y = 0; y < ref_h; ++y)
    for (int x = 0; x < ref_w; ++x)
      m[size_t(y) * size_t(ref_w) + size_t(x)] = row[size_t(y)] & col[size_t(x)];
  return m;
}

std::vector<uint8_t> crop_model_validity(const Crop& crop, int ref_w, int ref_h, Size2 model) {
  MACRO_CHECK(crop.view.w <= model.w && crop.view.h <= model.h);
  const std::vector<uint8_t> v = crop_view_validity(crop, ref_w, ref_h);
  if (crop.view == model) return v;
  std::vector<uint8_t> m(size_t(model.w) * size_t(model.h), kCanvasPad);
  for (int y = 0; y < crop.view.h; ++y)
    std::copy_n(v.begin() + std::ptrdiff_t(size_t(y) * size_t(crop.view.w)), crop.view.w,
                m.begin() + std::ptrdiff_t(size_t(y) * size_t(model.w)));
  return m;
}

gs::Image paste_on_canvas(const gs::Image& view, Size2 model) {
  MACRO_CHECK(view.width <= model.w && view.height <= model.h);
  if (view.width == model.w && view.height == model.h) return view;
  gs::Image out(model.w, model.h, view.channels);
  for (int y = 0; y < view.height; ++y)
    std::copy_n(view.data.begin() + std::ptrdiff_t(size_t(y) * view.width * view.channels),
                size_t(view.width) * view.channels,
                out.data.begin() + std::ptrdiff_t(size_t(y) * model.w * view.channels));
  return out;
}

gs::Image cut_crop_canvas(const gs::Image& ref, const CropBox& box) {
  gs::Image out(box.width(), box.height(), 3);
  for (int y = 0; y < box.height(); ++y) {
    const int ry = box.y0 + y;
    if (ry < 0 || ry >= ref.height) continue;
    for (int x = 0; x < box.width(); ++x) {
      const int rx = box.x0 + x;
      if (rx < 0 || rx >= ref.width) continue;
      for (int ch = 0; ch < 3; ++ch)
        out.at(y, x, ch) = ref.at(ry, rx, std::min(ch, ref.channels - 1));
    }
  }
  return out;
}

std::vector<CompositeView> compose_crop_views(const std::vector<Crop>& crops,
                                              const PlaneResult& planes,
                                              const std::vector<std::string>& ref_names,
                                              const std::vector<Size2>& ref_sizes, Size2 model) {
  const int W = planes.width, H = planes.height, P = int(planes.planes.size());
  MACRO_CHECK(ref_names.size() == ref_sizes.size());
  MACRO_CHECK(planes.labels.size() == size_t(W) * size_t(H) && model.w > 0 && model.h > 0);
  const size_t hw = size_t(model.w) * size_t(model.h);
  // The close-up plane map at model resolution (nearest), shared by every view.
  std::vector<int32_t> labels(hw);
  for (int y = 0; y < model.h; ++y) {
    const size_t row = size_t(nearest_index(y, H, model.h)) * size_t(W);
    for (int x = 0; x < model.w; ++x)
      labels[size_t(y) * model.w + x] = planes.labels[row + size_t(nearest_index(x, W, model.w))];
  }
  std::vector<CompositeView> out;
  for (size_t r = 0; r < ref_sizes.size(); ++r) {
    CompositeView v;
    v.ref = int(r);
    v.reference = ref_names[r];
    v.crop.assign(size_t(std::max(P, 1)), -1);
    bool any = false;
    for (size_t c = 0; c < crops.size(); ++c)
      if (crops[c].ref == int(r) && crops[c].plane >= 0 && crops[c].plane < P) {
        MACRO_CHECK(crops[c].view == model);  // full crops only
        v.crop[size_t(crops[c].plane)] = int(c);
        any = true;
      }
    if (!any) continue;
    std::vector<std::vector<uint8_t>> crop_valid(v.crop.size());
    for (size_t p = 0; p < v.crop.size(); ++p)
      if (v.crop[p] >= 0)
        crop_valid[p] =
            crop_view_validity(crops[size_t(v.crop[p])], ref_sizes[r].w, ref_sizes[r].h);
    v.labels = labels;
    v.valid.assign(hw, 0);
    v.plane_pixels.assign(v.crop.size(), 0);
    v.valid_pixels.assign(v.crop.size(), 0);
    for (size_t k = 0; k < hw; ++k) {
      const size_t s = size_t(v.source_plane(k));
      ++v.plane_pixels[s];
      if (v.crop[s] >= 0 && crop_valid[s][k]) {
        v.valid[k] = 1;
        ++v.valid_pixels[s];
      }
    }
    out.push_back(std::move(v));
  }
  return out;
}

gs::Image composite_view_image(const CompositeView& v, const std::vector<gs::Image>& crop_views,
                               Size2 model) {
  const size_t hw = size_t(model.w) * size_t(model.h);
  MACRO_CHECK(v.labels.size() == hw && v.valid.size() == hw);
  gs::Image out(model.w, model.h, 3);
  for (size_t k = 0; k < hw; ++k) {
    if (!v.valid[k]) continue;
    const gs::Image& src = crop_views[size_t(v.crop[size_t(v.source_plane(k))])];
    MACRO_CHECK(src.width == model.w && src.height == model.h && src.channels == 3);
    for (int ch = 0; ch < 3; ++ch) out.data[k * 3 + size_t(ch)] = src.data[k * 3 + size_t(ch)];
  }
  return out;
}

}  // namespace macro::enhance
