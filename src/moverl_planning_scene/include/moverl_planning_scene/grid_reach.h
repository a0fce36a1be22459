/**
 * \file grid_reach.h
 * \brief ROS-free: how many steps each cell of a grid lies from the nearest marked cell (or the grid's outside),
 *        stepping between neighbouring cells (26-connected) none of which is blocked. The hidden-space rule's distance
 *        (hidden_space.cpp): something that may be in a marked cell walks around a table (blocked cells), not through
 *        it, and (steps - 1) x resolution bounds from below how far it has to go.
 *
 * Exact up to `cells` steps: layer s is the marked cells grown s times by one step into the cells not blocked, each a
 * few shifts of the whole bit set (about 0.2 ms a step for the Panda's map). Beyond, a lower bound from the blocks of
 * 4^3 cells (blocked cells ignored): no marked block within g blocks (Chebyshev) puts the nearest marked cell at least
 * g x 4 + 1 steps away. The outside of the grid counts as marked (something may come in from there).
 */
#pragma once

#include <cstdint>
#include <vector>

namespace moverl_planning_scene {

/// \brief out = in | in shifted by +-stride bits (toward higher and lower bit ids), in one pass: a bit set of grid
///        cells (cell k is bit k & 63 of word k >> 6) grown by one step along the axis whose neighbours lie `stride`
///        cells apart (`stride` x r: r steps). Bits shifted past a row's (plane's) end land in the cells at the grid's
///        other edge: the callers treat the cells next to the edge as marked anyway.
void dilateBits(const std::vector<std::uint64_t>& in, std::int64_t stride, std::vector<std::uint64_t>* out);

class GridReach {
 public:
  /// \brief Build the layers.
  /// \param size cells per axis; cell (i, j, k) is bit (i size[1] + j) size[2] + k of marked and blocked (x-major, z
  ///        fastest, as OccupancyMap keeps its bit sets).
  /// \param cells steps computed exactly (one bit set each, kept here).
  /// \param block_marked per block of 4^3 cells, non-zero when the block holds a marked cell; blocks ceil(size / 4)
  ///        per axis, x-major, z fastest.
  /// \param levels block rings looked at beyond `cells` steps (0: none; the bound is then cells + 1).
  void build(const std::int64_t size[3], const std::vector<std::uint64_t>& marked,
             const std::vector<std::uint64_t>& blocked, int cells, const std::vector<std::uint8_t>& block_marked,
             int levels);
  /// \brief Steps from cell (i, j, k) to the nearest marked cell or the outside: exact when at most cells(), else a
  ///        lower bound above cells(). Meant for cells that are not blocked.
  int steps(std::int64_t i, std::int64_t j, std::int64_t k) const;
  int cells() const { return cells_; }

 private:
  std::int64_t size_[3] = {0, 0, 0}, blocks_[3] = {0, 0, 0};
  int cells_ = 0, levels_ = 0;
  std::vector<std::vector<std::uint64_t>> layers_;  ///< layers_[s - 1]: the cells within s steps
  std::vector<std::uint8_t> block_rings_;           ///< per block: the nearest marked block's ring, levels_ + 1 if none
  std::vector<std::uint64_t> scratch_a_, scratch_b_;
  std::vector<std::uint8_t> block_scratch_a_, block_scratch_b_;
};

}  // namespace moverl_planning_scene
