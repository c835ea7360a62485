// gsplat's schedules (schedule.h).
#include "gs/train/schedule.h"

#include <algorithm>
#include <cmath>
#include <numeric>

#include "gs/synth/synth_random.h"

namespace macro::gs::train {

double means_lr_factor(int step, int max_steps) {
  if (max_steps <= 0) return 1.0;
  // torch multiplies by gamma once per step; the closed form differs from it only by rounding.
  return std::pow(0.01, double(step) / double(max_steps));
}

int active_sh_degree(int step, int interval, int degree) {
  if (interval <= 0) return degree;
  return std::min(step / interval, degree);
}

ViewOrder::ViewOrder(size_t views, bool shuffled, uint64_t seed)
    : perm_(views), pos_(views), shuffled_(shuffled), state_(seed) {
  std::iota(perm_.begin(), perm_.end(), size_t(0));
}

bool ViewOrder::restore(const Snapshot& s) {
  if (s.perm.size() != perm_.size() || s.pos > perm_.size()) return false;
  for (size_t v : s.perm)
    if (v >= perm_.size()) return false;
  perm_ = s.perm;
  pos_ = s.pos;
  state_ = s.state;
  return true;
}

size_t ViewOrder::next() {
  if (perm_.empty()) return 0;
  if (pos_ == perm_.size()) {
    pos_ = 0;
    if (shuffled_) {
      synth_random::Rng rng{state_};
      std::iota(perm_.begin(), perm_.end(), size_t(0));
      for (size_t i = perm_.size() - 1; i > 0; --i) {
        // Unbiased index in [0, i]: rejection on the top of the 64-bit range.
        const uint64_t bound = uint64_t(i) + 1;
        const uint64_t limit = ~uint64_t(0) - (~uint64_t(0) % bound);
        uint64_t r;
        do r = rng.next();
        while (r >= limit);
        std::swap(perm_[i], perm_[size_t(r % bound)]);
      }
      state_ = rng.state;
    }
  }
  return perm_[pos_++];
}

}  // namespace macro::gs::train
