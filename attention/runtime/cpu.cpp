#include "attention/runtime/cpu.h"

#include <cpuid.h>
#include <sys/syscall.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cstdio>
#include <cstdlib>
#include <cstring>

namespace macro {
namespace {

unsigned long long xgetbv0() {
  unsigned eax, edx;
  __asm__ volatile("xgetbv" : "=a"(eax), "=d"(edx) : "c"(0));
  return (static_cast<unsigned long long>(edx) << 32) | eax;
}

bool request_amx_permission() {
  // Linux >= 5.16: ARCH_REQ_XCOMP_PERM (0x1023) for XTILEDATA (feature 18).
  constexpr long kArchReqXcompPerm = 0x1023;
  constexpr long kXfeatureXtiledata = 18;
  return syscall(SYS_arch_prctl, kArchReqXcompPerm, kXfeatureXtiledata) == 0;
}

CpuFeatures detect() {
  CpuFeatures f;
  unsigned a, b, c, d;
  if (!__get_cpuid(1, &a, &b, &c, &d)) return f;
  const bool osxsave = c & (1u << 27);
  const bool fma = c & (1u << 12);
  const bool f16c = c & (1u << 29);
  const bool avx = c & (1u << 28);
  unsigned long long xcr0 = osxsave ? xgetbv0() : 0;
  const bool ymm_os = (xcr0 & 0x6) == 0x6;
  const bool zmm_os = (xcr0 & 0xe6) == 0xe6;
  const bool tile_os = (xcr0 & 0x60000) == 0x60000;
  unsigned b7 = 0, c7 = 0, d7 = 0, a7_1 = 0;
  if (__get_cpuid_count(7, 0, &a, &b, &c, &d)) {
    b7 = b;
    c7 = c;
    d7 = d;
  }
  if (__get_cpuid_count(7, 1, &a, &b, &c, &d)) a7_1 = a;
  (void)c7;
  const bool avx2 = b7 & (1u << 5);
  const bool bmi2 = b7 & (1u << 8);
  const bool avx512f = b7 & (1u << 16), avx512dq = b7 & (1u << 17);
  const bool avx512bw = b7 & (1u << 30), avx512vl = b7 & (1u << 31);
  const bool avx512bf16 = a7_1 & (1u << 5);
  const bool amx_bf16 = d7 & (1u << 22), amx_tile = d7 & (1u << 24);
  f.avx2 = avx && avx2 && fma && f16c && bmi2 && ymm_os;
  f.avx512 = f.avx2 && avx512f && avx512dq && avx512bw && avx512vl && zmm_os;
  f.avx512bf16 = f.avx512 && avx512bf16;
  f.amx = f.avx512bf16 && amx_tile && amx_bf16 && tile_os && request_amx_permission();
  char brand[49] = {0};
  for (unsigned i = 0; i < 3; ++i) {
    if (!__get_cpuid(0x80000002 + i, &a, &b, &c, &d)) break;
    std::memcpy(brand + 16 * i + 0, &a, 4);
    std::memcpy(brand + 16 * i + 4, &b, 4);
    std::memcpy(brand + 16 * i + 8, &c, 4);
    std::memcpy(brand + 16 * i + 12, &d, 4);
  }
  f.brand = brand;
  while (!f.brand.empty() && f.brand.back() == ' ') f.brand.pop_back();
  f.l1d = std::max(0L, sysconf(_SC_LEVEL1_DCACHE_SIZE));
  f.l2 = std::max(0L, sysconf(_SC_LEVEL2_CACHE_SIZE));
  return f;
}

std::atomic<int> g_isa{-1};

}  // namespace

const CpuFeatures& cpu_features() {
  static const CpuFeatures f = detect();
  return f;
}

long l2_block_bytes(long num, long den, long fallback, long l2_bytes) {
  const long l2 = l2_bytes < 0 ? cpu_features().l2 : l2_bytes;
  if (l2 <= 0 || num <= 0 || den <= 0) return fallback;
  return std::clamp(l2 / den * num, fallback / 2, 4 * fallback);
}

const char* isa_name(Isa isa) {
  switch (isa) {
    case Isa::kScalar: return "scalar";
    case Isa::kAvx2: return "avx2";
    case Isa::kAvx512: return "avx512";
    case Isa::kAvx512Bf16: return "avx512bf16";
    case Isa::kAmx: return "amx";
  }
  return "?";
}

Result<Isa> parse_isa(const std::string& name) {
  for (Isa isa : {Isa::kScalar, Isa::kAvx2, Isa::kAvx512, Isa::kAvx512Bf16, Isa::kAmx}) {
    if (name == isa_name(isa)) return isa;
  }
  return Status::error("ISA '" + name + "': expected one of scalar, avx2, avx512, avx512bf16, amx");
}

bool isa_supported(Isa isa) {
  const CpuFeatures& f = cpu_features();
  switch (isa) {
    case Isa::kScalar: return true;
    case Isa::kAvx2: return f.avx2;
    case Isa::kAvx512: return f.avx512;
    case Isa::kAvx512Bf16: return f.avx512bf16;
    case Isa::kAmx: return f.amx;
  }
  return false;
}

Isa best_isa() {
  for (Isa isa : {Isa::kAmx, Isa::kAvx512Bf16, Isa::kAvx512, Isa::kAvx2}) {
    if (isa_supported(isa)) return isa;
  }
  return Isa::kScalar;
}

Isa active_isa() {
  int v = g_isa.load();
  if (v >= 0) return static_cast<Isa>(v);
  Isa isa = best_isa();
  if (const char* env = std::getenv("MACRO_ISA"); env && *env) {
    auto parsed = parse_isa(env);
    if (!parsed) {
      std::fprintf(stderr, "macro: MACRO_ISA: %s; using %s\n", parsed.status().message().c_str(),
                   isa_name(isa));
    } else if (!isa_supported(*parsed)) {
      std::fprintf(stderr, "macro: MACRO_ISA=%s is not supported by this CPU; using %s\n", env,
                   isa_name(isa));
    } else {
      isa = *parsed;
    }
  }
  g_isa.store(static_cast<int>(isa));
  return isa;
}

Status set_isa(Isa isa) {
  if (!isa_supported(isa)) {
    return Status::error(std::string("ISA ") + isa_name(isa) + ": not supported by this CPU (" +
                         cpu_features().brand + ")");
  }
  g_isa.store(static_cast<int>(isa));
  return Status::ok();
}

}  // namespace macro
