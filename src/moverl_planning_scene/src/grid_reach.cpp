/**
 * \file grid_reach.cpp
 * \brief GridReach: the steps from each cell to the nearest marked cell, as layers of bit sets (grid_reach.h).
 */
#include "moverl_planning_scene/grid_reach.h"

#include <algorithm>
#include <cstdlib>

namespace moverl_planning_scene {
namespace {

/// The 26 neighbours and the set itself: one cell along z, then y, then x (separable); the result in *a.
void dilateOnce(const std::int64_t* size, const std::vector<std::uint64_t>& in, std::vector<std::uint64_t>* a,
                std::vector<std::uint64_t>* b) {
  dilateBits(in, 1, b);
  dilateBits(*b, size[2], a);
  dilateBits(*a, size[1] * size[2], b);
  a->swap(*b);
}

}  // namespace

void dilateBits(const std::vector<std::uint64_t>& in, std::int64_t stride, std::vector<std::uint64_t>* out) {
  const auto n = static_cast<std::int64_t>(in.size());
  const std::int64_t q = stride >> 6;
  const int r = static_cast<int>(stride & 63);
  out->resize(in.size());
  std::uint64_t* o = out->data();
  const std::uint64_t* a = in.data();
  auto word = [&](std::int64_t w) {  // (every bound checked: the words next to the set's ends)
    std::uint64_t v = a[w];
    if (w - q >= 0) v |= r == 0 ? a[w - q] : (a[w - q] << r) | (w - q - 1 >= 0 ? a[w - q - 1] >> (64 - r) : 0);
    if (w + q < n) v |= r == 0 ? a[w + q] : (a[w + q] >> r) | (w + q + 1 < n ? a[w + q + 1] << (64 - r) : 0);
    return v;
  };
  // The words whose neighbours all lie in the set, without a branch (vectorised), then the ends.
  const std::int64_t first = std::min(n, q + 1), last = std::max(first, n - q - 1);
  if (r == 0) {
    for (std::int64_t w = first; w < last; ++w) o[w] = a[w] | a[w - q] | a[w + q];
  } else {
    for (std::int64_t w = first; w < last; ++w)
      o[w] = a[w] | (a[w - q] << r) | (a[w - q - 1] >> (64 - r)) | (a[w + q] >> r) | (a[w + q + 1] << (64 - r));
  }
  for (std::int64_t w = 0; w < first; ++w) o[w] = word(w);
  for (std::int64_t w = last; w < n; ++w) o[w] = word(w);
}

void GridReach::build(const std::int64_t size[3], const std::vector<std::uint64_t>& marked,
                      const std::vector<std::uint64_t>& blocked, int cells, int far) {
  for (int a = 0; a < 3; ++a) size_[a] = size[a];
  cells_ = std::max(0, cells);
  far_ = std::max(far, cells_ + 1);
  layers_.resize(static_cast<std::size_t>(cells_));
  const std::vector<std::uint64_t>* prev = &marked;
  for (int s = 0; s < cells_; ++s) {
    dilateOnce(size_, *prev, &scratch_a_, &scratch_b_);
    std::vector<std::uint64_t>& layer = layers_[static_cast<std::size_t>(s)];
    layer.resize(prev->size());
    for (std::size_t w = 0; w < layer.size(); ++w) {
      const std::uint64_t stop = w < blocked.size() ? blocked[w] : 0;
      layer[w] = (*prev)[w] | (scratch_a_[w] & ~stop);
    }
    prev = &layer;
  }
  near_.clear();
  if (far_ <= cells_ + 1) return;
  // The marked cells dilated by far - 1 along each axis, in doubling passes: a set dilated by d, or'ed with itself
  // shifted by +-r (r <= d + 1), is the set dilated by d + r.
  near_ = marked;
  const std::int64_t strides[3] = {1, size_[2], size_[1] * size_[2]};
  for (std::int64_t stride : strides) {
    for (int done = 0; done < far_ - 1;) {
      const int r = std::min(done + 1, far_ - 1 - done);
      dilateBits(near_, stride * r, &scratch_a_);
      near_.swap(scratch_a_);
      done += r;
    }
  }
}

int GridReach::steps(std::int64_t i, std::int64_t j, std::int64_t k) const {
  // The outside is e steps away (the straight way out, blocked or not: a lower bound on the way around).
  const std::int64_t e64 = std::min({i + 1, j + 1, k + 1, size_[0] - i, size_[1] - j, size_[2] - k});
  const int e = static_cast<int>(std::max<std::int64_t>(1, e64));
  const std::int64_t c = (i * size_[1] + j) * size_[2] + k;
  const int exact = std::min(cells_, e - 1);
  for (int s = 1; s <= exact; ++s) {
    if (((layers_[static_cast<std::size_t>(s - 1)][static_cast<std::size_t>(c >> 6)] >> (c & 63)) & 1u) != 0) return s;
  }
  if (e <= cells_) return e;
  int bound = cells_ + 1;
  // Farther than far - 1 (Chebyshev) from every marked cell: at least far steps. (A bit carried across a row's end by
  // the dilation's shifts lies within far - 1 of the grid's edge, where e bounds anyway.)
  if (!near_.empty() && ((near_[static_cast<std::size_t>(c >> 6)] >> (c & 63)) & 1u) == 0) bound = far_;
  return std::min(bound, e);
}

}  // namespace moverl_planning_scene
