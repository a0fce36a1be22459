#include "moverl_planning_scene/cloud_integrator.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstring>

namespace moverl_planning_scene {
namespace {

using Clock = std::chrono::steady_clock;
double since(Clock::time_point* t) {
  const Clock::time_point now = Clock::now();
  const double s = std::chrono::duration<double>(now - *t).count();
  *t = now;
  return s;
}

}  // namespace

bool parseIntegration(const std::string& name, Integration* out, std::string* error) {
  for (Integration i : {Integration::kProjective, Integration::kRayCasting}) {
    if (name == integrationName(i)) {
      *out = i;
      return true;
    }
  }
  if (error != nullptr) *error = "octomap/integration '" + name + "' unknown: one of projective, ray_casting";
  return false;
}

const char* integrationName(Integration integration) {
  return integration == Integration::kProjective ? "projective" : "ray_casting";
}

CloudIntegrator::CloudIntegrator(OccupancyMap* map, const FclCollisionChecker* checker, std::mutex* world_mutex,
                                 const CloudIntegratorOptions& options)
    : map_(map),
      checker_(checker),
      world_mutex_(world_mutex),
      options_(options),
      pool_(std::make_unique<WorkerPool>(options.threads)) {
  // The robot's padding band in the open batch's configurations, as addKnownFree's (a cell reaching into the padding).
  batch_known_free_ = [this](const std::vector<Eigen::Vector3d>& centres, std::vector<std::uint8_t>* known) {
    known->assign(centres.size(), 0);
    const double robot_pad = checker_->options().padding + map_->cellHalfDiagonal();
    for (std::size_t k = 0; k < batch_configurations_.size(); ++k) {
      const auto& q = batch_configurations_[k];
      if (std::find(batch_configurations_.begin(), batch_configurations_.begin() + k, q) !=
          batch_configurations_.begin() + k) {
        continue;  // the same configuration again (every cloud of an instant brings its own)
      }
      checker_->robotPointMask(q.data(), centres, robot_pad, &band_mask_, nullptr, pool_.get());
      for (std::size_t i = 0; i < centres.size(); ++i) (*known)[i] |= band_mask_[i];
    }
  };
}

Integration CloudIntegrator::compute(const CloudView& cloud, const Eigen::Isometry3d& sensor_pose,
                                     const std::vector<std::vector<double>>& configurations, MapUpdate* update,
                                     CloudTiming* timing, std::string* why) {
  const int width = cloud.width, height = cloud.height;
  CloudTiming t;
  Clock::time_point at = Clock::now();
  if (why != nullptr) why->clear();
  // The points in the sensor frame (contiguous x y z, one per pixel: the pinhole fit), their depths (non-finite: no
  // return), and the ones with a return in the map frame, in pixel order. Parts of the rows on the pool: each row's
  // points read and the ones with a return counted; then, from each row's first index (the counts before it summed),
  // their pixels and map-frame points written. Projection fits the pinhole model in the same two passes, while each
  // row is in the cache: the fit's sums per row in the first (a strided subset of rows and columns, about 4,000
  // points whatever the image's size), the model from them between the passes (rows in order: as fitPinhole's), and
  // its check of every point in the second.
  const bool projective = options_.integration == Integration::kProjective;
  std::string reason;  // why projection falls back to ray casting
  bool fitting = false;
  if (projective) {
    if (height < 2) {
      reason = "an unorganized cloud (height 1)";
    } else {
      fitting = pinholeImageSize(width, height, &reason);
    }
  }
  const std::size_t n = static_cast<std::size_t>(std::max(0, width)) * static_cast<std::size_t>(std::max(0, height));
  const int stride = std::max(1, static_cast<int>(std::sqrt(static_cast<double>(n) / 4000.0)));
  // A cloud of packed float32 x, y, z (12 bytes a point, no row padding, as the simulator's and most drivers' are) is
  // read where it lies (as sensor_msgs' PointCloud2Iterator reads fields); any other layout is copied into
  // sensor_xyz_ first. At 640x480 the copy moved 3.7 MB a cloud twice.
  const bool packed = cloud.point_step == 3 * sizeof(float) && cloud.x == 0 && cloud.y == sizeof(float) &&
                      cloud.z == 2 * sizeof(float) && cloud.row_step == 3 * sizeof(float) * std::max(0, width) &&
                      reinterpret_cast<std::uintptr_t>(cloud.data) % alignof(float) == 0;
  if (!packed) sensor_xyz_.resize(3 * n);
  const float* xyz = packed ? reinterpret_cast<const float*>(cloud.data) : sensor_xyz_.data();
  depth_.resize(n);
  has_return_.resize(n);
  const std::size_t rows = static_cast<std::size_t>(std::max(0, height));
  row_first_.assign(rows + 1, 0);
  if (fitting) {
    row_fit_.assign(rows, PinholeFit());
    row_worst_.assign(rows, 0.0);
  }
  const std::size_t rows_per_part = WorkerPool::kCheapPart / std::max<std::size_t>(1, std::max(0, width));
  WorkerPool::runParts(pool_.get(), rows, rows_per_part, [&](std::size_t v0, std::size_t v1, int) {
    for (std::size_t v = v0; v < v1; ++v) {
      const std::uint8_t* row = cloud.data + v * cloud.row_step;
      std::size_t returns = 0;
      for (int u = 0; u < width; ++u) {
        const std::size_t pixel = v * width + u;
        if (!packed) {
          float* copy = &sensor_xyz_[3 * pixel];
          const std::uint8_t* point = row + static_cast<std::size_t>(u) * cloud.point_step;
          std::memcpy(copy, point + cloud.x, sizeof(float));
          std::memcpy(copy + 1, point + cloud.y, sizeof(float));
          std::memcpy(copy + 2, point + cloud.z, sizeof(float));
        }
        const float* s = &xyz[3 * pixel];
        depth_[pixel] = s[2];
        // NaN marks no return in some drivers
        const bool finite = std::isfinite(s[0]) && std::isfinite(s[1]) && std::isfinite(s[2]);
        has_return_[pixel] = finite ? 1 : 0;
        returns += finite ? 1 : 0;
      }
      row_first_[v + 1] = returns;
      if (fitting && v % stride == 0) {
        row_fit_[v].addRow(&xyz[3 * v * width], static_cast<int>(v), width, stride);
      }
    }
  });
  for (std::size_t v = 0; v < rows; ++v) row_first_[v + 1] += row_first_[v];
  PinholeCamera fitted;
  bool fits = false;
  if (fitting) {
    PinholeFit fit;
    for (std::size_t v = 0; v < rows; v += static_cast<std::size_t>(stride)) fit.add(row_fit_[v]);
    fits = fit.solve(width, height, &fitted, &reason);
  }
  pixel_of_.resize(row_first_[rows]);
  points_.resize(row_first_[rows]);
  WorkerPool::runParts(pool_.get(), rows, rows_per_part, [&](std::size_t v0, std::size_t v1, int) {
    for (std::size_t v = v0; v < v1; ++v) {
      std::size_t k = row_first_[v];
      for (std::size_t pixel = v * width, end = pixel + width; pixel < end; ++pixel) {
        if (has_return_[pixel] == 0) continue;
        const float* s = &xyz[3 * pixel];
        pixel_of_[k] = static_cast<std::uint32_t>(pixel);
        points_[k++] = sensor_pose * Eigen::Vector3d(s[0], s[1], s[2]);
      }
      if (fits) {
        row_worst_[v] = pinholeRowResidual(fitted, &xyz[3 * v * width], static_cast<int>(v), kPinholeTolerancePx);
      }
    }
  });
  if (fits) fits = pinholeWithin(*std::max_element(row_worst_.begin(), row_worst_.end()), kPinholeTolerancePx, &reason);
  t.points = since(&at);
  mask_.assign(points_.size(), kPointObstacle);
  for (std::size_t c = 0; c < configurations.size(); ++c) {
    // Each later configuration tests only the points the ones before left (the masks are ORed).
    checker_->robotPointMask(configurations[c].data(), points_, options_.self_filter_padding,
                             c == 0 ? &mask_ : &mask_more_, c == 0 ? nullptr : &mask_, pool_.get());
    if (c > 0) {
      for (std::size_t k = 0; k < mask_.size(); ++k) mask_[k] |= mask_more_[k];
    }
  }
  t.self_filter = since(&at);
  if (options_.filter_static) {
    // Points on the scene's static objects (known exactly: no predictive margin) are the fixture: the space before
    // them is seen free, down to the fixture's surface (static_filter_padding: the cameras' error).
    {
      std::unique_lock<std::mutex> lock;
      if (world_mutex_ != nullptr) lock = std::unique_lock<std::mutex>(*world_mutex_);
      checker_->staticObjectPointMask(points_, options_.static_filter_padding, &mask_more_, pool_.get());
    }
    for (std::size_t k = 0; k < mask_.size(); ++k) {
      if (mask_[k] == kPointObstacle && mask_more_[k] != 0) mask_[k] = kPointOnFixture;
    }
  }
  t.static_filter = since(&at);
  Integration used = Integration::kRayCasting;
  if (projective) {
    if (fits) {
      camera_ = fitted;
      pixel_mask_.assign(n, kPointObstacle);
      WorkerPool::runParts(pool_.get(), points_.size(), WorkerPool::kCheapPart,
                           [&](std::size_t k0, std::size_t k1, int) {
                             for (std::size_t k = k0; k < k1; ++k) pixel_mask_[pixel_of_[k]] = mask_[k];
                           });
      map_->computeUpdateProjective(points_, mask_, depth_, pixel_mask_, camera_, sensor_pose, update, pool_.get());
      used = Integration::kProjective;
    }
    if (used != Integration::kProjective && why != nullptr) *why = reason;
  }
  if (used == Integration::kRayCasting) map_->computeUpdate(points_, mask_, sensor_pose.translation(), update);
  t.update = since(&at);
  if (map_->unknownOccupied()) addKnownFree(configurations, update);
  batch_configurations_.insert(batch_configurations_.end(), configurations.begin(), configurations.end());
  t.known_free = since(&at);
  if (timing != nullptr) *timing = t;
  return used;
}

bool CloudIntegrator::beginView(double stamp, MapUpdate* close, BatchStats* stats) {
  const bool closed = map_->beginView(stamp, close, &batch_known_free_, stats);
  if (closed) batch_configurations_.clear();
  return closed;
}

bool CloudIntegrator::closeBatch(MapUpdate* close, BatchStats* stats) {
  const bool closed = map_->closeBatch(close, stats, &batch_known_free_);
  batch_configurations_.clear();
  return closed;
}

void CloudIntegrator::addKnownFree(const std::vector<std::vector<double>>& configurations, MapUpdate* update) {
  // The cells (centres) inside the boxes that are unobserved and that `mask` puts inside the shapes: free. One mask
  // for the cells of all the boxes (a mask places every shape first; boxes that overlap may list a cell twice).
  auto turn_free = [&](const auto& mask, bool fixed) {
    cell_centers_.clear();
    cell_keys_.clear();
    for (const Eigen::AlignedBox3d& box : boxes_) {
      map_->knownFreeCells(box, fixed, &box_centers_, &box_keys_);
      cell_centers_.insert(cell_centers_.end(), box_centers_.begin(), box_centers_.end());
      cell_keys_.insert(cell_keys_.end(), box_keys_.begin(), box_keys_.end());
    }
    free_keys_.clear();
    if (!cell_centers_.empty()) mask(cell_centers_, &mask_more_);
    for (std::size_t k = 0; k < cell_keys_.size(); ++k) {
      if (mask_more_[k] != 0) free_keys_.push_back(cell_keys_[k]);
    }
    map_->addKnownFree(free_keys_, fixed, update);
  };
  // A cell's centre within half its diagonal of a shape: the cell reaches into the shape. The robot: every cell that
  // reaches into its padding (the start check inflates it by padding against the cells: an unseen cell there would
  // block the robot where it stands); a static object: every cell that reaches into its filter zone.
  const double half_diagonal = map_->cellHalfDiagonal();
  const double robot_pad = checker_->options().padding + half_diagonal;
  const double static_pad = options_.static_filter_padding + half_diagonal;
  for (const auto& q : configurations) {
    checker_->robotBoundingBoxes(q.data(), robot_pad, &boxes_);
    turn_free(
        [&](const std::vector<Eigen::Vector3d>& pts, std::vector<std::uint8_t>* m) {
          checker_->robotPointMask(q.data(), pts, robot_pad, m, nullptr, pool_.get());
        },
        false);
  }
  if (options_.filter_static && static_known_free_) {
    static_known_free_ = false;
    std::unique_lock<std::mutex> lock;
    if (world_mutex_ != nullptr) lock = std::unique_lock<std::mutex>(*world_mutex_);  // the world
    checker_->staticObjectBoxes(static_pad, &boxes_);
    // The cells wholly inside a static object (their eight corners inside its convex shape): nothing passes there.
    solid_keys_.clear();
    for (const Eigen::AlignedBox3d& box : boxes_) {
      map_->cellsIn(box, &box_centers_, &box_keys_);
      corners_.clear();
      const double h = 0.5 * map_->options().resolution;
      for (const Eigen::Vector3d& c : box_centers_) {
        for (int n = 0; n < 8; ++n)
          corners_.emplace_back(c + Eigen::Vector3d(n & 1 ? h : -h, n & 2 ? h : -h, n & 4 ? h : -h));
      }
      checker_->staticObjectSolidMask(corners_, &mask_more_);
      for (std::size_t k = 0; k < box_keys_.size(); ++k) {
        bool all = true;
        for (int n = 0; n < 8 && all; ++n) all = mask_more_[8 * k + n] != 0;
        if (all) solid_keys_.push_back(box_keys_[k]);
      }
    }
    map_->setSolid(solid_keys_);
    turn_free([&](const std::vector<Eigen::Vector3d>& pts,
                  std::vector<std::uint8_t>* m) { checker_->staticObjectPointMask(pts, static_pad, m, pool_.get()); },
              true);
  }
}

}  // namespace moverl_planning_scene
