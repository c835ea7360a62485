// TAESD encoder/decoder: layout, loading by checkpoint name, forward on the shared conv kernels.
#include "attention/nets/taesd.h"

#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <set>

#include "attention/runtime/bundled_data.h"
#include "attention/runtime/file_io.h"
#include "attention/runtime/ops.h"

namespace macro::nets {

namespace {

constexpr int kHidden = 64;  // TAESD width (n_hidden)

TaesdLayer conv_layer(int64_t c_in, int64_t c_out, int stride, bool bias) {
  TaesdLayer l;
  l.kind = TaesdLayerKind::kConv;
  l.conv.c_in = c_in;
  l.conv.c_out = c_out;
  l.conv.stride = stride;
  l.conv.has_bias = bias;
  return l;
}

TaesdLayer block_layer() {
  TaesdLayer l;
  l.kind = TaesdLayerKind::kBlock;
  for (TaesdConv& c : l.block.conv) c = std::move(conv_layer(kHidden, kHidden, 1, true).conv);
  return l;
}

TaesdLayer simple_layer(TaesdLayerKind kind) {
  TaesdLayer l;
  l.kind = kind;
  return l;
}

void visit_conv(const std::string& name, TaesdConv& c, const TaesdNet::Visitor& fn) {
  fn(name + ".weight", Shape{c.c_out, c.c_in, 3, 3}, c.weight);
  if (c.has_bias) fn(name + ".bias", Shape{c.c_out}, c.bias);
}

void pack_conv(TaesdConv& c, Precision precision) {
  c.packed =
      ConvWeights::pack(c.weight.data(), c.has_bias ? c.bias.data() : nullptr, c.c_out, c.c_in, 3,
                        3, precision == Precision::kBf16 ? WeightType::kBf16 : WeightType::kF32);
  std::vector<float>().swap(c.weight);  // the packed copy is all forward() reads
}

// Physical memory, to refuse inputs whose scratch could never fit.
uint64_t physical_memory_bytes() {
  const long pages = ::sysconf(_SC_PHYS_PAGES), page = ::sysconf(_SC_PAGESIZE);
  if (pages <= 0 || page <= 0) return uint64_t(1) << 40;
  return uint64_t(pages) * uint64_t(page);
}

}  // namespace

// ---- layout ------------------------------------------------------------------------------------

TaesdNet TaesdNet::encoder_layout(int latent_channels) {
  TaesdNet n;
  n.c_in = 3;
  n.c_out = latent_channels;
  n.downscale = 8;
  auto& L = n.layers;
  L.push_back(conv_layer(3, kHidden, 1, true));  // 0
  L.push_back(block_layer());                    // 1
  for (int stage = 0; stage < 3; ++stage) {      // 2, 6, 10: conv s2 then 3 blocks
    L.push_back(conv_layer(kHidden, kHidden, 2, false));
    for (int b = 0; b < 3; ++b) L.push_back(block_layer());
  }
  L.push_back(conv_layer(kHidden, latent_channels, 1, true));  // 14
  return n;
}

TaesdNet TaesdNet::decoder_layout(int latent_channels) {
  TaesdNet n;
  n.c_in = latent_channels;
  n.c_out = 3;
  n.upscale = 8;
  auto& L = n.layers;
  L.push_back(simple_layer(TaesdLayerKind::kClamp));           // 0
  L.push_back(conv_layer(latent_channels, kHidden, 1, true));  // 1
  L.push_back(simple_layer(TaesdLayerKind::kRelu));            // 2
  for (int stage = 0; stage < 3; ++stage) {                    // 3-5 | 6 up, 7 conv | ...
    for (int b = 0; b < 3; ++b) L.push_back(block_layer());
    L.push_back(simple_layer(TaesdLayerKind::kUpsample));
    L.push_back(conv_layer(kHidden, kHidden, 1, false));
  }
  L.push_back(block_layer());                    // 18
  L.push_back(conv_layer(kHidden, 3, 1, true));  // 19
  return n;
}

// ---- loading -----------------------------------------------------------------------------------

void TaesdNet::visit(const std::string& prefix, const Visitor& fn) {
  for (size_t i = 0; i < layers.size(); ++i) {
    TaesdLayer& l = layers[i];
    const std::string name = prefix + std::to_string(i);
    if (l.kind == TaesdLayerKind::kConv) visit_conv(name, l.conv, fn);
    if (l.kind == TaesdLayerKind::kBlock)
      for (int j = 0; j < 3; ++j)
        visit_conv(name + ".conv." + std::to_string(2 * j), l.block.conv[j], fn);
  }
}

Status TaesdNet::load(const SafeTensors& file, const std::string& prefix, Precision precision) {
  std::vector<std::string> problems;
  std::set<std::string> used;
  visit(prefix, [&](const std::string& name, const Shape& shape, std::vector<float>& storage) {
    used.insert(name);
    const TensorEntry* e = file.find(name);
    if (!e) {
      problems.push_back("missing tensor '" + name + "' (expected shape " + shape_to_string(shape) +
                         ")");
      return;
    }
    if (e->shape != shape) {
      problems.push_back("tensor '" + name + "': expected shape " + shape_to_string(shape) +
                         ", found " + shape_to_string(e->shape));
      return;
    }
    storage.resize(size_t(shape_numel(shape)));
    Status s = convert_to_f32(*e, storage.data(), storage.size());
    if (!s) problems.push_back(s.message());
  });
  for (const std::string& n : file.names())
    if (n.compare(0, prefix.size(), prefix) == 0 && !used.count(n))
      problems.push_back("unused tensor '" + n + "'");
  if (!problems.empty()) {
    std::string msg = file.path() + ": ";
    for (size_t i = 0; i < problems.size() && i < 8; ++i) msg += (i ? "; " : "") + problems[i];
    if (problems.size() > 8) msg += "; and " + std::to_string(problems.size() - 8) + " more";
    return Status::error(msg);
  }
  pack(precision);
  return Status::ok();
}

void TaesdNet::pack(Precision precision) {
  for (TaesdLayer& l : layers) {
    if (l.kind == TaesdLayerKind::kConv) pack_conv(l.conv, precision);
    if (l.kind == TaesdLayerKind::kBlock)
      for (TaesdConv& c : l.block.conv) pack_conv(c, precision);
  }
}

// ---- forward -----------------------------------------------------------------------------------

Shape TaesdNet::output_shape(const Shape& in) const {
  MACRO_CHECK(in.size() == 4);
  if (downscale > 1) {
    int64_t h = in[2], w = in[3];
    for (const TaesdLayer& l : layers)
      if (l.kind == TaesdLayerKind::kConv && l.conv.stride == 2) h = (h + 1) / 2, w = (w + 1) / 2;
    return {in[0], c_out, h, w};
  }
  return {in[0], c_out, in[2] * upscale, in[3] * upscale};
}

size_t TaesdNet::scratch_bytes(const Shape& in) const {
  // The largest activation is kHidden channels at the larger of input/output resolution.
  const Shape out = output_shape(in);
  const int64_t hw = std::max(in[2] * in[3], out[2] * out[3]);
  const size_t one = Arena::footprint(size_t(in[0] * kHidden * hw) * sizeof(float));
  return one * 3;
}

void TaesdNet::forward(const TensorView& x, float* y, Arena& arena, ThreadPool* pool) const {
  MACRO_CHECK(x.rank == 4 && x.dim(1) == c_in && x.is_contiguous());
  const int64_t N = x.dim(0);
  const int64_t max_elems = int64_t((scratch_bytes(x.shape_vec()) / 3) / sizeof(float));
  const size_t mark = arena.mark();
  float* buf[3] = {arena.alloc_f32(max_elems), arena.alloc_f32(max_elems),
                   arena.alloc_f32(max_elems)};
  const float* cur = x.f32();
  int cur_idx = -1;  // -1: the caller's input
  int64_t C = c_in, H = x.dim(2), W = x.dim(3);
  auto other = [&](int not_a, int not_b = -1) {
    for (int i = 0; i < 3; ++i)
      if (i != not_a && i != not_b) return i;
    return -1;
  };
  // act(conv(src) (+ residual)) -> dst, the ReLU fused into the conv epilogue; shapes updated by
  // the caller.
  auto run_conv = [&](const TaesdConv& c, const float* src, int64_t h, int64_t w, float* dst,
                      const float* residual, ConvAct act = ConvAct::kNone) {
    const Conv2dShape s = Conv2dShape::make(N, c.c_in, h, w, c.c_out, 3, c.stride, 1);
    conv2d(s, src, c.packed, residual, dst, act, pool);
  };
  for (size_t i = 0; i < layers.size(); ++i) {
    const TaesdLayer& l = layers[i];
    const bool last = i + 1 == layers.size();
    switch (l.kind) {
      case TaesdLayerKind::kClamp: {  // tanh(x / 3) * 3, exactly as written in PyTorch
        const int d = other(cur_idx);
        const int64_t n = N * C * H * W;
        for (int64_t k = 0; k < n; ++k) buf[d][k] = std::tanh(cur[k] / 3.0f) * 3.0f;
        cur = buf[d], cur_idx = d;
        break;
      }
      case TaesdLayerKind::kConv: {
        const int d = other(cur_idx);
        float* dst = last ? y : buf[d];
        // A ReLU layer right after the conv runs in the conv's epilogue (and is skipped below).
        const bool relu_next = !last && layers[i + 1].kind == TaesdLayerKind::kRelu;
        run_conv(l.conv, cur, H, W, dst, nullptr, relu_next ? ConvAct::kRelu : ConvAct::kNone);
        const Conv2dShape s =
            Conv2dShape::make(N, l.conv.c_in, H, W, l.conv.c_out, 3, l.conv.stride, 1);
        C = l.conv.c_out, H = s.out_h(), W = s.out_w();
        cur = dst, cur_idx = last ? -1 : d;
        if (relu_next) ++i;
        break;
      }
      case TaesdLayerKind::kRelu:
        MACRO_CHECK(cur_idx >= 0);
        activation(buf[cur_idx], cur, N * C * H * W, Act::kRelu, pool);
        break;
      case TaesdLayerKind::kUpsample: {
        const int d = other(cur_idx);
        upsample_nearest(buf[d], cur, N * C, H, W, 2 * H, 2 * W, pool);
        H *= 2, W *= 2;
        cur = buf[d], cur_idx = d;
        break;
      }
      case TaesdLayerKind::kBlock: {
        MACRO_CHECK(cur_idx >= 0);
        float* xb = buf[cur_idx];
        float* t1 = buf[other(cur_idx)];
        float* t2 = buf[other(cur_idx, other(cur_idx))];
        run_conv(l.block.conv[0], xb, H, W, t1, nullptr, ConvAct::kRelu);  // [N,64,H,W]
        run_conv(l.block.conv[1], t1, H, W, t2, nullptr, ConvAct::kRelu);
        run_conv(l.block.conv[2], t2, H, W, xb, xb, ConvAct::kRelu);  // relu(conv.4(t2) + x)
        break;
      }
    }
  }
  MACRO_CHECK(cur == y);
  arena.reset(mark);
}

// ---- Taesd -------------------------------------------------------------------------------------

bool Taesd::is_taesd_folder(const std::string& folder) {
  return file_exists(folder + "/taesd_encoder.safetensors") ||
         file_exists(folder + "/taesd_decoder.safetensors");
}

std::string Taesd::default_folder() {
  return find_bundled_data("data/weights/taesd", "MACRO_TAESD", is_taesd_folder);
}

Result<Taesd> Taesd::load(const std::string& folder, Precision precision) {
  Taesd t;
  t.precision_ = precision;
  const std::string enc = folder + "/taesd_encoder.safetensors";
  const std::string dec = folder + "/taesd_decoder.safetensors";
  const std::string diffusers = folder + "/diffusion_pytorch_model.safetensors";
  if (file_exists(enc) || file_exists(dec)) {
    if (file_exists(enc)) {
      MACRO_ASSIGN_OR_RETURN(SafeTensors f, SafeTensors::open(enc));
      t.encoder_ = TaesdNet::encoder_layout();
      MACRO_TRY(t.encoder_.load(f, "", precision));
    }
    if (file_exists(dec)) {
      MACRO_ASSIGN_OR_RETURN(SafeTensors f, SafeTensors::open(dec));
      t.decoder_ = TaesdNet::decoder_layout();
      MACRO_TRY(t.decoder_.load(f, "", precision));
    }
    return t;
  }
  if (file_exists(diffusers)) {
    // diffusers AutoencoderTiny: encoder.layers.{i}.*, decoder.layers.{i-1}.* (no clamp layer).
    // Re-key into the published names, the one conversion this loader knows.
    MACRO_ASSIGN_OR_RETURN(SafeTensors f, SafeTensors::open(diffusers));
    t.encoder_ = TaesdNet::encoder_layout();
    t.decoder_ = TaesdNet::decoder_layout();
    for (auto* net : {&t.encoder_, &t.decoder_}) {
      const bool is_dec = net == &t.decoder_;
      std::vector<std::string> missing;
      net->visit("", [&](const std::string& name, const Shape& shape, std::vector<float>& st) {
        const size_t dot = name.find('.');
        const int idx = std::stoi(name.substr(0, dot)) - (is_dec ? 1 : 0);
        const std::string key = std::string(is_dec ? "decoder" : "encoder") + ".layers." +
                                std::to_string(idx) + name.substr(dot);
        const TensorEntry* e = f.find(key);
        if (!e || e->shape != shape) {
          missing.push_back(key + " " + shape_to_string(shape));
          return;
        }
        st.resize(size_t(shape_numel(shape)));
        (void)convert_to_f32(*e, st.data(), st.size());
      });
      if (!missing.empty())
        return Status::error(
            diffusers + ": missing or mis-shaped tensor '" + missing.front() + "'" +
            (missing.size() > 1 ? " and " + std::to_string(missing.size() - 1) + " more" : ""));
      net->pack(precision);
    }
    return t;
  }
  return Status::error(
      folder +
      ": not a TAESD folder (expected taesd_encoder.safetensors and "
      "taesd_decoder.safetensors, or diffusers' diffusion_pytorch_model.safetensors)");
}

namespace {

Result<Tensor> run_net(const TaesdNet& net, const TensorView& x, ThreadPool* pool,
                       const std::string& what, const char* expected) {
  if (net.layers.empty()) return Status::error(what + ": this TAESD folder has no " + expected);
  if (x.dtype != DType::kF32 || x.rank != 4 || x.dim(1) != net.c_in || x.dim(0) < 1 ||
      x.dim(2) < 1 || x.dim(3) < 1 || !x.is_contiguous())
    return Status::error(what + ": expected F32 [N," + std::to_string(net.c_in) + ",H,W], found " +
                         x.describe());
  const Shape in = x.shape_vec();
  const size_t scratch = net.scratch_bytes(in);
  if (scratch > physical_memory_bytes())
    return Status::error(what + ": " + x.describe() + " needs " + std::to_string(scratch >> 20) +
                         " MB of activations, more than this machine's memory");
  Tensor y = Tensor::f32(net.output_shape(in));
  Arena arena(scratch);
  net.forward(x, y.f32(), arena, pool);
  return y;
}

}  // namespace

Result<Tensor> Taesd::encode(const TensorView& image, ThreadPool* pool,
                             const std::string& what) const {
  return run_net(encoder_, image, pool, what, "encoder");
}

Result<Tensor> Taesd::decode(const TensorView& latent, ThreadPool* pool,
                             const std::string& what) const {
  return run_net(decoder_, latent, pool, what, "decoder");
}

}  // namespace macro::nets
