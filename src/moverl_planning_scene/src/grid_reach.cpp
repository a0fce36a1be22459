/**
 * \file grid_reach.cpp
 * \brief GridReach: the steps from each cell to the nearest marked cell, as layers of bit sets (grid_reach.h).
 */
#include "moverl_planning_scene/grid_reach.h"

#include <algorithm>
#include <cstdlib>

namespace moverl_planning_scene {
namespace {

constexpr int kBlockShift = 2;  // blocks of 4^3 cells (OccupancyMap::kBlockBits)

/// The 26 neighbours and the set itself: one cell along z, then y, then x (separable); the result in *a.
void dilateOnce(const std::int64_t* size, const std::vector<std::uint64_t>& in, std::vector<std::uint64_t>* a,
                std::vector<std::uint64_t>* b) {
  dilateBits(in, 1, b);
  dilateBits(*b, size[2], a);
  dilateBits(*a, size[1] * size[2], b);
  a->swap(*b);
}

/// The same on a grid of bytes (the blocks), x-major, z fastest: along each axis a pass over contiguous runs.
void dilateBlocksOnce(const std::int64_t* n, std::vector<std::uint8_t>* set, std::vector<std::uint8_t>* tmp) {
  tmp->resize(set->size());
  for (int axis = 2; axis >= 0; --axis) {
    const std::uint8_t* in = set->data();
    std::uint8_t* out = tmp->data();
    // Cell (outer, c, inner) along the axis: outer over the axes before it, inner (contiguous) over the ones after.
    std::int64_t outer = 1, inner = 1;
    for (int a = 0; a < axis; ++a) outer *= n[a];
    for (int a = axis + 1; a < 3; ++a) inner *= n[a];
    const std::int64_t len = n[axis];
    for (std::int64_t o = 0; o < outer; ++o) {
      for (std::int64_t c = 0; c < len; ++c) {
        const std::int64_t row = (o * len + c) * inner;
        const std::uint8_t* lo = c > 0 ? in + row - inner : nullptr;
        const std::uint8_t* hi = c + 1 < len ? in + row + inner : nullptr;
        for (std::int64_t i = 0; i < inner; ++i) {
          std::uint8_t v = in[row + i];
          if (lo != nullptr) v |= lo[i];
          if (hi != nullptr) v |= hi[i];
          out[row + i] = v;
        }
      }
    }
    set->swap(*tmp);
  }
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
                      const std::vector<std::uint64_t>& blocked, int cells,
                      const std::vector<std::uint8_t>& block_marked, int levels) {
  for (int a = 0; a < 3; ++a) {
    size_[a] = size[a];
    blocks_[a] = size[a] > 0 ? ((size[a] - 1) >> kBlockShift) + 1 : 0;
  }
  cells_ = std::max(0, cells);
  levels_ = std::max(0, levels);
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
  // The blocks: the ring (Chebyshev, in blocks) of the nearest marked one, grown one ring at a time.
  block_rings_.assign(block_marked.size(), static_cast<std::uint8_t>(std::min(levels_ + 1, 255)));
  if (levels_ == 0) return;
  block_scratch_a_.assign(block_marked.size(), 0);
  for (std::size_t b = 0; b < block_marked.size(); ++b) {
    if (block_marked[b] != 0) block_scratch_a_[b] = 1, block_rings_[b] = 0;
  }
  for (int g = 1; g <= std::min(levels_, 254); ++g) {
    dilateBlocksOnce(blocks_, &block_scratch_a_, &block_scratch_b_);
    for (std::size_t b = 0; b < block_rings_.size(); ++b) {
      if (block_scratch_a_[b] != 0 && block_rings_[b] > g) block_rings_[b] = static_cast<std::uint8_t>(g);
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
  if (levels_ > 0) {
    const std::int64_t bi = i >> kBlockShift, bj = j >> kBlockShift, bk = k >> kBlockShift;
    const int ring = block_rings_[static_cast<std::size_t>((bi * blocks_[1] + bj) * blocks_[2] + bk)];
    // No marked block within g rings (g >= 1: ring 1 holds the cell's own block's neighbours and itself) puts the
    // nearest marked cell at least g x 4 + 1 steps away.
    const int clear = std::max(1, ring) - 1;
    bound = std::max(bound, clear * (1 << kBlockShift) + 1);
  }
  return std::min(bound, e);
}

}  // namespace moverl_planning_scene
