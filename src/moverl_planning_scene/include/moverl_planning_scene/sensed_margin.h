/**
 * \file sensed_margin.h
 * \brief The predictive margin against sensed obstacles (issue 16), ROS-free: how old the map is at a state's time,
 *        and how far a sensed obstacle may have come by the end of a move. OctomapMonitor applies it to the cameras'
 *        stamps; the tunables are config/planning_scene.yaml's octomap: speed_bound, latency, plan_horizon, max_age.
 */
#pragma once

#include <Eigen/Geometry>
#include <limits>
#include <string>
#include <vector>

#include "moverl_planning_scene/planning_scene.h"

namespace moverl_planning_scene {

/// \brief s: a camera seen this little before the world's motions restarted still counts as seen after (the epoch is
///        computed from doubles: a state's stamp minus its time since the restart).
constexpr double kEpochSlack = 1e-3;

/// \brief A camera as the map's age sees it: its frame and the stamp (s) of its last integrated cloud (-infinity: none
///        since start-up or the last clear).
struct CameraSeen {
  std::string frame;
  double stamp = -std::numeric_limits<double>::infinity();
};

/// \brief Map age (s) at time `stamp`: the oldest camera's last integrated cloud decides (a region only one camera
///        sees is as old as that camera's view). Infinite (blind) when there is no camera, when one has never been
///        heard from (every camera the world lists counts, also before its first cloud), or when one was last seen
///        before `epoch` (the world's motions restarted then: its view tells nothing about where moving things are
///        now; kEpochSlack). A cloud newer than the state: 0.
/// \param deciding set to the camera that decides the age (the first blind one when blind; "" when there is none)
double sensedMapAge(const std::vector<CameraSeen>& cameras, double stamp, double epoch,
                    std::string* deciding = nullptr);
/// \brief sensedMapAge of cameras known only by their stamps (unnamed).
double sensedMapAge(const std::vector<double>& last_cloud_stamps, double stamp, double epoch);

/// \brief The margin rule: an obstacle moving at up to speed_bound (m/s) may have come speed_bound x (map age + the
///        move's duration + latency) closer than where the map shows it.
struct SensedMarginRule {
  double speed_bound = 0.0;   ///< m/s
  double latency = 0.0;       ///< s
  double plan_horizon = 0.0;  ///< s: the longest a plan may last (the shield refuses slower ones)
  double max_age = 0.0;       ///< s: an older map knows nothing free (fail closed)
  double max_margin = 0.0;    ///< m: the largest margin the checker builds

  /// \brief The margins of a move of `duration` s (infinite: a plan, plan_horizon) from a state whose map is
  ///        `map_age` s old: the start with no move, the end with the move, a plan with plan_horizon. False with
  ///        *why when the map is blind or older than max_age, or the end's margin exceeds max_margin. A plan's margin
  ///        beyond max_margin is infinite: no plan can be checked (straight moves still can).
  bool compute(double map_age, double duration, SensedMargins* out, std::string* why) const;

  /// \brief The largest margin a check may use: how far an obstacle may come within the oldest map a check accepts
  ///        and the longest plan, speed_bound x (max_age + plan_horizon + latency) (at most
  ///        FclCollisionChecker::kMaxMargin; 0 without a speed bound), plus two cells of `resolution` (m). max_margin
  ///        is set from it; the sensed map reaches that far beyond the robot (sensedMapBounds).
  double largestMargin(double resolution) const;
};

/// \brief Lockstep with octomap/lockstep_lag: the newest cloud stamp (s) the map of a check stamped `stamp` holds. The
///        clouds rendered since the previous check's state are integrated while the simulator moves on, and the next
///        check reads them: a step does not wait for its own views, the map is one step older, and the margin counts
///        that age. The previous check's stamp (`previous`; NaN: none yet) when it is older than `stamp`; the world's
///        motions' restart (`epoch`, 0: none) when that came later, so that the views since the reset are in (without
///        them every camera counts as unseen); `stamp` itself, every cloud, for the first check and for another check
///        of the same state, and when the lag would cost more than `max_margin` (m): an obstacle moving at
///        `speed_bound` (m/s; <= 0: none) may come nearer by its speed times the lag, which the margin then covers.
double lockstepMapCutoff(double previous, double stamp, double epoch, double speed_bound, double max_margin);

/// \brief The box the sensed map covers, centred on the base link (m): everything the robot can reach with its padding
///        (reach_radius: FclCollisionChecker::reachRadius() + padding), widened by the largest margin a check may use
///        (SensedMarginRule::largestMargin). Something farther away cannot touch the robot within that margin's time,
///        so beams are clipped there. OctomapMonitor maps it; map_benchmark maps the same.
Eigen::AlignedBox3d sensedMapBounds(double reach_radius, double largest_margin);

}  // namespace moverl_planning_scene
