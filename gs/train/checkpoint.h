// Training checkpoints (`macro train --save-every N`, `--resume CKPT`; docs/training.md §2.11):
// the parameters and everything the loop carries between steps (TrainState: Adam moments, rates
// and step count, the view order's position and generator, the split and MCMC generators, the
// default strategy's grad2d / count, the mip 3D filter, the next step), so a resumed run ends
// with the same bits as an uninterrupted one.
//
// File (little-endian): "MACROCKPT\0" + u32 version (1); u32 length + the run's settings as text
// (key=value lines; a resume must match them); i32 next_step, i32 sh_degree, u64 N; the six
// parameter arrays (f32, SplatParams order); i32 Adam steps and per group: name, f64 lr, f64 m,
// f64 v; the view order (u64 count, u64 entries, u64 pos, u64 state); the split generator
// (u64 state, u8 has_spare, f64 spare); grad2d (f64 [N] or none), count (i32 [N] or none); MCMC
// (u64 sample state + a generator); the 3D filter (f32 [N] or none); u64 FNV-1a of all before.
#pragma once

#include <string>

#include "attention/runtime/status.h"
#include "gs/formats/splat_params.h"
#include "gs/train/trainer.h"

namespace macro::gs::train {

inline constexpr uint32_t kCheckpointVersion = 2;  // 2: float Adam moments

// OUT.ply -> OUT.ply.ckpt
std::string checkpoint_path_for(const std::string& out_path);

// Written atomically (a failure or an interrupt leaves the previous checkpoint in place).
Status write_checkpoint(const std::string& path, const std::string& settings,
                        const SplatParams& params, const TrainState& state);

struct Checkpoint {
  std::string settings;
  SplatParams params;
  TrainState state;
};
// Errors name the file and what is wrong: not a checkpoint, another version, truncated or
// corrupt (checksum), inconsistent sizes, or settings that differ from `settings` (the first
// differing key, with both values).
Result<Checkpoint> read_checkpoint(const std::string& path, const std::string& settings);

}  // namespace macro::gs::train
