// The schedules of gsplat's simple_trainer (docs/training.md §2.5): the means' learning-rate
// decay, the per-epoch view order and the active SH degree.
#pragma once

#include <cstddef>
#include <cstdint>
#include <vector>

namespace macro::gs::train {

// gsplat's ExponentialLR(gamma = 0.01^(1 / max_steps)) on the means optimizer, stepped after
// every optimizer step: the rate used at step s (0-based) is lr0 * 0.01^(s / max_steps); at
// s = max_steps it is 0.01 lr0. max_steps <= 0 gives 1.
double means_lr_factor(int step, int max_steps);

// min(step / interval, degree) (integer division); interval <= 0: every band from the start.
int active_sh_degree(int step, int interval, int degree);

// The view of every step, as a DataLoader with shuffle=True: each epoch (V consecutive steps) a
// fresh uniform permutation of 0..V-1 (Fisher-Yates over one SplitMix64 stream seeded by `seed`).
// Our generator is not torch's, so the order is not gsplat's, only its kind.
class ViewOrder {
 public:
  ViewOrder(size_t views, bool shuffled, uint64_t seed);
  size_t next();  // the view of the next step
  // The position in the order (checkpoints): the current permutation, the place in it and the
  // generator's state.
  struct Snapshot {
    std::vector<size_t> perm;
    size_t pos = 0;
    uint64_t state = 0;
  };
  Snapshot snapshot() const { return {perm_, pos_, state_}; }
  // false when the snapshot is not one of this order (another view count).
  bool restore(const Snapshot& s);

 private:
  std::vector<size_t> perm_;
  size_t pos_;
  bool shuffled_;
  uint64_t state_;
};

}  // namespace macro::gs::train
