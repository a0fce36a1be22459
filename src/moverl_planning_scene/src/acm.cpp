/**
 * \file acm.cpp
 * \brief FclCollisionChecker: the allowed-collision matrix (link pairs that are adjacent, rigidly attached, always or
 *        never in collision over random configurations are not checked, as MoveIt's setup assistant decides) and its
 *        cache file.
 */
#include <unistd.h>
#include <chrono>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <limits>
#include <random>
#include <sstream>

#include <fcl/geometry/bvh/BVH_model.h>
#include <fcl/geometry/shape/box.h>
#include <fcl/geometry/shape/capsule.h>
#include <fcl/geometry/shape/cone.h>
#include <fcl/geometry/shape/convex.h>
#include <fcl/geometry/shape/cylinder.h>
#include <fcl/geometry/shape/sphere.h>
#include <fcl/math/bv/OBBRSS.h>
#include <fcl/narrowphase/collision.h>
#include <fcl/narrowphase/distance.h>

#include "fcl_checker_internal.h"

namespace moverl_planning_scene {
namespace {

constexpr std::uint64_t kFnvOffset = 1469598103934665603ULL;
constexpr std::uint64_t kFnvPrime = 1099511628211ULL;
constexpr int kAcmFileVersion = 3;  // 2: complete hulls, one geometry per mesh piece; 3: "never" pairs searched
// The targeted search that confirms a "never" pair (searchNeverPair): starts per pair (the random samples where the
// pair's bounding spheres came closest), the first and last step (rad) of the pattern search, distance evaluations
// per start at most.
constexpr int kSearchStarts = 4;
constexpr double kSearchFirstStep = 0.25, kSearchLastStep = 1e-3;
constexpr int kSearchEvaluations = 800;

void fnv(std::uint64_t* h, const void* data, std::size_t n) {
  const auto* p = static_cast<const unsigned char*>(data);
  for (std::size_t i = 0; i < n; ++i) {
    *h ^= p[i];
    *h *= kFnvPrime;
  }
}
void fnvString(std::uint64_t* h, const std::string& s) {
  fnv(h, s.data(), s.size());
  const char sep = '\0';
  fnv(h, &sep, 1);
}
template <typename T>
void fnvValue(std::uint64_t* h, T v) {
  fnv(h, &v, sizeof(v));
}

}  // namespace

std::uint64_t FclCollisionChecker::acmKey() const {
  std::uint64_t h = kFnvOffset;
  fnvValue(&h, kAcmFileVersion);
  fnvString(&h, model_.urdfText());
  for (const auto& j : model_.jointNames()) fnvString(&h, j);
  fnvString(&h, "|fixed|");
  for (const auto& kv : model_.fixedPositions()) {
    fnvString(&h, kv.first);
    fnvValue(&h, kv.second);
  }
  fnvValue(&h, options_.acm_samples);
  fnvValue(&h, options_.acm_seed);
  fnvValue(&h, options_.self_padding);
  fnvValue(&h, static_cast<int>(options_.mesh_mode));
  // Geometry content (mesh files may change while the URDF text does not).
  for (const Geom& g : geoms_) {
    fnvValue(&h, g.radius);
    fnvValue(&h, g.center_local.x());
    fnvValue(&h, g.center_local.y());
    fnvValue(&h, g.center_local.z());
  }
  return h;
}

bool FclCollisionChecker::loadAcm(const std::string& file) {
  std::ifstream in(file);
  if (!in) return false;
  const std::size_t n = model_.linkNames().size();
  std::vector<AcmReason> acm(n * n, AcmReason::kNoGeometry);
  std::string a, b;
  int reason = 0;
  std::size_t count = 0;
  while (in >> a >> b >> reason) {
    const int ia = model_.linkIndex(a), ib = model_.linkIndex(b);
    if (ia < 0 || ib < 0 || reason < 0 || reason > static_cast<int>(AcmReason::kNoGeometry)) return false;
    acm[ia * n + ib] = acm[ib * n + ia] = static_cast<AcmReason>(reason);
    ++count;
  }
  if (count == 0) return false;
  acm_ = acm;
  return true;
}

void FclCollisionChecker::saveAcm(const std::string& file) const {
  std::error_code ec;
  std::filesystem::create_directories(std::filesystem::path(file).parent_path(), ec);
  const std::string tmp = file + ".tmp" + std::to_string(::getpid());
  {
    std::ofstream out(tmp);
    if (!out) return;
    const auto& names = model_.linkNames();
    const std::size_t n = names.size();
    for (std::size_t a = 0; a < n; ++a) {
      for (std::size_t b = a + 1; b < n; ++b) {
        if (acm_[a * n + b] == AcmReason::kNoGeometry) continue;
        out << names[a] << ' ' << names[b] << ' ' << static_cast<int>(acm_[a * n + b]) << '\n';
      }
    }
  }
  std::filesystem::rename(tmp, file, ec);
  if (ec) std::filesystem::remove(tmp, ec);
}

void FclCollisionChecker::computeAcm() {
  const auto t0 = std::chrono::steady_clock::now();
  const std::size_t n = model_.linkNames().size();
  acm_stats_ = AcmStats();
  if (!options_.acm_cache_dir.empty()) {
    char name[64];
    std::snprintf(name, sizeof(name), "acm_%016llx.txt", static_cast<unsigned long long>(acmKey()));
    acm_stats_.cache_file = (std::filesystem::path(options_.acm_cache_dir) / name).string();
    if (loadAcm(acm_stats_.cache_file)) acm_stats_.from_cache = true;
  }
  if (!acm_stats_.from_cache) {
    acm_.assign(n * n, AcmReason::kNoGeometry);
    // Nearest ancestor with collision geometry ("looking through" geometry-less links and fixed joints).
    auto geometry_parent = [&](int l) {
      int p = model_.parentLink(l);
      while (p >= 0 && link_geoms_[p].empty()) p = model_.parentLink(p);
      return p;
    };
    std::vector<std::pair<int, int>> candidates;
    for (std::size_t a = 0; a < n; ++a) {
      if (link_geoms_[a].empty()) continue;
      for (std::size_t b = a + 1; b < n; ++b) {
        if (link_geoms_[b].empty()) continue;
        const int ia = static_cast<int>(a), ib = static_cast<int>(b);
        AcmReason r = AcmReason::kEnabled;
        if (model_.isStatic(ia) && model_.isStatic(ib)) {
          r = AcmReason::kStatic;
        } else if (geometry_parent(ib) == ia || geometry_parent(ia) == ib) {
          r = AcmReason::kAdjacent;
        } else if (model_.drivingJoint(ia) == model_.drivingJoint(ib)) {
          r = AcmReason::kRigid;  // no controlled joint between them
        } else {
          candidates.emplace_back(ia, ib);
        }
        acm_[a * n + b] = acm_[b * n + a] = r;
      }
    }
    if (options_.acm_samples > 0 && !candidates.empty()) {
      // "always": the real shapes touch in every sample; "never": even the padded shapes never touch in the samples
      // and a search for the pair's closest approach (from the samples where they came closest) finds none either.
      std::vector<int> hits(candidates.size(), 0), padded_hits(candidates.size(), 0);
      // Per candidate, the kSearchStarts samples of the smallest gap between its links' padded bounding spheres.
      std::vector<std::vector<std::pair<double, std::vector<double>>>> closest(candidates.size());
      std::mt19937_64 rng(options_.acm_seed);
      const std::size_t dof = model_.dof();
      std::vector<double> q(dof);
      for (int s = 0; s < options_.acm_samples; ++s) {
        for (std::size_t i = 0; i < dof; ++i) {
          std::uniform_real_distribution<double> d(model_.lowerLimits()[i], model_.upperLimits()[i]);
          q[i] = d(rng);
        }
        updateTransforms(q.data());
        for (std::size_t c = 0; c < candidates.size(); ++c) {
          if (linkPairCollides(candidates[c].first, candidates[c].second, true)) {
            ++padded_hits[c];
            if (linkPairCollides(candidates[c].first, candidates[c].second, false)) ++hits[c];
          } else if (padded_hits[c] == 0) {
            keepClosest(sphereGap(candidates[c].first, candidates[c].second), q, &closest[c]);
          }
        }
      }
      for (std::size_t c = 0; c < candidates.size(); ++c) {
        AcmReason r = AcmReason::kEnabled;
        const int a = candidates[c].first, b = candidates[c].second;
        if (padded_hits[c] == 0) {
          const double d = searchNeverPair(a, b, closest[c]);
          if (d > 0.0) {
            r = AcmReason::kNever;
            acm_stats_.never_min_distance = std::min(acm_stats_.never_min_distance, d);
          } else {
            ++acm_stats_.never_refuted;  // the search found them touching: checked
          }
        }
        if (hits[c] == options_.acm_samples) r = AcmReason::kAlways;
        acm_[a * n + b] = acm_[b * n + a] = r;
      }
    }
    if (!acm_stats_.cache_file.empty()) saveAcm(acm_stats_.cache_file);
  }
  rebuildPairLists();
  acm_stats_.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

double FclCollisionChecker::sphereGap(int la, int lb) const {
  double gap = std::numeric_limits<double>::infinity();
  for (int ga : link_geoms_[la]) {
    for (int gb : link_geoms_[lb]) {
      const Geom& a = geoms_[ga];
      const Geom& b = geoms_[gb];
      gap = std::min(gap, (a.world_center - b.world_center).norm() - a.padded_radius - b.padded_radius);
    }
  }
  return gap;
}

void FclCollisionChecker::keepClosest(double gap, const std::vector<double>& q,
                                      std::vector<std::pair<double, std::vector<double>>>* best) const {
  if (best->size() < static_cast<std::size_t>(kSearchStarts)) {
    best->emplace_back(gap, q);
  } else {
    auto worst =
        std::max_element(best->begin(), best->end(), [](const auto& x, const auto& y) { return x.first < y.first; });
    if (gap >= worst->first) return;
    worst->first = gap;
    worst->second = q;
  }
}

double FclCollisionChecker::linkPairDistance(int la, int lb) {
  // Distance between the links' padded shapes: <= 0 when they touch (the self check would flag the pair).
  double best = std::numeric_limits<double>::infinity();
  for (int ga : link_geoms_[la]) {
    for (int gb : link_geoms_[lb]) {
      const Geom& a = geoms_[ga];
      const Geom& b = geoms_[gb];
      if (geomPairCollides(a, b, false, nullptr, /*padded=*/true)) return 0.0;
      fcl::DistanceRequestd req;
      fcl::DistanceResultd res;
      const double d = fcl::distance(a.padded.get(), a.world_tf, b.padded.get(), b.world_tf, req, res);
      // A distance FCL cannot give (negative) falls back on the bounding spheres' gap, a lower bound.
      best = std::min(
          best,
          d >= 0.0 ? d : std::max(0.0, (a.world_center - b.world_center).norm() - a.padded_radius - b.padded_radius));
    }
  }
  return best;
}

double FclCollisionChecker::searchNeverPair(int la, int lb,
                                            const std::vector<std::pair<double, std::vector<double>>>& starts) {
  // The joints that move one link relative to the other (a perturbation changes their relative pose).
  const std::size_t dof = model_.dof();
  std::vector<std::size_t> joints;
  std::vector<double> q0(dof), q1(dof);
  for (std::size_t i = 0; i < dof; ++i) q0[i] = 0.5 * (model_.lowerLimits()[i] + model_.upperLimits()[i]);
  model_.computeLinkTransforms(q0.data(), &link_poses_);
  const Eigen::Isometry3d rel0 = link_poses_[la].inverse() * link_poses_[lb];
  for (std::size_t i = 0; i < dof; ++i) {
    q1 = q0;
    q1[i] += 0.1 * (model_.upperLimits()[i] - model_.lowerLimits()[i]);
    model_.computeLinkTransforms(q1.data(), &link_poses_);
    const Eigen::Isometry3d rel = link_poses_[la].inverse() * link_poses_[lb];
    if ((rel.matrix() - rel0.matrix()).norm() > 1e-9) joints.push_back(i);
  }
  double best = std::numeric_limits<double>::infinity();
  for (const auto& start : starts) {
    // Pattern search: each relevant joint by +-step while the distance drops; halve the step when none does.
    std::vector<double> q = start.second;
    updateTransforms(q.data());
    double d = linkPairDistance(la, lb);
    int evaluations = 1;
    for (double step = kSearchFirstStep; step >= kSearchLastStep && d > 0.0 && evaluations < kSearchEvaluations;) {
      bool improved = false;
      for (std::size_t i : joints) {
        for (double sign : {1.0, -1.0}) {
          const double old = q[i];
          q[i] = std::min(std::max(old + sign * step, model_.lowerLimits()[i]), model_.upperLimits()[i]);
          updateTransforms(q.data());
          const double e = linkPairDistance(la, lb);
          ++evaluations;
          if (e < d) {
            d = e;
            improved = true;
            break;  // keep going this way on the next joint
          }
          q[i] = old;
        }
        if (d <= 0.0) break;
      }
      if (!improved) step *= 0.5;
    }
    best = std::min(best, d);
    if (best <= 0.0) break;
  }
  return best;
}

void FclCollisionChecker::rebuildPairLists() {
  const std::size_t n = model_.linkNames().size();
  self_pairs_.clear();
  for (std::size_t a = 0; a < n; ++a) {
    for (std::size_t b = a + 1; b < n; ++b) {
      switch (acm_[a * n + b]) {
        case AcmReason::kEnabled:
          ++acm_stats_.enabled;
          self_pairs_.emplace_back(static_cast<int>(a), static_cast<int>(b));
          break;
        case AcmReason::kAdjacent:
          ++acm_stats_.adjacent;
          break;
        case AcmReason::kRigid:
          ++acm_stats_.rigid;
          break;
        case AcmReason::kAlways:
          ++acm_stats_.always;
          break;
        case AcmReason::kNever:
          ++acm_stats_.never;
          break;
        default:
          break;
      }
    }
  }
  world_geoms_.clear();
  for (std::size_t g = 0; g < geoms_.size(); ++g) {
    if (!model_.isStatic(geoms_[g].link)) world_geoms_.push_back(static_cast<int>(g));
  }
  // How far a point of one link of each pair moves relative to the other per rad of each joint (checkPath's culling).
  const std::size_t dof = model_.dof();
  pair_joint_radius_.assign(self_pairs_.size(), std::vector<double>(dof, 0.0));
  for (std::size_t p = 0; p < self_pairs_.size(); ++p) {
    const int a = self_pairs_[p].first, b = self_pairs_[p].second;
    for (std::size_t i = 0; i < dof; ++i) pair_joint_radius_[p][i] = linkMotionRadius(a, b, i);
  }
  std::size_t shape_pairs = 0;
  for (const auto& lp : self_pairs_) shape_pairs += link_geoms_[lp.first].size() * link_geoms_[lp.second].size();
  self_memory_.assign(shape_pairs, PairMemory());
}

double FclCollisionChecker::linkMotionRadius(int a, int b, std::size_t i) const {
  const bool moves_a = a >= 0 && model_.jointMovesLink(i, a), moves_b = model_.jointMovesLink(i, b);
  if (moves_a == moves_b) return 0.0;
  double r = 0.0;
  for (int g : link_geoms_[moves_a ? a : b]) r = std::max(r, geom_joint_radius_[g][i]);
  return r;
}

double FclCollisionChecker::segmentMotionBound(const double* q0, const double* q1, int a, int b) const {
  double m = 0.0;
  for (std::size_t i = 0; i < model_.dof(); ++i) m += std::fabs(q1[i] - q0[i]) * linkMotionRadius(a, b, i);
  return m;
}

AcmReason FclCollisionChecker::acmReason(const std::string& link_a, const std::string& link_b) const {
  const int a = model_.linkIndex(link_a), b = model_.linkIndex(link_b);
  if (a < 0 || b < 0 || a == b) return AcmReason::kNoGeometry;
  return acm_[a * model_.linkNames().size() + b];
}

}  // namespace moverl_planning_scene
