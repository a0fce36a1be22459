/**
 * \file grid_reach.h
 * \brief ROS-free: how many steps each cell of a grid lies from the nearest marked cell (or the grid's outside),
 *        stepping between neighbouring cells (26-connected) none of which is blocked. The hidden-space rule's distance
 *        (hidden_space.cpp): something that may be in a marked cell walks around a table (blocked cells), not through
 *        it, and (steps - 1) x resolution bounds from below how far it has to go.
 *
 * Exact up to `cells` steps: layer s is the marked cells grown s times by one step into the cells not blocked, each a
 * few shifts of the whole bit set. Beyond, one lower bound, `far`: a cell farther than far - 1 (Chebyshev, blocked
 * cells ignored) from every marked cell is at least far steps away (a step changes each index by one at most); the
 * cells within are the marked ones dilated by far - 1, in doubling passes (about log2(far) + 1 shifts per axis). The
 * outside of the grid counts as marked (something may come in from there).
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
  /// \param far the lower bound beyond `cells` for the cells that far (Chebyshev) from every marked cell (one more bit
  ///        set); far <= cells + 1: none (the bound is then cells + 1).
  void build(const std::int64_t size[3], const std::vector<std::uint64_t>& marked,
             const std::vector<std::uint64_t>& blocked, int cells, int far);
  /// \brief Steps from cell (i, j, k) to the nearest marked cell or the outside: exact when at most cells(), else a
  ///        lower bound above cells() (far, for a cell that far from every marked one). Meant for cells that are not
  ///        blocked.
  int steps(std::int64_t i, std::int64_t j, std::int64_t k) const;
  int cells() const { return cells_; }

 private:
  std::int64_t size_[3] = {0, 0, 0};
  int cells_ = 0, far_ = 0;
  std::vector<std::vector<std::uint64_t>> layers_;  ///< layers_[s - 1]: the cells within s steps
  std::vector<std::uint64_t> near_;                 ///< the cells within far_ - 1 (Chebyshev) of a marked one
  std::vector<std::uint64_t> scratch_a_, scratch_b_;
};

}  // namespace moverl_planning_scene
