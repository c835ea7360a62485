// Training checkpoints (checkpoint.h).
#include "gs/train/checkpoint.h"

#include <cmath>
#include <cstring>
#include <map>
#include <sstream>

#include "attention/runtime/file_io.h"

namespace macro::gs::train {
namespace {

constexpr char kMagic[10] = {'M', 'A', 'C', 'R', 'O', 'C', 'K', 'P', 'T', '\0'};

uint64_t fnv1a(const uint8_t* p, size_t n) {
  uint64_t h = 0xcbf29ce484222325ull;
  for (size_t i = 0; i < n; ++i) h = (h ^ p[i]) * 0x100000001b3ull;
  return h;
}

struct Writer {
  std::vector<uint8_t> b;
  template <typename T>
  void pod(const T& v) {
    const auto* p = reinterpret_cast<const uint8_t*>(&v);
    b.insert(b.end(), p, p + sizeof(T));
  }
  template <typename T>
  void array(const std::vector<T>& v) {
    pod(uint64_t(v.size()));
    const auto* p = reinterpret_cast<const uint8_t*>(v.data());
    b.insert(b.end(), p, p + v.size() * sizeof(T));
  }
  void text(const std::string& s) {
    pod(uint32_t(s.size()));
    b.insert(b.end(), s.begin(), s.end());
  }
};

struct Reader {
  const std::vector<uint8_t>& b;
  size_t pos = 0;
  bool ok = true;
  template <typename T>
  T pod() {
    T v{};
    if (pos + sizeof(T) > b.size()) {
      ok = false;
      return v;
    }
    std::memcpy(&v, b.data() + pos, sizeof(T));
    pos += sizeof(T);
    return v;
  }
  template <typename T>
  std::vector<T> array(uint64_t max_count) {
    const uint64_t n = pod<uint64_t>();
    std::vector<T> v;
    if (!ok || n > max_count || n * sizeof(T) > b.size() - pos) {
      ok = false;
      return v;
    }
    v.resize(size_t(n));
    std::memcpy(v.data(), b.data() + pos, size_t(n) * sizeof(T));
    pos += size_t(n) * sizeof(T);
    return v;
  }
  std::string text() {
    const uint32_t n = pod<uint32_t>();
    if (!ok || n > b.size() - pos) {
      ok = false;
      return {};
    }
    std::string s(reinterpret_cast<const char*>(b.data() + pos), n);
    pos += n;
    return s;
  }
};

std::map<std::string, std::string> parse_settings(const std::string& s) {
  std::map<std::string, std::string> out;
  std::istringstream in(s);
  std::string line;
  while (std::getline(in, line)) {
    const size_t eq = line.find('=');
    if (eq != std::string::npos) out[line.substr(0, eq)] = line.substr(eq + 1);
  }
  return out;
}

}  // namespace

std::string checkpoint_path_for(const std::string& out_path) {
  return out_path + ".ckpt";
}

Status write_checkpoint(const std::string& path, const std::string& settings,
                        const SplatParams& params, const TrainState& st) {
  Writer w;
  w.b.insert(w.b.end(), kMagic, kMagic + sizeof kMagic);
  w.pod(kCheckpointVersion);
  w.text(settings);
  w.pod(int32_t(st.next_step));
  w.pod(int32_t(params.sh_degree));
  w.pod(uint64_t(params.size()));
  for (const std::vector<float>* a :
       {&params.means, &params.scales, &params.quats, &params.opacities, &params.sh0, &params.shN})
    w.array(*a);
  w.pod(int32_t(st.adam_steps));
  w.pod(uint32_t(st.adam.size()));
  for (const TrainState::AdamGroup& g : st.adam) {
    w.text(g.name);
    w.pod(g.lr);
    w.array(g.m);
    w.array(g.v);
  }
  std::vector<uint64_t> perm(st.view_order.perm.begin(), st.view_order.perm.end());
  w.array(perm);
  w.pod(uint64_t(st.view_order.pos));
  w.pod(st.view_order.state);
  for (const NormalRng::Snapshot* r : {&st.split_rng, &st.mcmc_noise}) {
    w.pod(r->state);
    w.pod(uint8_t(r->have_spare));
    w.pod(r->spare);
  }
  w.array(st.default_state.grad2d);
  w.array(st.default_state.count);
  w.pod(st.mcmc_sample_state);
  w.array(st.filter_3d);
  w.pod(fnv1a(w.b.data(), w.b.size()));
  return write_file_atomic(path, w.b.data(), w.b.size());
}

Result<Checkpoint> read_checkpoint(const std::string& path, const std::string& settings) {
  MACRO_ASSIGN_OR_RETURN(std::vector<uint8_t> bytes, read_file(path));
  auto bad = [&](const std::string& what) {
    return Status::error("--resume: " + path + ": " + what);
  };
  if (bytes.size() < sizeof kMagic + 4 + 8 || std::memcmp(bytes.data(), kMagic, sizeof kMagic))
    return bad("not a training checkpoint (expected it to start with \"MACROCKPT\")");
  uint64_t stored_sum;
  std::memcpy(&stored_sum, bytes.data() + bytes.size() - 8, 8);
  Reader r{bytes, sizeof kMagic};
  const uint32_t version = r.pod<uint32_t>();
  if (version != kCheckpointVersion)
    return bad("checkpoint version " + std::to_string(version) + ", this build reads version " +
               std::to_string(kCheckpointVersion));
  if (fnv1a(bytes.data(), bytes.size() - 8) != stored_sum)
    return bad("checksum mismatch: the file is truncated or corrupt");
  Checkpoint c;
  c.settings = r.text();
  if (!r.ok) return bad("truncated settings");
  const auto have = parse_settings(c.settings), want = parse_settings(settings);
  for (const auto& [key, value] : want) {
    const auto it = have.find(key);
    const std::string found = it == have.end() ? "(absent)" : it->second;
    if (found != value)
      return bad("written by a run with " + key + " = " + found + ", this run has " + key + " = " +
                 value + " (resume with the same inputs and settings)");
  }
  TrainState& st = c.state;
  st.next_step = r.pod<int32_t>();
  const int32_t degree = r.pod<int32_t>();
  const uint64_t n = r.pod<uint64_t>();
  if (!r.ok || degree < 0 || degree > 3 || n > bytes.size())
    return bad("bad header (SH degree " + std::to_string(degree) + ", " + std::to_string(n) +
               " Gaussians)");
  SplatParams& p = c.params;
  p.resize(size_t(n), degree);
  const uint64_t cap = bytes.size();
  for (std::vector<float>* a : {&p.means, &p.scales, &p.quats, &p.opacities, &p.sh0, &p.shN}) {
    const size_t want_size = a->size();
    *a = r.array<float>(cap);
    if (!r.ok || a->size() != want_size)
      return bad("parameter arrays do not match " + std::to_string(n) + " Gaussians of SH degree " +
                 std::to_string(degree));
  }
  st.adam_steps = r.pod<int32_t>();
  const uint32_t groups = r.pod<uint32_t>();
  if (!r.ok || groups > 16) return bad("bad optimizer state");
  for (uint32_t i = 0; i < groups && r.ok; ++i) {
    TrainState::AdamGroup g;
    g.name = r.text();
    g.lr = r.pod<double>();
    g.m = r.array<float>(cap);
    g.v = r.array<float>(cap);
    st.adam.push_back(std::move(g));
  }
  const std::vector<uint64_t> perm = r.array<uint64_t>(cap);
  st.view_order.perm.assign(perm.begin(), perm.end());
  st.view_order.pos = size_t(r.pod<uint64_t>());
  st.view_order.state = r.pod<uint64_t>();
  for (NormalRng::Snapshot* s : {&st.split_rng, &st.mcmc_noise}) {
    s->state = r.pod<uint64_t>();
    s->have_spare = r.pod<uint8_t>() != 0;
    s->spare = r.pod<double>();
  }
  st.default_state.grad2d = r.array<double>(cap);
  st.default_state.count = r.array<int32_t>(cap);
  st.mcmc_sample_state = r.pod<uint64_t>();
  st.filter_3d = r.array<float>(cap);
  if (!r.ok || r.pos + 8 != bytes.size()) return bad("truncated or malformed state");
  const size_t N = size_t(n);
  if ((!st.default_state.grad2d.empty() && st.default_state.grad2d.size() != N) ||
      st.default_state.count.size() != st.default_state.grad2d.size() ||
      (!st.filter_3d.empty() && st.filter_3d.size() != N))
    return bad("strategy state or 3D filter does not match " + std::to_string(n) + " Gaussians");
  if (st.next_step < 0) return bad("negative step " + std::to_string(st.next_step));
  MACRO_TRY(p.check_shapes().with_context("--resume: " + path));
  return c;
}

}  // namespace macro::gs::train
