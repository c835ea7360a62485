// PlayCanvas / SuperSplat SOG: meta.json plus lossless WebP images, as a folder or as the members
// of one .sog zip. Images are decoded with libwebp to RGBA; Gaussian i is pixel i in row-major
// order. Version 2 (meta.json "version": 2):
//   means   means_l / means_u: 16 bits per axis, u = l + 256 * h (R, G, B = x, y, z);
//           v = mins + (maxs - mins) * u / 65535, then position = sign(v) * (exp(|v|) - 1)
//   quats   R, G, B = the three smaller components of (w, x, y, z) in that order, each
//           (b / 255 * 2 - 1) / sqrt(2); A = 252 + index of the largest, which is made positive
//           and rebuilt as sqrt(1 - sum of squares). Other A values give the identity.
//   scales  R, G, B index the 256-entry codebook of log scales
//   sh0     R, G, B index the codebook of f_dc values; A / 255 is the opacity (after the sigmoid)
//   shN     optional: labels (R | G << 8 = palette entry) and centroids (64 entries per row, each
//           (K - 1) pixels wide, R, G, B of coefficient j at x = (entry % 64) * (K - 1) + j,
//           y = entry / 64) indexing the shN codebook; "bands" gives the degree, "count" the
//           palette size.
// Version 1 (no "version" field): count = means.shape[0]; scales, sh0 and shN are lerps between
// "mins" and "maxs" (sh0's fourth channel is an opacity logit) and the SH degree follows from the
// centroid image's width (192, 512, 960).
// Values are stored in the frame of the .ply they were made from (RDF for Inria scenes).
#include <webp/decode.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <nlohmann/json.hpp>

#include "attention/runtime/file_io.h"
#include "attention/runtime/io/zip_reader.h"
#include "gs/formats/scene_formats.h"

namespace macro::gs::formats {
namespace {

using nlohmann::json;

struct Image {
  int width = 0, height = 0;
  std::vector<uint8_t> rgba;
  const uint8_t* px(size_t i) const { return rgba.data() + i * 4; }
};

// Image members are plain names next to meta.json: no folders, no "..".
Status check_member_name(const std::string& name, const std::string& what) {
  if (name.empty() || name.find('/') != std::string::npos || name.find('\\') != std::string::npos ||
      name == "." || name == "..")
    return Status::error(what + ": expected a file name next to meta.json, found '" +
                         printable_name(name) + "'");
  return Status::ok();
}

Result<Image> load_image(const SogMemberReader& read, const std::string& name,
                         const std::string& file, size_t min_pixels) {
  const std::string what = file + ": " + printable_name(name);
  MACRO_TRY(check_member_name(name, file + ": meta.json file name"));
  MACRO_ASSIGN_OR_RETURN(std::vector<uint8_t> bytes, read(name));
  Image img;
  if (!WebPGetInfo(bytes.data(), bytes.size(), &img.width, &img.height))
    return Status::error(what + ": not a WebP image (" + std::to_string(bytes.size()) +
                         " bytes; header unreadable)");
  const uint64_t pixels = uint64_t(img.width) * uint64_t(img.height);
  if (pixels < min_pixels)
    return Status::error(what + ": image of " + std::to_string(img.width) + "x" +
                         std::to_string(img.height) + " pixels, expected at least " +
                         std::to_string(min_pixels));
  // Bounded: a SOG image holds one pixel per Gaussian (or palette entry); allow a square's slack.
  if (pixels > 4 * uint64_t(min_pixels) + (1u << 20))
    return Status::error(what + ": image of " + std::to_string(img.width) + "x" +
                         std::to_string(img.height) + " pixels, far more than the " +
                         std::to_string(min_pixels) + " it should hold");
  img.rgba.resize(static_cast<size_t>(pixels) * 4);
  if (!WebPDecodeRGBAInto(bytes.data(), bytes.size(), img.rgba.data(), img.rgba.size(),
                          img.width * 4))
    return Status::error(what + ": corrupt WebP image (decoding failed)");
  return img;
}

// meta.json accessors: each names the field and what was expected.
Result<const json*> member(const json& j, const char* key, const std::string& where) {
  if (!j.is_object() || !j.contains(key))
    return Status::error(where + ": missing field '" + key + "'");
  return &j[key];
}

Result<std::vector<float>> numbers(const json& j, const char* key, size_t n,
                                   const std::string& where) {
  MACRO_ASSIGN_OR_RETURN(const json* v, member(j, key, where));
  if (!v->is_array() || v->size() != n)
    return Status::error(where + "." + key + ": expected an array of " + std::to_string(n) +
                         " numbers, found " +
                         (v->is_array() ? std::to_string(v->size()) + " entries" : v->type_name()));
  std::vector<float> out(n);
  for (size_t i = 0; i < n; ++i) {
    if (!(*v)[i].is_number())
      return Status::error(where + "." + key + "[" + std::to_string(i) +
                           "]: expected a number, found " + (*v)[i].type_name());
    out[i] = (*v)[i].get<float>();
    if (!std::isfinite(out[i]))
      return Status::error(where + "." + key + "[" + std::to_string(i) + "]: not finite");
  }
  return out;
}

Result<float> number(const json& j, const char* key, const std::string& where) {
  MACRO_ASSIGN_OR_RETURN(const json* v, member(j, key, where));
  if (!v->is_number()) return Status::error(where + "." + key + ": expected a number");
  return v->get<float>();
}

Result<std::string> file_at(const json& j, size_t index, const std::string& where) {
  MACRO_ASSIGN_OR_RETURN(const json* v, member(j, "files", where));
  if (!v->is_array() || v->size() <= index || !(*v)[index].is_string())
    return Status::error(where + ".files: expected at least " + std::to_string(index + 1) +
                         " file names");
  return (*v)[index].get<std::string>();
}

Result<size_t> count_field(const json& v, const std::string& where, const LoadLimits& limits) {
  if (!v.is_number_integer() || v.get<int64_t>() < 0)
    return Status::error(where + ": expected a non-negative integer count");
  const uint64_t n = v.get<uint64_t>();
  if (n > limits.max_gaussians)
    return Status::error(where + ": " + std::to_string(n) + " Gaussians exceed the limit of " +
                         std::to_string(limits.max_gaussians) + " (--max-gaussians)");
  return static_cast<size_t>(n);
}

float inv_log(float v) {
  const float e = std::exp(std::abs(v)) - 1.f;
  return v < 0 ? -e : e;
}

// Value lookup for one byte: a codebook (v2) or a lerp between min and max (v1).
struct Dequant {
  std::vector<float> codebook;  // 256 entries (v2), empty for v1
  float lo = 0, hi = 0;
  float operator()(uint8_t b) const {
    return codebook.empty() ? lo + (hi - lo) * (b / 255.f) : codebook[b];
  }
};

}  // namespace

Result<GaussianCloud> decode_sog(const SogMemberReader& read, const std::string& file,
                                 const LoadLimits& limits) {
  MACRO_ASSIGN_OR_RETURN(std::vector<uint8_t> meta_bytes, read("meta.json"));
  const std::string where = file + ": meta.json";
  const json meta = json::parse(meta_bytes.begin(), meta_bytes.end(), nullptr, false);
  if (meta.is_discarded()) return Status::error(where + ": not valid JSON (truncated?)");
  if (!meta.is_object()) return Status::error(where + ": expected a JSON object");
  int version = 1;
  if (meta.contains("version")) {
    if (!meta["version"].is_number_integer() || meta["version"].get<int64_t>() != 2)
      return Status::error(where + ": unsupported SOG version " + meta["version"].dump() +
                           " (this reader supports 1 and 2)");
    version = 2;
  }
  MACRO_ASSIGN_OR_RETURN(const json* means, member(meta, "means", where));
  size_t N = 0;
  if (version == 2) {
    MACRO_ASSIGN_OR_RETURN(const json* c, member(meta, "count", where));
    MACRO_ASSIGN_OR_RETURN(N, count_field(*c, where + ".count", limits));
  } else {
    MACRO_ASSIGN_OR_RETURN(const json* shape, member(*means, "shape", where + ".means"));
    if (!shape->is_array() || shape->empty())
      return Status::error(where + ".means.shape: expected [count, 3]");
    MACRO_ASSIGN_OR_RETURN(N, count_field((*shape)[0], where + ".means.shape[0]", limits));
  }
  MACRO_ASSIGN_OR_RETURN(std::vector<float> mins, numbers(*means, "mins", 3, where + ".means"));
  MACRO_ASSIGN_OR_RETURN(std::vector<float> maxs, numbers(*means, "maxs", 3, where + ".means"));

  // Per-attribute value maps.
  auto dequant = [&](const json& j, const char* name, int channel,
                     const std::string& w) -> Result<Dequant> {
    Dequant d;
    if (version == 2) {
      MACRO_ASSIGN_OR_RETURN(d.codebook, numbers(j, "codebook", 256, w));
      return d;
    }
    if (channel < 0) {  // one scalar range (v1 shN)
      MACRO_ASSIGN_OR_RETURN(d.lo, number(j, "mins", w));
      MACRO_ASSIGN_OR_RETURN(d.hi, number(j, "maxs", w));
      return d;
    }
    const size_t n = std::string(name) == "sh0" ? 4 : 3;
    MACRO_ASSIGN_OR_RETURN(std::vector<float> lo, numbers(j, "mins", n, w));
    MACRO_ASSIGN_OR_RETURN(std::vector<float> hi, numbers(j, "maxs", n, w));
    d.lo = lo[static_cast<size_t>(channel)];
    d.hi = hi[static_cast<size_t>(channel)];
    return d;
  };

  MACRO_ASSIGN_OR_RETURN(const json* quats, member(meta, "quats", where));
  MACRO_ASSIGN_OR_RETURN(const json* scales, member(meta, "scales", where));
  MACRO_ASSIGN_OR_RETURN(const json* sh0, member(meta, "sh0", where));
  std::array<Dequant, 3> scale_q, colour_q;
  Dequant opacity_logit_q;
  for (int c = 0; c < 3; ++c) {
    MACRO_ASSIGN_OR_RETURN(scale_q[c], dequant(*scales, "scales", c, where + ".scales"));
    MACRO_ASSIGN_OR_RETURN(colour_q[c], dequant(*sh0, "sh0", c, where + ".sh0"));
  }
  if (version == 1) {
    MACRO_ASSIGN_OR_RETURN(opacity_logit_q, dequant(*sh0, "sh0", 3, where + ".sh0"));
  }

  // SH bands above 0.
  const json* shn = meta.contains("shN") ? &meta["shN"] : nullptr;
  int degree = 0;
  size_t palette = 0;
  Dequant sh_q;
  Image centroids, labels;
  if (shn) {
    const std::string w = where + ".shN";
    MACRO_ASSIGN_OR_RETURN(std::string cname, file_at(*shn, 0, w));
    MACRO_ASSIGN_OR_RETURN(std::string lname, file_at(*shn, 1, w));
    MACRO_ASSIGN_OR_RETURN(labels, load_image(read, lname, file, N));
    if (version == 2) {
      MACRO_ASSIGN_OR_RETURN(const json* bands, member(*shn, "bands", w));
      if (!bands->is_number_integer() || bands->get<int64_t>() < 0 || bands->get<int64_t>() > 3)
        return Status::error(w + ".bands: expected 0..3, found " + bands->dump());
      degree = bands->get<int>();
      MACRO_ASSIGN_OR_RETURN(const json* pc, member(*shn, "count", w));
      if (!pc->is_number_integer() || pc->get<int64_t>() < 0 || pc->get<int64_t>() > 65536)
        return Status::error(w + ".count: expected a palette size 0..65536, found " + pc->dump());
      palette = pc->get<size_t>();
      MACRO_ASSIGN_OR_RETURN(sh_q, dequant(*shn, "shN", -1, w));
    } else {
      MACRO_ASSIGN_OR_RETURN(sh_q, dequant(*shn, "shN", -1, w));
    }
    const size_t rows_hint = degree > 0 ? (palette + 63) / 64 : 0;
    const size_t coeffs_hint = size_t((degree + 1) * (degree + 1) - 1);
    MACRO_ASSIGN_OR_RETURN(
        centroids, load_image(read, cname, file, version == 2 ? rows_hint * 64 * coeffs_hint : 1));
    if (version == 1) {
      const int w1 = centroids.width;
      degree = w1 == 192 ? 1 : w1 == 512 ? 2 : w1 == 960 ? 3 : -1;
      if (degree < 0)
        return Status::error(file + ": " + printable_name(cname) +
                             ": centroid image width: expected 192, 512 or 960 (SH degree 1-3), "
                             "found " +
                             std::to_string(w1));
      palette = size_t(centroids.width / (degree == 1   ? 3
                                          : degree == 2 ? 8
                                                        : 15)) *
                size_t(centroids.height);
    }
    const size_t coeffs = size_t((degree + 1) * (degree + 1) - 1);
    if (degree > 0 && size_t(centroids.width) != 64 * coeffs)
      return Status::error(file + ": " + printable_name(cname) + ": centroid image width: " +
                           "expected " + std::to_string(64 * coeffs) + " for SH degree " +
                           std::to_string(degree) + ", found " + std::to_string(centroids.width));
  }

  MACRO_ASSIGN_OR_RETURN(std::string ml, file_at(*means, 0, where + ".means"));
  MACRO_ASSIGN_OR_RETURN(std::string mu, file_at(*means, 1, where + ".means"));
  MACRO_ASSIGN_OR_RETURN(std::string qn, file_at(*quats, 0, where + ".quats"));
  MACRO_ASSIGN_OR_RETURN(std::string sn, file_at(*scales, 0, where + ".scales"));
  MACRO_ASSIGN_OR_RETURN(std::string cn, file_at(*sh0, 0, where + ".sh0"));
  MACRO_ASSIGN_OR_RETURN(Image lo, load_image(read, ml, file, N));
  MACRO_ASSIGN_OR_RETURN(Image hi, load_image(read, mu, file, N));
  MACRO_ASSIGN_OR_RETURN(Image qi, load_image(read, qn, file, N));
  MACRO_ASSIGN_OR_RETURN(Image si, load_image(read, sn, file, N));
  MACRO_ASSIGN_OR_RETURN(Image ci, load_image(read, cn, file, N));

  GaussianCloud cloud;
  cloud.resize(N, degree);
  const size_t K = static_cast<size_t>(cloud.sh_coeffs());
  const float inv_sqrt2 = 0.70710678118654752f;
  for (size_t i = 0; i < N; ++i) {
    const uint8_t *l = lo.px(i), *h = hi.px(i), *q = qi.px(i), *s = si.px(i), *c = ci.px(i);
    for (int a = 0; a < 3; ++a) {
      const float u = float(l[a] | h[a] << 8) / 65535.f;
      cloud.position[i * 3 + a] = inv_log(mins[a] + (maxs[a] - mins[a]) * u);
      cloud.scale[i * 3 + a] = std::exp(scale_q[a](s[a]));
      cloud.sh[i * K * 3 + a] = colour_q[a](c[a]);
    }
    cloud.opacity[i] = version == 2 ? c[3] / 255.f : sigmoid(opacity_logit_q(c[3]));
    float* r = &cloud.rotation[i * 4];
    if (q[3] < 252) {
      r[0] = 1.f, r[1] = r[2] = r[3] = 0.f;
    } else {
      const int largest = q[3] - 252;
      float sum = 0.f;
      for (int k = 0, j = 0; k < 4; ++k) {
        if (k == largest) continue;
        r[k] = (q[j++] / 255.f * 2.f - 1.f) * inv_sqrt2;
        sum += r[k] * r[k];
      }
      r[largest] = std::sqrt(std::max(0.f, 1.f - sum));
    }
    if (degree > 0) {
      const uint8_t* lab = labels.px(i);
      const size_t entry = size_t(lab[0]) | size_t(lab[1]) << 8;
      if (entry >= palette) continue;  // no palette entry: the bands stay zero
      const size_t coeffs = K - 1;
      const size_t x0 = (entry % 64) * coeffs, y = entry / 64;
      if (y >= size_t(centroids.height)) continue;
      for (size_t j = 0; j < coeffs; ++j) {
        const uint8_t* p = centroids.px(y * size_t(centroids.width) + x0 + j);
        for (size_t ch = 0; ch < 3; ++ch) cloud.sh[(i * K + 1 + j) * 3 + ch] = sh_q(p[ch]);
      }
    }
  }
  return cloud;
}

Result<GaussianCloud> decode_sog_zip(const uint8_t* data, size_t size, const std::string& file,
                                     const LoadLimits& limits) {
  MACRO_ASSIGN_OR_RETURN(std::vector<ZipEntry> entries, read_zip_directory(data, size, file));
  auto read = [&](const std::string& name) -> Result<std::vector<uint8_t>> {
    for (const ZipEntry& e : entries) {
      if (e.name != name) continue;
      if (e.method == 0)
        return std::vector<uint8_t>(data + e.data_offset, data + e.data_offset + e.size);
      MACRO_TRY(check_inflated_size(e, file));
      std::vector<uint8_t> out(static_cast<size_t>(e.size));
      MACRO_TRY(inflate_zip_record(data, e, out.data(), file));
      return out;
    }
    return Status::error(file + ": the .sog archive has no member '" + printable_name(name) + "'");
  };
  return decode_sog(read, file, limits);
}

Result<GaussianCloud> decode_sog_folder(const std::string& folder, const LoadLimits& limits) {
  auto read = [&](const std::string& name) -> Result<std::vector<uint8_t>> {
    return read_file(folder + "/" + name, limits.max_file_bytes);
  };
  return decode_sog(read, folder, limits);
}

}  // namespace macro::gs::formats
