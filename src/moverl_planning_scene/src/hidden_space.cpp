/**
 * \file hidden_space.cpp
 * \brief OccupancyMap's hidden space (options.hidden_space, issue 52): a free cell stays free only while nothing that
 *        moves at up to the speed bound could have reached it since a camera last saw it free. The views of one
 *        instant are a batch (beginView); at its close (closeBatch) the watched free cells no view of it saw turn
 *        possibly occupied when something possibly occupied as of the batch before could have come there by now.
 *
 * The rule, for anything moving at up to v that the cameras see wherever they look (docs/sensing.md, "Space no camera
 * sees"): let P(s) be where it may be at time s. After the batch at s_k, P(s_k) lies in the possibly-occupied cells
 * N_k (seen occupied, never seen, or stale). By s_{k+1} it lies within v (s_{k+1} - s_k) of N_k, and not in the cells
 * the views at s_{k+1} saw free: so a free cell c none of them saw may hold it iff its distance to N_k is below
 * v (s_{k+1} - s_k). Each hidden cell keeps the largest lower bound found so far on when something could first be in
 * it, s_j + d(c, N_j) / v over the batches j it stayed hidden in: something in a hidden region advances at v (a cell
 * per batch only when v times the batch's interval exceeds a cell), and a hidden region far from every
 * possibly-occupied cell stays free for as long as the views keep it so. The distance is a lower bound: (L - 1) x
 * resolution for cells L apart (Chebyshev, in grid indices) is the least distance between two cells that far apart.
 * Outside the grid counts as possibly occupied (something may walk in).
 *
 * Cost: only the blocks within speed_bound x watch_time of a possibly-occupied cell are watched (their cells looked at
 * by every view, clamped free or not, as the projective update looks at unclamped cells: an unchanged block repeats its
 * last view); a close looks at the watched free cells no view of the batch saw.
 */
#include <algorithm>
#include <cmath>
#include <limits>

#include "moverl_planning_scene/occupancy_map.h"

namespace moverl_planning_scene {
namespace {

constexpr int kBlockShift = OccupancyMap::kBlockBits, kSubShift = OccupancyMap::kSuperBits - kBlockShift;
constexpr std::uint64_t kAllCells = ~std::uint64_t{0};
/// Closes between two full recomputes of the watched blocks (between them the watch only grows, a superset).
constexpr int kFullWatchEvery = 32;
/// The steps to the nearest possibly-occupied cell are exact this far (cells: GridReach's layers); beyond, a bound.
constexpr int kCellSearch = 4;
/// watchMask's widest watch (cells): its window of rows is 4 + 2 L cells along each axis, up to 64.
constexpr int kMaskCells = 30;
/// Blocks whose cells changed beyond which the watch is made anew for the whole grid (watchAll, about 2 ms for the
/// Panda's map at a watch of one cell) rather than for the blocks near them (watchMask, 27 blocks each at least).
constexpr std::size_t kIncrementalWatch = 64;

bool testBit(const std::vector<std::uint64_t>& bits, std::int64_t k) { return ((bits[k >> 6] >> (k & 63)) & 1u) != 0; }
void setBit(std::vector<std::uint64_t>* bits, std::int64_t k) { (*bits)[k >> 6] |= std::uint64_t{1} << (k & 63); }

}  // namespace

int OccupancyMap::blocksWithin(double seconds) const {
  // Blocks b apart (Chebyshev) hold cells (b - 1) x 4 cells apart at least: a possibly-occupied cell can reach a cell
  // of a block b away within `seconds` only when (b - 1) x the block's edge < speed_bound x seconds.
  const double block = options_.resolution * (1 << kBlockShift);
  const double most = static_cast<double>(std::max(blocks_[0], std::max(blocks_[1], blocks_[2])));
  return static_cast<int>(std::min(most, std::floor(options_.speed_bound * std::max(0.0, seconds) / block) + 1.0));
}

int OccupancyMap::cellsWithin(double seconds) const {
  // Cells L apart (Chebyshev, in grid indices) are (L - 1) x resolution apart at least: something at the speed bound
  // can come from one to the other within `seconds` only when that is less than speed_bound x seconds.
  const double most = static_cast<double>(std::max(size_[0], std::max(size_[1], size_[2])));
  return static_cast<int>(
      std::min(most, std::floor(options_.speed_bound * std::max(0.0, seconds) / options_.resolution) + 1.0));
}

void OccupancyMap::setSpeedBound(double speed_bound) {
  options_.speed_bound = std::isfinite(speed_bound) ? std::max(0.0, speed_bound) : 0.0;
  if (!options_.hidden_space) return;
  // Until batches come, watch as far as watch_time lets something come; then as far as the batches' interval does
  // (the longest of the last kIntervals: a reset's extra batch a substep after the one before counts as short).
  std::fill(intervals_, intervals_ + kIntervals, options_.watch_time);
  watch_cells_ = options_.speed_bound > 0.0 ? cellsWithin(options_.watch_time) : -1;
  updateWatched(true);
}

void OccupancyMap::dilateBlocks(int m, std::vector<std::uint8_t>* out) const {
  // Chebyshev dilation by m of the blocks holding a possibly-occupied cell, with the grid's outside holding some:
  // separable (x, then y, then z), over block coordinates; *out per block index.
  const std::int64_t X = blocks_[0], Y = blocks_[1], Z = blocks_[2];
  auto lin = [&](std::int64_t x, std::int64_t y, std::int64_t z) { return (x * Y + y) * Z + z; };
  std::vector<std::uint8_t> a(static_cast<std::size_t>(X * Y * Z), 0), t(a.size(), 0);
  for (std::int64_t x = 0; x < X; ++x) {
    for (std::int64_t y = 0; y < Y; ++y) {
      for (std::int64_t z = 0; z < Z; ++z) {
        const bool edge = x < m || y < m || z < m || x >= X - m || y >= Y - m || z >= Z - m;
        a[lin(x, y, z)] = edge || block_count_[blockIndex(x, y, z)] != 0 ? 1 : 0;
      }
    }
  }
  auto pass = [&](const std::vector<std::uint8_t>& in, std::vector<std::uint8_t>* o, int axis) {
    const std::int64_t n[3] = {X, Y, Z};
    std::int64_t at[3];
    for (at[0] = 0; at[0] < X; ++at[0]) {
      for (at[1] = 0; at[1] < Y; ++at[1]) {
        for (at[2] = 0; at[2] < Z; ++at[2]) {
          std::uint8_t any = 0;
          std::int64_t q[3] = {at[0], at[1], at[2]};
          const std::int64_t lo = std::max<std::int64_t>(0, at[axis] - m);
          const std::int64_t hi = std::min<std::int64_t>(n[axis] - 1, at[axis] + m);
          for (q[axis] = lo; q[axis] <= hi && !any; ++q[axis]) any = in[lin(q[0], q[1], q[2])];
          (*o)[lin(at[0], at[1], at[2])] = any;
        }
      }
    }
  };
  pass(a, &t, 0);
  pass(t, &a, 1);
  pass(a, &t, 2);
  out->assign(block_watched_.size(), 0);
  std::int64_t at[3];
  for (std::int64_t b = 0; b < static_cast<std::int64_t>(out->size()); ++b) {
    blockCoords(b, at);
    if (at[0] < X && at[1] < Y && at[2] < Z) (*out)[b] = t[lin(at[0], at[1], at[2])];
  }
}

void OccupancyMap::blockCoords(std::int64_t b, std::int64_t* at) const {
  constexpr std::int64_t sub = (1 << kSubShift) - 1;
  std::int64_t s[3];
  unravel(b >> (3 * kSubShift), supers_, s);
  const std::int64_t local = b & ((std::int64_t{1} << (3 * kSubShift)) - 1);
  at[0] = (s[0] << kSubShift) | ((local >> (2 * kSubShift)) & sub);
  at[1] = (s[1] << kSubShift) | ((local >> kSubShift) & sub);
  at[2] = (s[2] << kSubShift) | (local & sub);
}

std::int64_t OccupancyMap::blockFirstCell(const std::int64_t* block_at) const {
  return cellId(block_at[0] << kBlockShift, block_at[1] << kBlockShift, block_at[2] << kBlockShift);
}

void OccupancyMap::setWatched(std::int64_t b, std::uint64_t mask) {
  const std::uint64_t old = block_watched_[b];
  if (old == mask) return;
  block_watched_[b] = mask;
  // A cell that comes into the watch was farther than the watch from every possibly-occupied cell when it was last
  // made (unless it turned free since): nothing could be in it before that time plus the watch's distance over the
  // speed bound. It carries that bound, so that something in hidden space advances at the bound, not a cell a batch.
  const std::uint64_t carried = mask & ~old & ~turned_free_[b];
  if (carried != 0 && std::isfinite(watch_made_at_) && options_.speed_bound > 0.0) {
    const double bound = watch_made_at_ + watch_made_cells_ * options_.resolution / options_.speed_bound;
    std::int64_t at[3];
    blockCoords(b, at);
    const std::int64_t k0 = blockFirstCell(at);
    for (std::uint64_t bits = carried; bits != 0; bits &= bits - 1) {
      float& kept = free_until_[static_cast<std::size_t>(k0 + cell_offset_[__builtin_ctzll(bits)])];
      if (std::isnan(kept) || kept < bound) kept = static_cast<float>(bound);
    }
  }
  const std::int64_t s = b >> (3 * kSubShift);
  if ((old != 0) != (mask != 0))
    super_watched_[s] = static_cast<std::uint16_t>(super_watched_[s] + (mask != 0 ? 1 : -1));
  // A view that did not look at a newly watched cell must not be repeated for it.
  if ((mask & ~old) != 0) block_dirtied_[b] = super_dirtied_[s] = epoch_;
}

std::uint64_t OccupancyMap::watchMask(const std::int64_t* block_at, int L) const {
  // The block's free cells within L (Chebyshev, cells) of a possibly-occupied one or of the grid's edge: the rows
  // along z of the window the block's cells look into, each dilated along z, then along y and x (4 bits a row).
  const std::int64_t b = blockIndex(block_at[0], block_at[1], block_at[2]);
  if (block_free_[b] == 0) return 0;
  if (L > kMaskCells) return block_free_[b];  // a watch this wide looks at every free cell
  const int W = (1 << kBlockShift) + 2 * L;
  const std::int64_t i0 = (block_at[0] << kBlockShift) - L, j0 = (block_at[1] << kBlockShift) - L;
  const std::int64_t k0 = (block_at[2] << kBlockShift) - L;
  const std::uint64_t span = (std::uint64_t{1} << (2 * L + 1)) - 1;  // a cell's 2L + 1 along z
  // row[x][y]: which of the block's 4 z-cells have a possibly-occupied cell within L along z at (i0 + x, j0 + y).
  std::uint8_t rows[64][64];
  for (int x = 0; x < W; ++x) {
    const std::int64_t i = i0 + x;
    for (int y = 0; y < W; ++y) {
      const std::int64_t j = j0 + y;
      std::uint64_t bits;  // the window's W cells along z, bit 0 at k0
      if (i < 0 || j < 0 || i >= size_[0] || j >= size_[1]) {
        bits = ~std::uint64_t{0};
      } else {
        bits = 0;
        const std::int64_t ka = std::max<std::int64_t>(0, k0), kb = std::min<std::int64_t>(size_[2] - 1, k0 + W - 1);
        if (ka > 0 || kb < k0 + W - 1) {  // beyond the grid along z counts
          for (int k = 0; k < W; ++k) {
            if (k0 + k < 0 || k0 + k >= size_[2]) bits |= std::uint64_t{1} << k;
          }
        }
        const std::int64_t first = cellId(i, j, ka), last = cellId(i, j, kb);
        std::uint64_t got = 0;
        for (std::int64_t w = first >> 6, shift = 0; w <= last >> 6; ++w) {
          std::uint64_t word = occupied_[static_cast<std::size_t>(w)];
          if (w == first >> 6) {
            word >>= (first & 63);
            got |= word;
            shift = 64 - (first & 63);
          } else {
            if (shift < 64) got |= word << shift;
            shift += 64;
          }
        }
        const int n = static_cast<int>(kb - ka + 1);
        if (n < 64) got &= (std::uint64_t{1} << n) - 1;
        bits |= got << (ka - k0);
      }
      std::uint8_t r = 0;
      for (int z = 0; z < (1 << kBlockShift); ++z) {
        if (((bits >> z) & span) != 0) r |= static_cast<std::uint8_t>(1u << z);  // window cells [z, z + 2L]
      }
      rows[x][y] = r;
    }
  }
  std::uint64_t mask = 0;
  constexpr int e = 1 << kBlockShift;
  for (int cx = 0; cx < e; ++cx) {
    for (int cy = 0; cy < e; ++cy) {
      std::uint8_t r = 0;
      for (int x = cx; x <= cx + 2 * L; ++x) {
        for (int y = cy; y <= cy + 2 * L; ++y) r |= rows[x][y];
      }
      mask |= static_cast<std::uint64_t>(r) << ((cx << kBlockShift | cy) << kBlockShift);
    }
  }
  return mask & block_free_[b];
}

void OccupancyMap::watchAll(int L) {
  // Every cell within L (Chebyshev) of a possibly-occupied cell or of the grid's edge, as a bit set in cell order:
  // occupied_ dilated by L along z, then y, then x, each a shift of the whole set (a row's, a plane's stride). A shift
  // carries bits across a row's (plane's) end only into cells within L of the grid's edge, which are set anyway.
  const std::size_t n = occupied_.size();
  // One doubling pass: when *set is the set dilated by d along the axis (its cells within d of a set one) and
  // r <= 2 d + 1, the set or'ed with itself shifted by +-r cells is the set dilated by d + r (the bands [-d, d] and
  // [r - d, r + d], and their mirror, leave no gap).
  auto dilate = [&](std::vector<std::uint64_t>* set, std::vector<std::uint64_t>* tmp, std::int64_t stride, int r) {
    dilateBits(*set, stride * r, tmp);
    set->swap(*tmp);
  };
  // Chebyshev dilation by L along one axis as doubling passes (radii 1, 2, 4, ..., the last what is left): about
  // log2(L) + 1 shifts of the whole set, not L.
  auto along = [&](std::vector<std::uint64_t>* set, std::vector<std::uint64_t>* tmp, std::int64_t stride) {
    for (int done = 0; done < L;) {
      const int r = std::min(done + 1, L - done);
      dilate(set, tmp, stride, r);
      done += r;
    }
  };
  std::vector<std::uint64_t>& a = watch_scratch_a_;
  std::vector<std::uint64_t>& b = watch_scratch_b_;
  a.assign(occupied_.begin(), occupied_.end());
  along(&a, &b, 1);
  along(&a, &b, size_[2]);
  along(&a, &b, size_[1] * size_[2]);
  // The cells within L of the grid's edge, word by word.
  auto set_range = [&](std::int64_t first, std::int64_t last) {  // cells [first, last]
    for (std::int64_t w = first >> 6; w <= last >> 6; ++w) {
      std::uint64_t bits = ~std::uint64_t{0};
      if (w == first >> 6) bits &= ~std::uint64_t{0} << (first & 63);
      if (w == last >> 6) bits &= ~std::uint64_t{0} >> (63 - (last & 63));
      a[static_cast<std::size_t>(w)] |= bits;
    }
  };
  const std::int64_t l = std::min<std::int64_t>(L, std::max(size_[0], std::max(size_[1], size_[2])));
  for (std::int64_t i = 0; i < size_[0]; ++i) {
    if (i < l || i >= size_[0] - l) {
      set_range(cellId(i, 0, 0), cellId(i, size_[1] - 1, size_[2] - 1));
      continue;
    }
    for (std::int64_t j = 0; j < size_[1]; ++j) {
      const std::int64_t row = cellId(i, j, 0);
      if (j < l || j >= size_[1] - l) {
        set_range(row, row + size_[2] - 1);
      } else {
        set_range(row, row + std::min<std::int64_t>(l, size_[2]) - 1);
        set_range(row + std::max<std::int64_t>(0, size_[2] - l), row + size_[2] - 1);
      }
    }
  }
  // Each block's mask: its 16 rows of 4 cells, of the free ones.
  const std::int64_t nb = static_cast<std::int64_t>(block_watched_.size());
  constexpr int e = 1 << kBlockShift;
  std::int64_t at[3];
  for (std::int64_t bi = 0; bi < nb; ++bi) {
    if (block_free_[bi] == 0) {
      setWatched(bi, 0);
      continue;
    }
    blockCoords(bi, at);
    std::uint64_t mask = 0;
    for (int cx = 0; cx < e; ++cx) {
      const std::int64_t i = (at[0] << kBlockShift) + cx;
      if (i >= size_[0]) break;
      for (int cy = 0; cy < e; ++cy) {
        const std::int64_t j = (at[1] << kBlockShift) + cy;
        if (j >= size_[1]) break;
        const std::int64_t k = at[2] << kBlockShift, first = cellId(i, j, k);
        const int w = static_cast<int>(first >> 6), o = static_cast<int>(first & 63);
        std::uint64_t bits = a[static_cast<std::size_t>(w)] >> o;
        if (o > 64 - e && static_cast<std::size_t>(w + 1) < n) bits |= a[static_cast<std::size_t>(w + 1)] << (64 - o);
        mask |= (bits & ((1u << e) - 1)) << ((cx << kBlockShift | cy) << kBlockShift);
      }
    }
    setWatched(bi, mask & block_free_[bi]);
  }
}

void OccupancyMap::updateWatched(bool full) {
  if (block_watched_.empty()) return;
  if (!options_.integrates) {  // no views look at this map's cells
    for (std::int64_t b : grown_blocks_) grown_mark_[b] = 0;
    grown_blocks_.clear();
    return;
  }
  struct Made {  // what the watch is as of now, once it is made
    OccupancyMap* map;
    ~Made() {
      map->watch_made_at_ = map->map_time_;
      map->watch_made_cells_ = map->watch_cells_;
      std::fill(map->turned_free_.begin(), map->turned_free_.end(), 0);
    }
  } made{this};
  const bool active = hiddenSpaceActive() && watch_cells_ >= 0;
  const std::int64_t nb = static_cast<std::int64_t>(block_watched_.size());
  std::int64_t at[3];
  if (!active) {
    for (std::int64_t b = 0; b < nb; ++b) setWatched(b, 0);
  } else {
    // The blocks near a cell that changed (turned possibly occupied or free): their cells' distances changed. Their
    // masks one by one, or the whole grid at once (watchAll's bit operations) when that costs less: a block's mask
    // reads a window of (4 + 2 L)^2 rows and ors 16 (2 L + 1)^2 of them; the whole grid is a few passes over its
    // words per axis and 16 rows a block.
    const int L = watch_cells_;
    const std::int64_t m = (L + (1 << kBlockShift) - 1) >> kBlockShift;
    const double per_block =
        L > kMaskCells ? 1.0 : std::pow(4.0 + 2.0 * L, 2) + 16.0 * std::pow(2.0 * L + 1.0, 2);  // (wider: every free)
    const double whole = 3.0 * (std::log2(std::max(1, L)) + 2.0) * static_cast<double>(occupied_.size()) +
                         16.0 * static_cast<double>(nb);
    const double most = whole / per_block;  // blocks beyond which watchAll costs less
    std::vector<std::int64_t> todo;
    bool all = full || grown_blocks_.size() > kIncrementalWatch;
    for (std::size_t g = 0; g < grown_blocks_.size() && !all; ++g) {
      std::int64_t q[3];
      blockCoords(grown_blocks_[g], at);
      for (q[0] = std::max<std::int64_t>(0, at[0] - m); q[0] <= std::min(blocks_[0] - 1, at[0] + m); ++q[0]) {
        for (q[1] = std::max<std::int64_t>(0, at[1] - m); q[1] <= std::min(blocks_[1] - 1, at[1] + m); ++q[1]) {
          for (q[2] = std::max<std::int64_t>(0, at[2] - m); q[2] <= std::min(blocks_[2] - 1, at[2] + m); ++q[2]) {
            const std::int64_t n = blockIndex(q[0], q[1], q[2]);
            if (grown_mark_[n] == 2) continue;  // listed already
            grown_mark_[n] = 2;
            todo.push_back(n);
          }
        }
      }
      all = static_cast<double>(todo.size()) > most;
    }
    if (all) {
      for (std::int64_t n : todo) grown_mark_[n] = 0;
      watchAll(L);
      closes_since_full_watch_ = 0;
    } else {
      for (std::int64_t n : todo) {
        blockCoords(n, at);
        setWatched(n, watchMask(at, L));
        grown_mark_[n] = 0;
      }
    }
  }
  for (std::int64_t b : grown_blocks_) grown_mark_[b] = 0;
  grown_blocks_.clear();
}

void OccupancyMap::setSolid(const std::vector<std::uint64_t>& keys) {
  if (solid_.empty()) return;
  std::fill(solid_.begin(), solid_.end(), 0);
  for (std::uint64_t key : keys) {
    if (key < value_.size()) setBit(&solid_, static_cast<std::int64_t>(key));
  }
}

void OccupancyMap::cellsIn(const Eigen::AlignedBox3d& box, std::vector<Eigen::Vector3d>* centers,
                           std::vector<std::uint64_t>* keys) const {
  centers->clear();
  keys->clear();
  if (box.isEmpty()) return;
  const double r = options_.resolution;
  std::int64_t lo[3], hi[3];
  for (int i = 0; i < 3; ++i) {
    lo[i] = std::max<std::int64_t>(0, static_cast<std::int64_t>(std::ceil(box.min()[i] / r - 0.5)) - offset_[i]);
    hi[i] = std::min<std::int64_t>(size_[i] - 1,
                                   static_cast<std::int64_t>(std::floor(box.max()[i] / r - 0.5)) - offset_[i]);
    if (lo[i] > hi[i]) return;
  }
  for (std::int64_t i = lo[0]; i <= hi[0]; ++i) {
    for (std::int64_t j = lo[1]; j <= hi[1]; ++j) {
      for (std::int64_t k = lo[2]; k <= hi[2]; ++k) {
        centers->push_back(centre(i, j, k));
        keys->push_back(static_cast<std::uint64_t>(cellId(i, j, k)));
      }
    }
  }
}

void OccupancyMap::buildReach(int needed) {
  // Exactly up to kCellSearch steps (or needed, if fewer), and a cell farther than needed - 1 (Chebyshev) from every
  // possibly-occupied one is at least needed steps away: out of reach until now, which is all closeBatch asks.
  reach_.build(size_, occupied_, solid_, std::min(needed, kCellSearch), needed);
}

void OccupancyMap::refreshFree(std::int64_t c) {
  std::int64_t b, s;
  std::uint64_t bit;
  boxesOf(c, &b, &s, &bit);
  const bool free = testBit(observed_, c) && !testBit(occupied_, c);
  block_free_[b] = free ? block_free_[b] | bit : block_free_[b] & ~bit;
}

void OccupancyMap::makeStale(std::int64_t c) {
  const bool was_seen_occupied = testBit(observed_, c) && value_[c] >= threshold_;
  setValue(c, prior_);
  if (!testBit(observed_, c)) {
    setBit(&observed_, c);
    ++observed_cells_;
  }
  if (!was_seen_occupied) countSeen(c, 1);
  if (!testBit(stale_, c)) {
    setBit(&stale_, c);
    ++stale_cells_;
  }
  refreshFree(c);
}

bool OccupancyMap::beginView(double stamp, MapUpdate* close, const KnownFree* known_free, BatchStats* stats) {
  if (!options_.hidden_space) return false;
  bool closed = false;
  if (!std::isnan(batch_stamp_) && stamp > batch_stamp_) closed = closeBatch(close, stats, known_free);
  if (std::isnan(batch_stamp_) && stamp > map_time_) {
    batch_stamp_ = stamp;
    // (A close returned here widens the watch for this batch when it is applied: applyClose.)
    if (!closed && watchAhead()) updateWatched(true);
  }
  recording_ = stamp == batch_stamp_;  // else late: it sees nothing free that another view may contradict
  return closed;
}

bool OccupancyMap::closeBatch(MapUpdate* out, BatchStats* stats, const KnownFree* known_free) {
  if (!options_.hidden_space || std::isnan(batch_stamp_)) return false;
  out->hits.clear();
  out->misses.clear();
  out->fixed.clear();
  out->stale.clear();
  out->stats = MapUpdateStats();
  out->close = true;
  out->late = false;
  out->forget = false;
  out->stamp = batch_stamp_;
  BatchStats bs;
  if (hiddenSpaceActive() && std::isfinite(map_time_)) {
    const double v = options_.speed_bound, res = options_.resolution, now = batch_stamp_, before = map_time_;
    if (now - before > options_.watch_time || forget_next_) {
      out->forget = bs.forget = true;  // the views stopped for longer than the watch covers: nothing is known free
    } else {
      // The Chebyshev distance that keeps a cell unreachable until now: (L - 1) res / v >= now - before.
      const int needed = static_cast<int>(std::ceil((now - before) * v / res)) + 1;
      const std::int64_t nb = static_cast<std::int64_t>(block_watched_.size());
      // The blocks something may have come into since the batch before: the watched ones, or, when this batch came
      // later than the watch was made for, every block that near (what the views did not look at counts as hidden).
      const bool wider = cellsWithin(now - before) > watch_cells_;
      bs.beyond_watch = wider;
      if (wider) dilateBlocks(blocksWithin(now - before), &reach_scratch_);
      std::int64_t at[3];
      bool reach_built = false;  // (made when the first hidden cell needs it)
      for (std::int64_t b = 0; b < nb; ++b) {
        if (wider ? reach_scratch_[b] == 0 : block_watched_[b] == 0) continue;
        ++bs.watched_blocks;
        // The watched free cells no view saw (wider: every free cell not seen: the views did not look at them all).
        const std::uint64_t hidden = block_free_[b] & ~batch_seen_[b] & (wider ? ~std::uint64_t{0} : block_watched_[b]);
        if (hidden == 0) continue;
        blockCoords(b, at);
        const std::int64_t k0 = blockFirstCell(at);
        for (std::uint64_t bits = hidden; bits != 0; bits &= bits - 1) {
          const int n = __builtin_ctzll(bits);
          const std::int64_t ci = (at[0] << kBlockShift) + (n >> (2 * kBlockShift));
          const std::int64_t cj = (at[1] << kBlockShift) + ((n >> kBlockShift) & ((1 << kBlockShift) - 1));
          const std::int64_t ck = (at[2] << kBlockShift) + (n & ((1 << kBlockShift) - 1));
          const std::int64_t c = k0 + cell_offset_[n];
          if (testBit(fixed_, c) || testBit(solid_, c)) continue;  // free for good: nothing can be there
          ++bs.hidden;
          if (!reach_built) {
            buildReach(needed);
            reach_built = true;
          }
          const int L = reach_.steps(ci, cj, ck);
          const double reach = before + std::max(0, L - 1) * res / v;  // nothing there before this
          const double kept = std::isnan(free_until_[c]) ? reach : std::max<double>(free_until_[c], reach);
          if (kept < now) {
            out->stale.push_back(static_cast<std::uint64_t>(c));
            if (known_free != nullptr) vouch_centres_.push_back(centre(ci, cj, ck));
          } else {
            free_until_[c] = static_cast<float>(std::min(kept, static_cast<double>(std::numeric_limits<float>::max())));
          }
        }
      }
      if (known_free != nullptr && !out->stale.empty()) {
        // The would-be stale cells the caller knows hold nothing (the robot's padding band) stay free.
        (*known_free)(vouch_centres_, &vouch_known_);
        std::size_t kept = 0;
        for (std::size_t k = 0; k < out->stale.size(); ++k) {
          if (k < vouch_known_.size() && vouch_known_[k] != 0) continue;
          out->stale[kept++] = out->stale[k];
        }
        out->stale.resize(kept);
      }
      vouch_centres_.clear();
      bs.stale = out->stale.size();
    }
  }
  // (The bounds of the cells the batch saw stay: a lower bound on when something could first be in a cell stays one
  // as views come; each is below the map's time once it is older than a batch, and then a new close's bound counts.)
  std::fill(batch_seen_.begin(), batch_seen_.end(), 0);
  forget_next_ = false;
  batch_stamp_ = std::numeric_limits<double>::quiet_NaN();
  recording_ = false;
  if (stats != nullptr) *stats = bs;
  return true;
}

void OccupancyMap::applyClose(const MapUpdate& update) {
  if (update.forget && !stale_.empty()) {
    const auto cells = static_cast<std::int64_t>(value_.size());
    for (std::int64_t c = 0; c < cells; ++c) {
      if (testBit(observed_, c) && !testBit(occupied_, c) && !testBit(fixed_, c) && !testBit(solid_, c)) makeStale(c);
    }
  }
  for (std::uint64_t key : update.stale) {
    const auto c = static_cast<std::int64_t>(key);
    if (c < 0 || c >= static_cast<std::int64_t>(value_.size()) || stale_.empty()) continue;
    if (testBit(occupied_, c) || testBit(fixed_, c) || testBit(solid_, c)) continue;  // (as closeBatch read: never)
    makeStale(c);
  }
  // The batch's misses of possibly-occupied cells, in their order.
  std::vector<std::uint64_t> held;
  held.swap(held_misses_);
  for (std::uint64_t key : held) applyOne(static_cast<std::int64_t>(key), false);
  // The watch: as far as something may come within the longest of the last batches' intervals (a quarter more).
  bool resized = false;
  if (std::isfinite(update.stamp) && std::isfinite(map_time_) && update.stamp > map_time_ && watch_cells_ >= 0) {
    std::rotate(intervals_, intervals_ + 1, intervals_ + kIntervals);
    intervals_[kIntervals - 1] = update.stamp - map_time_;
    const double longest = *std::max_element(intervals_, intervals_ + kIntervals);
    const int m = std::min(cellsWithin(options_.watch_time), cellsWithin(1.25 * longest));
    resized = m != watch_cells_;
    watch_cells_ = m;
  }
  if (std::isfinite(update.stamp)) map_time_ = std::max(map_time_, update.stamp);
  resized = watchAhead() || resized;  // the next batch, when its first view closed this one
  updateWatched(resized || ++closes_since_full_watch_ >= kFullWatchEvery);
}

bool OccupancyMap::watchAhead() {
  // The open batch comes later after the map's time than the watch covers (the integrator skipped instants): its
  // views must look at every free cell something may have reached by then, else its close counts the ones they did
  // not look at as hidden, seen free or not (the stale floods of docs/notes/ssm_research.md). A batch later than
  // watch_time finds everything possibly occupied anyway (forget).
  if (!hiddenSpaceActive() || watch_cells_ < 0 || std::isnan(batch_stamp_) || !std::isfinite(map_time_)) return false;
  const double gap = batch_stamp_ - map_time_;
  if (gap > options_.watch_time) return false;
  const int needed = cellsWithin(gap);
  if (needed <= watch_cells_) return false;
  watch_cells_ = needed;
  ++watches_ahead_;
  return true;
}

void OccupancyMap::census(const Eigen::Vector3d& at, double radius, MapCensus* out) const {
  *out = MapCensus();
  const double r2 = radius * radius;
  std::int64_t lo[3], hi[3];
  for (int i = 0; i < 3; ++i) {
    lo[i] = std::max<std::int64_t>(0, indexOf(at[i] - radius, i));
    hi[i] = std::min<std::int64_t>(size_[i] - 1, indexOf(at[i] + radius, i));
    if (lo[i] > hi[i]) return;
  }
  for (std::int64_t i = lo[0]; i <= hi[0]; ++i) {
    for (std::int64_t j = lo[1]; j <= hi[1]; ++j) {
      for (std::int64_t k = lo[2]; k <= hi[2]; ++k) {
        const Eigen::Vector3d p = centre(i, j, k);
        const Eigen::Vector3d d = p - at;
        if (d.squaredNorm() > r2) continue;
        ++out->cells;
        const int octant = (d.x() >= 0 ? 1 : 0) + (d.y() >= 0 ? 2 : 0) + (d.z() >= 0 ? 4 : 0);
        ++out->cells_by_octant[octant];
        const std::int64_t c = cellId(i, j, k);
        bool hidden = false;
        if (!testBit(observed_, c)) {
          ++out->unseen;
          hidden = true;
        } else if (!stale_.empty() && testBit(stale_, c)) {
          ++out->stale;
          hidden = true;
        } else if (testBit(occupied_, c)) {
          ++out->seen_occupied;
        } else {
          ++out->free;
        }
        if (hidden) ++out->hidden_by_octant[octant];
      }
    }
  }
}

}  // namespace moverl_planning_scene
