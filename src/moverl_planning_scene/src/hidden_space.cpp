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
/// The cell-by-cell search for the nearest possibly-occupied cell goes this far (Chebyshev, cells); beyond, blocks.
constexpr int kCellSearch = 4;

bool testBit(const std::vector<std::uint64_t>& bits, std::int64_t k) { return ((bits[k >> 6] >> (k & 63)) & 1u) != 0; }
void setBit(std::vector<std::uint64_t>* bits, std::int64_t k) { (*bits)[k >> 6] |= std::uint64_t{1} << (k & 63); }

}  // namespace

void OccupancyMap::setSpeedBound(double speed_bound) {
  options_.speed_bound = std::isfinite(speed_bound) ? std::max(0.0, speed_bound) : 0.0;
  if (!options_.hidden_space) return;
  // A block is watched when a possibly-occupied cell lies within speed_bound x watch_time of one of its cells: blocks
  // b apart (Chebyshev) have cells (b - 1) x 4 cells apart at least.
  const double reach = options_.speed_bound * options_.watch_time;
  const double block = options_.resolution * (1 << kBlockShift);
  const double most = static_cast<double>(std::max(blocks_[0], std::max(blocks_[1], blocks_[2])));
  watch_blocks_ = options_.speed_bound > 0.0 ? static_cast<int>(std::min(most, std::floor(reach / block) + 1.0)) : -1;
  updateWatched(true);
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

void OccupancyMap::setWatched(std::int64_t b, bool on) {
  if ((block_watched_[b] != 0) == on) return;
  block_watched_[b] = on ? kAllCells : 0;
  const std::int64_t s = b >> (3 * kSubShift);
  super_watched_[s] = static_cast<std::uint16_t>(super_watched_[s] + (on ? 1 : -1));
  // A view that did not look at the block's clamped cells must not be repeated for them.
  if (on) block_dirtied_[b] = super_dirtied_[s] = epoch_;
}

void OccupancyMap::updateWatched(bool full) {
  if (block_watched_.empty()) return;
  const bool active = hiddenSpaceActive() && watch_blocks_ >= 0;
  const std::int64_t nb = static_cast<std::int64_t>(block_watched_.size());
  auto inside = [&](const std::int64_t* at) { return at[0] < blocks_[0] && at[1] < blocks_[1] && at[2] < blocks_[2]; };
  if (!active) {
    for (std::int64_t b = 0; b < nb; ++b) setWatched(b, false);
  } else if (full) {
    // Chebyshev dilation by watch_blocks_ of the blocks holding a possibly-occupied cell, with the grid's outside
    // holding some: separable (x, then y, then z), over block coordinates.
    const std::int64_t X = blocks_[0], Y = blocks_[1], Z = blocks_[2], m = watch_blocks_;
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
    auto pass = [&](const std::vector<std::uint8_t>& in, std::vector<std::uint8_t>* out, int axis) {
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
            (*out)[lin(at[0], at[1], at[2])] = any;
          }
        }
      }
    };
    pass(a, &t, 0);
    pass(t, &a, 1);
    pass(a, &t, 2);
    std::int64_t at[3];
    for (std::int64_t b = 0; b < nb; ++b) {
      blockCoords(b, at);
      setWatched(b, inside(at) && t[lin(at[0], at[1], at[2])] != 0);
    }
    closes_since_full_watch_ = 0;
  } else {
    const std::int64_t m = watch_blocks_;
    for (std::int64_t b : grown_blocks_) {
      if (block_count_[b] == 0) continue;
      std::int64_t at[3], q[3];
      blockCoords(b, at);
      for (q[0] = std::max<std::int64_t>(0, at[0] - m); q[0] <= std::min(blocks_[0] - 1, at[0] + m); ++q[0]) {
        for (q[1] = std::max<std::int64_t>(0, at[1] - m); q[1] <= std::min(blocks_[1] - 1, at[1] + m); ++q[1]) {
          for (q[2] = std::max<std::int64_t>(0, at[2] - m); q[2] <= std::min(blocks_[2] - 1, at[2] + m); ++q[2]) {
            setWatched(blockIndex(q[0], q[1], q[2]), true);
          }
        }
      }
    }
  }
  for (std::int64_t b : grown_blocks_) grown_mark_[b] = 0;
  grown_blocks_.clear();
}

int OccupancyMap::chebyshevToOccupied(std::int64_t i, std::int64_t j, std::int64_t k, int up_to) const {
  // Is any cell of the cube of half-edge L around (i, j, k) possibly occupied (or outside the grid)? Row by row along
  // z: the bits of a row lie side by side in occupied_.
  auto cube = [&](std::int64_t L) {
    if (i - L < 0 || j - L < 0 || k - L < 0 || i + L >= size_[0] || j + L >= size_[1] || k + L >= size_[2]) return true;
    for (std::int64_t x = i - L; x <= i + L; ++x) {
      for (std::int64_t y = j - L; y <= j + L; ++y) {
        const std::int64_t first = cellId(x, y, k - L), last = cellId(x, y, k + L);
        for (std::int64_t w = first >> 6; w <= last >> 6; ++w) {
          std::uint64_t bits = occupied_[static_cast<std::size_t>(w)];
          if (w == first >> 6) bits &= ~std::uint64_t{0} << (first & 63);
          if (w == last >> 6) bits &= ~std::uint64_t{0} >> (63 - (last & 63));
          if (bits != 0) return true;
        }
      }
    }
    return false;
  };
  const int cells = std::min(up_to, kCellSearch);
  for (int L = 1; L <= cells; ++L) {
    if (cube(L)) return L;
  }
  if (up_to <= cells) return up_to + 1;
  // Farther: blocks around the cell's block. No possibly-occupied cell within g blocks (Chebyshev) of the cell's own
  // puts the nearest at least g x 4 + 1 cells away; the first g with one bounds the distance from below by the g
  // before's.
  const std::int64_t bi = i >> kBlockShift, bj = j >> kBlockShift, bk = k >> kBlockShift;
  int bound = cells + 1;  // what the cell search showed
  for (std::int64_t g = 1;; ++g) {
    const int shows = static_cast<int>(g * (1 << kBlockShift)) + 1;  // what a clear ring of g blocks shows
    if (bi - g < 0 || bj - g < 0 || bk - g < 0 || bi + g >= blocks_[0] || bj + g >= blocks_[1] ||
        bk + g >= blocks_[2]) {
      return bound;  // the grid's edge
    }
    for (std::int64_t x = bi - g; x <= bi + g; ++x) {
      for (std::int64_t y = bj - g; y <= bj + g; ++y) {
        for (std::int64_t z = bk - g; z <= bk + g; ++z) {
          if (block_count_[blockIndex(x, y, z)] != 0) return bound;
        }
      }
    }
    bound = std::max(bound, shows);
    if (bound > up_to) return bound;
  }
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

bool OccupancyMap::beginView(double stamp, MapUpdate* close, const KnownFree* known_free) {
  if (!options_.hidden_space) return false;
  bool closed = false;
  if (!std::isnan(batch_stamp_) && stamp > batch_stamp_) closed = closeBatch(close, nullptr, known_free);
  if (std::isnan(batch_stamp_) && stamp > map_time_) batch_stamp_ = stamp;
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
      std::int64_t at[3];
      for (std::int64_t b = 0; b < nb; ++b) {
        if (block_watched_[b] == 0) continue;
        ++bs.watched_blocks;
        if ((block_free_[b] & ~batch_seen_[b]) == 0) continue;
        blockCoords(b, at);
        const std::int64_t k0 = blockFirstCell(at);
        for (std::uint64_t bits = block_free_[b] & ~batch_seen_[b]; bits != 0; bits &= bits - 1) {
          const int n = __builtin_ctzll(bits);
          const std::int64_t ci = (at[0] << kBlockShift) + (n >> (2 * kBlockShift));
          const std::int64_t cj = (at[1] << kBlockShift) + ((n >> kBlockShift) & ((1 << kBlockShift) - 1));
          const std::int64_t ck = (at[2] << kBlockShift) + (n & ((1 << kBlockShift) - 1));
          const std::int64_t c = k0 + cell_offset_[n];
          if (testBit(fixed_, c)) continue;  // free for good
          ++bs.hidden;
          const int L = chebyshevToOccupied(ci, cj, ck, needed);
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
      if (testBit(observed_, c) && !testBit(occupied_, c) && !testBit(fixed_, c)) makeStale(c);
    }
  }
  for (std::uint64_t key : update.stale) {
    const auto c = static_cast<std::int64_t>(key);
    if (c < 0 || c >= static_cast<std::int64_t>(value_.size()) || stale_.empty()) continue;
    if (testBit(occupied_, c) || testBit(fixed_, c)) continue;  // (the same map state as closeBatch read: never)
    makeStale(c);
  }
  // The batch's misses of possibly-occupied cells, in their order.
  std::vector<std::uint64_t> held;
  held.swap(held_misses_);
  for (std::uint64_t key : held) applyOne(static_cast<std::int64_t>(key), false);
  if (std::isfinite(update.stamp)) map_time_ = std::max(map_time_, update.stamp);
  updateWatched(++closes_since_full_watch_ >= kFullWatchEvery);
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
