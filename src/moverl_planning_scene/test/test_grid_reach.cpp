/**
 * \file test_grid_reach.cpp
 * \brief GridReach (the hidden-space rule's distance) against a plain breadth-first search, without a roscore: random
 *        grids whose sizes are not multiples of a block, marked and blocked cells at random; exact up to the layers,
 *        a lower bound beyond them (far: the cells that far from every marked one).
 */
#include <gtest/gtest.h>

#include <algorithm>
#include <cstdint>
#include <deque>
#include <random>
#include <vector>

#include "moverl_planning_scene/grid_reach.h"

namespace mps = moverl_planning_scene;

namespace {

struct Grid {
  std::int64_t size[3];
  std::vector<std::uint8_t> marked, blocked;
  std::int64_t id(std::int64_t i, std::int64_t j, std::int64_t k) const { return (i * size[1] + j) * size[2] + k; }
  std::int64_t cells() const { return size[0] * size[1] * size[2]; }
  std::vector<std::uint64_t> bits(const std::vector<std::uint8_t>& v) const {
    std::vector<std::uint64_t> out(static_cast<std::size_t>((cells() + 63) / 64), 0);
    for (std::int64_t c = 0; c < cells(); ++c) {
      if (v[c] != 0) out[c >> 6] |= std::uint64_t{1} << (c & 63);
    }
    return out;
  }
};

/// The reference: breadth first from the marked cells into the cells not blocked (26 neighbours); the outside is
/// min(i + 1, size - i, ...) steps from a cell (the straight way out).
std::vector<int> reference(const Grid& g) {
  const int kFar = 1 << 20;
  std::vector<int> d(static_cast<std::size_t>(g.cells()), kFar);
  std::deque<std::int64_t> q;
  for (std::int64_t c = 0; c < g.cells(); ++c) {
    if (g.marked[c] != 0) d[c] = 0, q.push_back(c);
  }
  while (!q.empty()) {
    const std::int64_t c = q.front();
    q.pop_front();
    const std::int64_t i = c / (g.size[1] * g.size[2]), j = (c / g.size[2]) % g.size[1], k = c % g.size[2];
    for (int dx = -1; dx <= 1; ++dx) {
      for (int dy = -1; dy <= 1; ++dy) {
        for (int dz = -1; dz <= 1; ++dz) {
          const std::int64_t x = i + dx, y = j + dy, z = k + dz;
          if (x < 0 || y < 0 || z < 0 || x >= g.size[0] || y >= g.size[1] || z >= g.size[2]) continue;
          const std::int64_t n = g.id(x, y, z);
          if (g.blocked[n] != 0 || d[n] <= d[c] + 1) continue;
          d[n] = d[c] + 1;
          q.push_back(n);
        }
      }
    }
  }
  for (std::int64_t i = 0; i < g.size[0]; ++i) {
    for (std::int64_t j = 0; j < g.size[1]; ++j) {
      for (std::int64_t k = 0; k < g.size[2]; ++k) {
        const std::int64_t e = std::min({i + 1, j + 1, k + 1, g.size[0] - i, g.size[1] - j, g.size[2] - k});
        int& v = d[g.id(i, j, k)];
        v = std::min<int>(v, static_cast<int>(e));
      }
    }
  }
  return d;
}

Grid randomGrid(std::mt19937* rng, double p_marked, double p_blocked) {
  std::uniform_int_distribution<int> side(5, 29);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  Grid g{{side(*rng), side(*rng), side(*rng)}, {}, {}};
  g.marked.assign(static_cast<std::size_t>(g.cells()), 0);
  g.blocked.assign(static_cast<std::size_t>(g.cells()), 0);
  for (std::int64_t c = 0; c < g.cells(); ++c) {
    g.marked[c] = u(*rng) < p_marked;
    g.blocked[c] = !g.marked[c] && u(*rng) < p_blocked;
  }
  return g;
}

}  // namespace

TEST(GridReach, ExactUpToItsLayersAndALowerBoundBeyond) {
  std::mt19937 rng(52);
  int compared = 0, exact = 0, beyond = 0;
  for (int trial = 0; trial < 60; ++trial) {
    // Sparse marks (long ways, the far bound counts), dense ones, and walls of blocked cells to go around.
    const double p_marked = trial % 3 == 0 ? 0.0005 : trial % 3 == 1 ? 0.01 : 0.05;
    const Grid g = randomGrid(&rng, p_marked, trial % 2 == 0 ? 0.0 : 0.3);
    const std::vector<int> want = reference(g);
    for (int cells : {1, 2, 4}) {
      for (int far : {0, 7}) {
        mps::GridReach reach;
        reach.build(g.size, g.bits(g.marked), g.bits(g.blocked), cells, far);
        for (std::int64_t i = 0; i < g.size[0]; ++i) {
          for (std::int64_t j = 0; j < g.size[1]; ++j) {
            for (std::int64_t k = 0; k < g.size[2]; ++k) {
              const std::int64_t c = g.id(i, j, k);
              if (g.blocked[c] != 0 || g.marked[c] != 0) continue;
              const int got = reach.steps(i, j, k), w = want[c];
              ++compared;
              if (w <= cells) {
                ++exact;
                ASSERT_EQ(got, w) << "cell " << i << " " << j << " " << k << " of " << g.size[0] << "x" << g.size[1]
                                  << "x" << g.size[2] << ", trial " << trial << ", cells " << cells;
              } else {
                ++beyond;
                ASSERT_GT(got, cells) << "trial " << trial;
                ASSERT_LE(got, w) << "not a lower bound: cell " << i << " " << j << " " << k << ", trial " << trial
                                  << ", far " << far;
              }
            }
          }
        }
      }
    }
  }
  // Both regimes were exercised.
  EXPECT_GT(exact, 100000);
  EXPECT_GT(beyond, 100000);
  EXPECT_GT(compared, exact);
}

TEST(GridReach, ACellFarFromEveryMarkedOneIsAtLeastFarAway) {
  // One marked cell in a 60^3 grid: a cell 20 cells from it along x (and 30 from every edge) is at least far = 17
  // steps away, more than the 4 exact layers show; one 16 cells away only beyond them (5); one 17 away, 17.
  Grid g{{60, 60, 60}, {}, {}};
  g.marked.assign(static_cast<std::size_t>(g.cells()), 0);
  g.blocked.assign(static_cast<std::size_t>(g.cells()), 0);
  g.marked[g.id(10, 30, 30)] = 1;
  mps::GridReach reach;
  reach.build(g.size, g.bits(g.marked), g.bits(g.blocked), 4, 17);
  EXPECT_EQ(reach.steps(13, 30, 30), 3);
  EXPECT_EQ(reach.steps(30, 30, 30), 17);
  EXPECT_EQ(reach.steps(26, 30, 30), 5);
  EXPECT_EQ(reach.steps(27, 30, 30), 17);
  EXPECT_EQ(reach.steps(30, 30, 59), 1);  // next to the outside
  reach.build(g.size, g.bits(g.marked), g.bits(g.blocked), 4, 2);
  EXPECT_EQ(reach.steps(30, 30, 30), 5);  // no far bound: beyond the layers
}

TEST(GridReach, DilateBitsIsTheSetOrItsShiftsByTheStride) {
  // Random bit sets of lengths around word multiples, shifted by strides below, at and above a word (and farther than
  // the set is long): bit k of the result is bit k, k - stride or k + stride of the input.
  std::mt19937 rng(7);
  for (std::int64_t bits : {1, 63, 64, 65, 500, 4096, 10007}) {
    for (std::int64_t stride : {1, 5, 63, 64, 65, 128, 253, 700, 20000}) {
      const std::size_t words = static_cast<std::size_t>((bits + 63) / 64);
      std::vector<std::uint64_t> in(words, 0), out;
      std::vector<std::uint8_t> set(static_cast<std::size_t>(words * 64), 0);
      for (std::int64_t k = 0; k < bits; ++k) {
        if (std::uniform_int_distribution<int>(0, 9)(rng) == 0) {
          set[k] = 1;
          in[k >> 6] |= std::uint64_t{1} << (k & 63);
        }
      }
      mps::dilateBits(in, stride, &out);
      ASSERT_EQ(out.size(), in.size());
      const auto n = static_cast<std::int64_t>(words * 64);
      for (std::int64_t k = 0; k < n; ++k) {
        const bool want =
            set[k] != 0 || (k - stride >= 0 && set[k - stride] != 0) || (k + stride < n && set[k + stride] != 0);
        ASSERT_EQ(((out[k >> 6] >> (k & 63)) & 1u) != 0, want)
            << "bit " << k << " of " << bits << ", stride " << stride;
      }
    }
  }
}
