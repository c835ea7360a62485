// PlayCanvas / SuperSplat SOG version 2 writer: the layout of format_sog.cpp's reader, made the way
// splat-transform makes it (docs/formats.md §PlayCanvas / SuperSplat SOG):
//   - Gaussians in Morton order of their positions, pixel i = Gaussian order[i]; images
//     ceil(sqrt(N) / 4) * 4 wide and ceil(N / width / 4) * 4 high (at least 4 x 4)
//   - means: v = sign(x) log(|x| + 1) per axis, 16 bits between the axis' mins and maxs
//   - quats: unit (w, x, y, z), the largest |component| made positive, the other three in order
//     times sqrt(2) mapped to bytes, A = 252 + index of the largest
//   - scales, sh0: 256-entry codebooks (codebook_1d over the three axes' log scales, over the three
//     f_dc channels); sh0's A = opacity * 255
//   - shN: a palette of the Gaussians' rest coefficients (each Gaussian its own entry when N <=
//     65536, else 65536 k-means centroids), the palette's values through a 256-entry codebook
// Images are lossless WebP with `exact` set, so colours under alpha 0 (opacity 0) survive.
#include <webp/encode.h>

#include <algorithm>
#include <cmath>
#include <nlohmann/json.hpp>

#include "attention/runtime/progress.h"
#include "attention/runtime/thread_pool.h"
#include "gs/formats/scene_formats.h"
#include "gs/formats/sog_quantize.h"

namespace macro::gs::formats {
namespace {

using nlohmann::json;

constexpr size_t kMaxPalette = 65536;
constexpr int kMaxWebpSide = 16383;

struct Image {
  std::string name;
  int width = 0, height = 0;
  std::vector<uint8_t> rgba;
};

Result<std::vector<uint8_t>> encode_webp(const Image& img, const std::string& file) {
  const std::string what = file + ": " + img.name;
  WebPConfig config;
  if (!WebPConfigInit(&config)) return Status::error(what + ": libwebp version mismatch");
  config.lossless = 1;
  config.quality = 70;  // the effort WebPEncodeLosslessRGBA uses
  config.exact = 1;
  WebPPicture pic;
  if (!WebPPictureInit(&pic)) return Status::error(what + ": libwebp version mismatch");
  pic.use_argb = 1;
  pic.width = img.width;
  pic.height = img.height;
  WebPMemoryWriter writer;
  WebPMemoryWriterInit(&writer);
  pic.writer = WebPMemoryWrite;
  pic.custom_ptr = &writer;
  const bool ok =
      WebPPictureImportRGBA(&pic, img.rgba.data(), img.width * 4) && WebPEncode(&config, &pic);
  const int err = pic.error_code;
  WebPPictureFree(&pic);
  std::vector<uint8_t> out;
  if (ok) out.assign(writer.mem, writer.mem + writer.size);
  WebPMemoryWriterClear(&writer);
  if (!ok)
    return Status::error(what + ": WebP encoding of a " + std::to_string(img.width) + "x" +
                         std::to_string(img.height) + " image failed (libwebp error " +
                         std::to_string(err) + ")");
  return out;
}

double log_transform(double x) {
  return x < 0 ? -std::log(-x + 1.0) : std::log(x + 1.0);
}

uint8_t to_byte(double v) {  // v in [0, 255]
  return uint8_t(std::clamp(std::lround(v), 0l, 255l));
}

// A Gaussian the format cannot hold: any non-finite value, a scale that is not positive.
Status check_values(const GaussianCloud& c, const std::string& file) {
  const size_t N = c.size(), K3 = size_t(c.sh_coeffs()) * 3;
  for (size_t i = 0; i < N; ++i) {
    auto bad = [&](const char* field, float v, const char* expected) {
      return Status::error(file + ": Gaussian " + std::to_string(i) + ": " + field + " " +
                           std::to_string(v) + ", expected " + expected + " (SOG cannot store it)");
    };
    for (size_t a = 0; a < 3; ++a)
      if (!std::isfinite(c.position[i * 3 + a]))
        return bad("position", c.position[i * 3 + a], "a finite value");
    for (size_t a = 0; a < 3; ++a)
      if (!std::isfinite(c.scale[i * 3 + a]) || !(c.scale[i * 3 + a] > 0.f))
        return bad("scale", c.scale[i * 3 + a], "a finite positive value");
    for (size_t a = 0; a < 4; ++a)
      if (!std::isfinite(c.rotation[i * 4 + a]))
        return bad("rotation", c.rotation[i * 4 + a], "a finite value");
    if (!std::isfinite(c.opacity[i])) return bad("opacity", c.opacity[i], "a finite value");
    for (size_t j = 0; j < K3; ++j)
      if (!std::isfinite(c.sh[i * K3 + j]))
        return bad("colour (SH)", c.sh[i * K3 + j], "a finite value");
  }
  return Status::ok();
}

}  // namespace

Result<std::vector<ZipMember>> encode_sog_members(const GaussianCloud& cloud,
                                                  const std::string& file, int iterations) {
  MACRO_TRY(check_values(cloud, file));
  const size_t N = cloud.size();
  const size_t K = size_t(cloud.sh_coeffs());
  const int width = std::max(4, int(std::ceil(std::sqrt(double(N)) / 4.0)) * 4);
  const int height = std::max(4, int(std::ceil(double(N) / double(width) / 4.0)) * 4);
  if (width > kMaxWebpSide || height > kMaxWebpSide)
    return Status::error(file + ": " + std::to_string(N) + " Gaussians need " +
                         std::to_string(width) + "x" + std::to_string(height) +
                         " images, beyond WebP's 16383 pixels per side");
  const size_t pixels = size_t(width) * size_t(height);
  auto image = [&](const char* name) {
    Image img{name, width, height, std::vector<uint8_t>(pixels * 4, 0)};
    for (size_t p = 0; p < pixels; ++p) img.rgba[p * 4 + 3] = 255;
    return img;
  };
  const std::vector<uint32_t> order = morton_order(cloud.position);
  std::vector<Image> images;

  // means
  double mins[3] = {0, 0, 0}, maxs[3] = {0, 0, 0};
  for (size_t a = 0; a < 3; ++a) {
    if (N == 0) break;
    mins[a] = maxs[a] = log_transform(cloud.position[a]);
    for (size_t i = 0; i < N; ++i) {
      const double v = log_transform(cloud.position[i * 3 + a]);
      mins[a] = std::min(mins[a], v);
      maxs[a] = std::max(maxs[a], v);
    }
    // The reader computes in float: store the float range it will read.
    mins[a] = double(float(mins[a]));
    maxs[a] = double(float(maxs[a]));
  }
  Image means_l = image("means_l.webp"), means_u = image("means_u.webp");
  for (size_t p = 0; p < N; ++p) {
    const size_t g = order[p];
    for (size_t a = 0; a < 3; ++a) {
      const double range = maxs[a] - mins[a];
      const double t = range > 0 ? (log_transform(cloud.position[g * 3 + a]) - mins[a]) / range : 0;
      const uint32_t u = uint32_t(std::clamp(std::lround(t * 65535.0), 0l, 65535l));
      means_l.rgba[p * 4 + a] = uint8_t(u & 0xff);
      means_u.rgba[p * 4 + a] = uint8_t(u >> 8);
    }
  }
  images.push_back(std::move(means_l));
  images.push_back(std::move(means_u));

  // quats
  Image quats = image("quats.webp");
  const double sqrt2 = std::sqrt(2.0);
  for (size_t p = 0; p < N; ++p) {
    const float* r = &cloud.rotation[size_t(order[p]) * 4];
    double q[4], len = 0;
    for (int k = 0; k < 4; ++k) q[k] = r[k], len += q[k] * q[k];
    len = std::sqrt(len);
    if (!(len > 0)) q[0] = 1, q[1] = q[2] = q[3] = 0, len = 1;  // no rotation: the identity
    int largest = 0;
    for (int k = 1; k < 4; ++k)
      if (std::abs(q[k]) > std::abs(q[largest])) largest = k;
    const double s = (q[largest] < 0 ? -1.0 : 1.0) * sqrt2 / len;
    for (int k = 0, j = 0; k < 4; ++k) {
      if (k == largest) continue;
      quats.rgba[p * 4 + size_t(j++)] = to_byte(255.0 * (q[k] * s * 0.5 + 0.5));
    }
    quats.rgba[p * 4 + 3] = uint8_t(252 + largest);
  }
  images.push_back(std::move(quats));

  // scales and sh0: one codebook over the three columns each.
  auto columns_codebook = [&](const char* name, auto value_of, std::vector<float>& codebook) {
    std::vector<float> values(N * 3);
    for (size_t i = 0; i < N; ++i)
      for (size_t a = 0; a < 3; ++a) values[i * 3 + a] = value_of(i, a);
    codebook = codebook_1d(values, 256);
    Image img = image(name);
    for (size_t p = 0; p < N; ++p)
      for (size_t a = 0; a < 3; ++a)
        img.rgba[p * 4 + a] = uint8_t(nearest_entry(codebook, values[size_t(order[p]) * 3 + a]));
    return img;
  };
  std::vector<float> scale_cb, colour_cb;
  images.push_back(columns_codebook(
      "scales.webp", [&](size_t i, size_t a) { return std::log(cloud.scale[i * 3 + a]); },
      scale_cb));
  Image sh0 = columns_codebook(
      "sh0.webp", [&](size_t i, size_t a) { return cloud.sh[i * K * 3 + a]; }, colour_cb);
  for (size_t p = 0; p < N; ++p)
    sh0.rgba[p * 4 + 3] = to_byte(std::clamp(double(cloud.opacity[order[p]]), 0.0, 1.0) * 255.0);
  images.push_back(std::move(sh0));

  json meta;
  meta["version"] = 2;
  meta["asset"] = {{"generator", "macro"}};
  meta["count"] = N;
  meta["means"] = {{"mins", {mins[0], mins[1], mins[2]}},
                   {"maxs", {maxs[0], maxs[1], maxs[2]}},
                   {"files", {"means_l.webp", "means_u.webp"}}};
  meta["scales"] = {{"codebook", scale_cb}, {"files", {"scales.webp"}}};
  meta["quats"] = {{"files", {"quats.webp"}}};
  meta["sh0"] = {{"codebook", colour_cb}, {"files", {"sh0.webp"}}};

  // shN: the palette, its values through a codebook, the labels.
  if (cloud.sh_degree > 0 && N > 0) {
    const size_t coeffs = K - 1, dim = coeffs * 3;
    const KMeansResult pal =
        kmeans(cloud.sh.data() + 3, N, dim, K * 3, std::min(N, kMaxPalette), iterations,
               0x50c5eedull, "sog: SH palette (k-means)", ThreadPool::global());
    const size_t entries = pal.centroids.size() / dim;
    const std::vector<float> sh_cb = codebook_1d(pal.centroids, 256);
    const int rows = int((entries + 63) / 64);
    Image centroids{"shN_centroids.webp", int(64 * coeffs), rows,
                    std::vector<uint8_t>(size_t(rows) * 64 * coeffs * 4, 0)};
    for (size_t px = 0; px < centroids.rgba.size() / 4; ++px) centroids.rgba[px * 4 + 3] = 255;
    for (size_t e = 0; e < entries; ++e)
      for (size_t j = 0; j < coeffs; ++j) {
        uint8_t* px = &centroids.rgba[(e * coeffs + j) * 4];  // 64 entries per row, row-major
        for (size_t ch = 0; ch < 3; ++ch)
          px[ch] = uint8_t(nearest_entry(sh_cb, pal.centroids[e * dim + j * 3 + ch]));
      }
    Image labels = image("shN_labels.webp");
    for (size_t p = 0; p < N; ++p) {
      const uint32_t l = pal.labels[order[p]];
      labels.rgba[p * 4 + 0] = uint8_t(l & 0xff);
      labels.rgba[p * 4 + 1] = uint8_t(l >> 8);
    }
    images.push_back(std::move(centroids));
    images.push_back(std::move(labels));
    meta["shN"] = {{"count", entries},
                   {"bands", cloud.sh_degree},
                   {"codebook", sh_cb},
                   {"files", {"shN_centroids.webp", "shN_labels.webp"}}};
  }

  // Encode the images side by side.
  std::vector<ZipMember> members(images.size() + 1);
  std::vector<Status> status(images.size(), Status::ok());
  Progress progress("sog: WebP images", images.size(), 0.5);
  ThreadPool::global().parallel_for(
      images.size(),
      [&](size_t b, size_t e, int) {
        for (size_t i = b; i < e; ++i) {
          Result<std::vector<uint8_t>> bytes = encode_webp(images[i], file);
          if (bytes)
            members[i] = {images[i].name, std::move(*bytes)};
          else
            status[i] = bytes.status();
          progress.advance();
        }
      },
      1);
  progress.finish();
  for (const Status& s : status) MACRO_TRY(s);
  const std::string text = meta.dump();
  members.back() = {"meta.json", std::vector<uint8_t>(text.begin(), text.end())};
  return members;
}

}  // namespace macro::gs::formats
