// Scene file detection, dispatch to the per-format decoders/encoders (gs/formats/scene_formats.h),
// and the one sanitize pass every loaded cloud goes through (the bad-value policy in scene_io.h).
#include "gs/formats/scene_io.h"

#include <fcntl.h>
#include <sys/mman.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstring>

#include "attention/runtime/file_io.h"
#include "attention/runtime/io/zip_reader.h"
#include "attention/runtime/io/zip_writer.h"
#include "attention/runtime/progress.h"
#include "gs/formats/ply_reader.h"
#include "gs/formats/scene_formats.h"

namespace macro::gs {
namespace {

std::string lower_extension(const std::string& name) {
  const size_t slash = name.find_last_of('/');
  const size_t dot = name.find_last_of('.');
  if (dot == std::string::npos || (slash != std::string::npos && dot < slash)) return "";
  std::string ext = name.substr(dot);
  std::transform(ext.begin(), ext.end(), ext.begin(),
                 [](unsigned char c) { return std::tolower(c); });
  return ext;
}

bool ends_with(const std::string& s, const std::string& tail) {
  return s.size() >= tail.size() && s.compare(s.size() - tail.size(), tail.size(), tail) == 0;
}

// Drops Gaussians with non-finite values, repairs quaternions and scales (policy in scene_io.h).
// A file whose every Gaussian is dropped is an error (it names the first bad field), not an empty
// scene: a file with zero Gaussians to begin with still loads.
Status sanitize(GaussianCloud& c, LoadReport& report, const std::string& file) {
  const size_t N = c.size();
  const size_t K3 = static_cast<size_t>(c.sh_coeffs()) * 3;
  size_t kept = 0;
  const char* first_bad = nullptr;  // field of the first dropped Gaussian, for the message
  for (size_t i = 0; i < N; ++i) {
    const char* bad = nullptr;
    for (size_t a = 0; a < 3 && !bad; ++a)
      if (!std::isfinite(c.position[i * 3 + a])) bad = "position";
    for (size_t a = 0; a < 3 && !bad; ++a)
      if (!std::isfinite(c.scale[i * 3 + a])) bad = "scale";
    for (size_t a = 0; a < 4 && !bad; ++a)
      if (!std::isfinite(c.rotation[i * 4 + a])) bad = "rotation";
    if (!bad && !std::isfinite(c.opacity[i])) bad = "opacity";
    for (size_t j = 0; j < K3 && !bad; ++j)
      if (!std::isfinite(c.sh[i * K3 + j])) bad = "colour (SH)";
    if (bad) {
      if (!first_bad) first_bad = bad;
      ++report.dropped_nonfinite;
      continue;
    }
    if (kept != i) {
      std::copy_n(&c.position[i * 3], 3, &c.position[kept * 3]);
      std::copy_n(&c.scale[i * 3], 3, &c.scale[kept * 3]);
      std::copy_n(&c.rotation[i * 4], 4, &c.rotation[kept * 4]);
      std::copy_n(&c.sh[i * K3], K3, &c.sh[kept * K3]);
      c.opacity[kept] = c.opacity[i];
    }
    float* q = &c.rotation[kept * 4];
    const double n2 =
        double(q[0]) * q[0] + double(q[1]) * q[1] + double(q[2]) * q[2] + double(q[3]) * q[3];
    if (!(n2 > 1e-30)) {
      q[0] = 1.f, q[1] = q[2] = q[3] = 0.f;
      ++report.fixed_quaternions;
    } else if (n2 != 1.0) {
      const double inv = 1.0 / std::sqrt(n2);
      for (int a = 0; a < 4; ++a) q[a] = static_cast<float>(q[a] * inv);
    }
    float* s = &c.scale[kept * 3];
    bool clamped = false;
    for (int a = 0; a < 3; ++a) {
      if (s[a] > 0.f) continue;
      s[a] = std::max(std::abs(s[a]), kMinScale);
      clamped = true;
    }
    report.clamped_scales += clamped;
    c.opacity[kept] = std::clamp(c.opacity[kept], 0.f, 1.f);
    ++kept;
  }
  if (kept != N) {
    c.position.resize(kept * 3);
    c.scale.resize(kept * 3);
    c.rotation.resize(kept * 4);
    c.sh.resize(kept * K3);
    c.opacity.resize(kept);
  }
  if (report.dropped_nonfinite || report.fixed_quaternions || report.clamped_scales) {
    log_info("load",
             file + ": dropped " + std::to_string(report.dropped_nonfinite) +
                 " Gaussians with NaN/Inf values, set " + std::to_string(report.fixed_quaternions) +
                 " zero quaternions to identity, clamped " + std::to_string(report.clamped_scales) +
                 " Gaussians' zero/negative scales (docs/formats.md)");
  }
  if (N > 0 && kept == 0)
    return Status::error(file + ": all " + std::to_string(N) +
                         " Gaussians have NaN/Inf values (the first in field '" + first_bad +
                         "'), nothing is left to render");
  return Status::ok();
}

}  // namespace

const char* scene_format_name(SceneFormat format) {
  switch (format) {
    case SceneFormat::kPly:
      return "ply";
    case SceneFormat::kCompressedPly:
      return "compressed.ply";
    case SceneFormat::kSplat:
      return "splat";
    case SceneFormat::kSpz:
      return "spz";
    case SceneFormat::kSog:
      return "sog";
    case SceneFormat::kGsplatCheckpoint:
      return "gsplat checkpoint";
  }
  return "?";
}

Result<SceneFormat> detect_scene_format(const uint8_t* data, size_t size, const std::string& name) {
  const std::string ext = lower_extension(name);
  if (size == 0) return Status::error(name + ": empty file");
  if (ext == ".splat") return SceneFormat::kSplat;  // headerless: the extension decides
  if (ply::looks_like_ply(data, size)) {
    MACRO_ASSIGN_OR_RETURN(ply::Header header, ply::parse_header(data, size, name));
    return formats::is_compressed_ply(header) ? SceneFormat::kCompressedPly : SceneFormat::kPly;
  }
  if (formats::is_gzip(data, size) || formats::is_spz_v4(data, size) || ext == ".spz")
    return SceneFormat::kSpz;
  if (ext == ".sog") return SceneFormat::kSog;  // the zip reader names what is wrong
  if (size >= 4 && le32(data) == kZipLocalHeaderSig) {
    // A zip: SOG if it holds meta.json, else a torch checkpoint (the loader names what is missing).
    Result<std::vector<ZipEntry>> entries = read_zip_directory(data, size, name);
    if (!entries) return entries.status();
    for (const ZipEntry& e : *entries)
      if (e.name == "meta.json") return SceneFormat::kSog;
    return SceneFormat::kGsplatCheckpoint;
  }
  if (ext == ".ply") return SceneFormat::kPly;  // the PLY parser names what is wrong
  if (ext == ".pt" || ext == ".pth" || ext == ".ckpt") return SceneFormat::kGsplatCheckpoint;
  return Status::error(name +
                       ": unknown scene format: expected a PLY header, a .spz (gzip or 'NGSP'), "
                       "a zip (.sog, gsplat .pt) or the extension .splat (found extension '" +
                       ext + "')");
}

Result<GaussianCloud> load_scene_from_memory(const uint8_t* data, size_t size,
                                             const std::string& name, const LoadLimits& limits,
                                             LoadReport* report_out) {
  LoadReport report;
  MACRO_ASSIGN_OR_RETURN(SceneFormat format, detect_scene_format(data, size, name));
  report.format = format;
  Result<GaussianCloud> cloud = Status::error("unreachable");
  switch (format) {
    case SceneFormat::kPly:
    case SceneFormat::kCompressedPly: {
      MACRO_ASSIGN_OR_RETURN(ply::Header header, ply::parse_header(data, size, name));
      cloud = format == SceneFormat::kPly
                  ? formats::decode_ply(header, data, size, name, limits, report)
                  : formats::decode_compressed_ply(header, data, size, name, limits, report);
      break;
    }
    case SceneFormat::kSplat:
      cloud = formats::decode_splat(data, size, name, limits);
      break;
    case SceneFormat::kSpz:
      cloud = formats::decode_spz(data, size, name, limits, report);
      break;
    case SceneFormat::kSog:
      cloud = formats::decode_sog_zip(data, size, name, limits);
      break;
    case SceneFormat::kGsplatCheckpoint:
      cloud = formats::decode_gsplat_checkpoint(data, size, name, limits);
      break;
  }
  if (!cloud) return cloud.status();
  MACRO_TRY(sanitize(*cloud, report, name));
  if (report_out) *report_out = report;
  return cloud;
}

Result<GaussianCloud> load_scene(const std::string& path, const LoadLimits& limits,
                                 LoadReport* report) {
  // A SOG folder, or its meta.json: the images are separate files next to it.
  struct stat dir_st {};
  const bool is_dir = ::stat(path.c_str(), &dir_st) == 0 && S_ISDIR(dir_st.st_mode);
  if (is_dir || ends_with(path, "/meta.json") || path == "meta.json") {
    std::string folder = path;
    if (!is_dir) folder = path.size() > 10 ? path.substr(0, path.size() - 10) : ".";
    LoadReport r;
    r.format = SceneFormat::kSog;
    MACRO_ASSIGN_OR_RETURN(GaussianCloud cloud, formats::decode_sog_folder(folder, limits));
    MACRO_TRY(sanitize(cloud, r, path));
    if (report) *report = r;
    return cloud;
  }
  // Map the file read-only: no copy and no fresh pages for a 250 MB .ply. Anything that cannot be
  // mapped (a pipe, an empty file) goes through read_file, which names the problem.
  const int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
  struct stat st {};
  if (fd >= 0 && ::fstat(fd, &st) == 0 && S_ISREG(st.st_mode) && st.st_size > 0) {
    const uint64_t size = static_cast<uint64_t>(st.st_size);
    if (size > limits.max_file_bytes) {
      ::close(fd);
      return Status::error(path + ": file of " + std::to_string(size) +
                           " bytes exceeds the limit "
                           "of " +
                           std::to_string(limits.max_file_bytes) + " bytes");
    }
    void* map = ::mmap(nullptr, size, PROT_READ, MAP_PRIVATE, fd, 0);
    ::close(fd);
    if (map != MAP_FAILED) {
      ::madvise(map, size, MADV_SEQUENTIAL);
      auto cloud =
          load_scene_from_memory(static_cast<const uint8_t*>(map), size, path, limits, report);
      ::munmap(map, size);
      return cloud;
    }
  } else if (fd >= 0) {
    ::close(fd);
  }
  MACRO_ASSIGN_OR_RETURN(std::vector<uint8_t> bytes, read_file(path, limits.max_file_bytes));
  return load_scene_from_memory(bytes.data(), bytes.size(), path, limits, report);
}

namespace {
Status check_consistent(const GaussianCloud& cloud, const std::string& name) {
  const size_t N = cloud.size();
  const size_t K =
      cloud.sh_degree < 0 || cloud.sh_degree > 3 ? 0 : static_cast<size_t>(cloud.sh_coeffs());
  if (K == 0 || cloud.position.size() != N * 3 || cloud.scale.size() != N * 3 ||
      cloud.rotation.size() != N * 4 || cloud.sh.size() != N * K * 3)
    return Status::error(name + ": inconsistent GaussianCloud (array sizes do not match " +
                         std::to_string(N) + " Gaussians of SH degree " +
                         std::to_string(cloud.sh_degree) + ")");
  return Status::ok();
}
}  // namespace

Result<std::vector<uint8_t>> encode_scene(const GaussianCloud& cloud, SceneFormat format,
                                          const std::string& name, const SaveOptions& options) {
  MACRO_TRY(check_consistent(cloud, name));
  switch (format) {
    case SceneFormat::kPly:
      return formats::encode_ply(cloud, name);
    case SceneFormat::kSplat:
      return formats::encode_splat(cloud, name);
    case SceneFormat::kSpz:
      return formats::encode_spz(cloud, name, options.spz_version);
    case SceneFormat::kSog: {
      MACRO_ASSIGN_OR_RETURN(std::vector<ZipMember> members,
                             formats::encode_sog_members(cloud, name, options.sog_iterations));
      return write_zip_stored(members, name);
    }
    case SceneFormat::kCompressedPly:
    case SceneFormat::kGsplatCheckpoint:
      break;
  }
  return Status::error(name + ": writing " + scene_format_name(format) +
                       " is not supported (use .ply, .splat, .spz, .sog or meta.json)");
}

bool is_sog_folder_output(const std::string& path) {
  return path == "meta.json" || ends_with(path, "/meta.json");
}

namespace {
// A SOG folder: each image written atomically next to meta.json, meta.json last, so a reader never
// finds a meta.json naming images that are not there yet.
Status save_sog_folder(const GaussianCloud& cloud, const std::string& path,
                       const SaveOptions& options) {
  const size_t slash = path.find_last_of('/');
  const std::string folder = slash == std::string::npos ? "." : path.substr(0, slash);
  MACRO_TRY(check_consistent(cloud, path));
  if (!is_directory(folder))
    return Status::error(path + ": the SOG folder '" + folder + "' does not exist");
  MACRO_ASSIGN_OR_RETURN(std::vector<ZipMember> members,
                         formats::encode_sog_members(cloud, path, options.sog_iterations));
  for (const ZipMember& m : members)
    MACRO_TRY(write_file_atomic(folder + "/" + m.name, m.bytes.data(), m.bytes.size()));
  return Status::ok();
}
}  // namespace

Status save_scene(const GaussianCloud& cloud, const std::string& path, const SaveOptions& options) {
  const std::string ext = lower_extension(path);
  SceneFormat format;
  if (ends_with(path, ".compressed.ply"))
    format = SceneFormat::kCompressedPly;
  else if (ext == ".ply")
    format = SceneFormat::kPly;
  else if (ext == ".splat")
    format = SceneFormat::kSplat;
  else if (ext == ".spz")
    format = SceneFormat::kSpz;
  else if (ext == ".sog")
    format = SceneFormat::kSog;
  else if (is_sog_folder_output(path))
    return save_sog_folder(cloud, path, options);
  else if (ext == ".pt" || ext == ".pth" || ext == ".ckpt")
    format = SceneFormat::kGsplatCheckpoint;
  else
    return Status::error(path + ": unknown output extension '" + ext +
                         "' (expected .ply, .splat, .spz, .sog, or a file named meta.json for a "
                         "SOG folder)");
  MACRO_ASSIGN_OR_RETURN(std::vector<uint8_t> bytes, encode_scene(cloud, format, path, options));
  return write_file_atomic(path, bytes.data(), bytes.size());
}

}  // namespace macro::gs
