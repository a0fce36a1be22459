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

/// out |= in shifted by `by` cells (toward higher cell ids when by > 0). Bits shifted past a row's (plane's) end land
/// in cells next to the grid's edge, whose steps the edge bounds anyway (steps()).
void orShifted(const std::vector<std::uint64_t>& in, std::int64_t by, std::vector<std::uint64_t>* out) {
  const auto n = static_cast<std::int64_t>(in.size());
  const std::int64_t q = std::llabs(by) >> 6;
  const int r = static_cast<int>(std::llabs(by) & 63);
  std::vector<std::uint64_t>& o = *out;
  if (by > 0) {
    for (std::int64_t w = q; w < n; ++w) {
      std::uint64_t v = in[w - q] << r;
      if (r != 0 && w - q - 1 >= 0) v |= in[w - q - 1] >> (64 - r);
      o[w] |= v;
    }
  } else {
    for (std::int64_t w = 0; w + q < n; ++w) {
      std::uint64_t v = in[w + q] >> r;
      if (r != 0 && w + q + 1 < n) v |= in[w + q + 1] << (64 - r);
      o[w] |= v;
    }
  }
}

/// The 26 neighbours and the set itself: one cell along z, then y, then x (separable).
void dilateOnce(const std::int64_t* size, std::vector<std::uint64_t>* set, std::vector<std::uint64_t>* tmp) {
  const std::int64_t strides[3] = {1, size[2], size[1] * size[2]};
  for (std::int64_t stride : strides) {
    tmp->assign(set->begin(), set->end());
    orShifted(*set, stride, tmp);
    orShifted(*set, -stride, tmp);
    set->swap(*tmp);
  }
}

/// The same on a grid of bytes (the blocks), x-major, z fastest.
void dilateBlocksOnce(const std::int64_t* n, std::vector<std::uint8_t>* set, std::vector<std::uint8_t>* tmp) {
  for (int axis = 2; axis >= 0; --axis) {
    tmp->assign(set->size(), 0);
    std::int64_t at[3];
    for (at[0] = 0; at[0] < n[0]; ++at[0]) {
      for (at[1] = 0; at[1] < n[1]; ++at[1]) {
        for (at[2] = 0; at[2] < n[2]; ++at[2]) {
          const std::int64_t b = (at[0] * n[1] + at[1]) * n[2] + at[2];
          if ((*set)[b] == 0) continue;
          (*tmp)[b] = 1;
          std::int64_t q[3] = {at[0], at[1], at[2]};
          for (int d = -1; d <= 1; d += 2) {
            q[axis] = at[axis] + d;
            if (q[axis] >= 0 && q[axis] < n[axis]) (*tmp)[(q[0] * n[1] + q[1]) * n[2] + q[2]] = 1;
          }
        }
      }
    }
    set->swap(*tmp);
  }
}

}  // namespace

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
  std::vector<std::uint64_t> prev = marked;
  for (int s = 0; s < cells_; ++s) {
    scratch_a_ = prev;
    dilateOnce(size_, &scratch_a_, &scratch_b_);
    std::vector<std::uint64_t>& layer = layers_[static_cast<std::size_t>(s)];
    layer.resize(prev.size());
    for (std::size_t w = 0; w < prev.size(); ++w) {
      const std::uint64_t stop = w < blocked.size() ? blocked[w] : 0;
      layer[w] = prev[w] | (scratch_a_[w] & ~stop);
    }
    prev = layer;
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
