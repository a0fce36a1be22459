/**
 * \file sensed_margin.h
 * \brief The predictive margin against sensed obstacles (issue 16), ROS-free: how old the map is at a state's time,
 *        and how far a sensed obstacle may have come by the end of a move. OctomapMonitor applies it to the cameras'
 *        stamps; the tunables are config/planning_scene.yaml's octomap: speed_bound, latency, plan_horizon, max_age.
 */
#pragma once

#include <Eigen/Geometry>
#include <cstdint>
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

/// \brief What a check against the sensed map promises (octomap/safety; docs/sensing.md, "Two safety definitions").
enum class Safety : std::uint8_t {
  /// "separation": nothing sensed ever touches the robot, moving or at rest, provided nothing moves faster than the
  /// speed bound (the world's sensing: speed_bound, else octomap/speed_bound): the world's promise, not the standard's.
  kSeparation = 0,
  /// "ssm": ISO/TS 15066's speed and separation monitoring: the robot stands still before anything sensed can reach
  /// it, whatever the world promises: everything the cameras see or miss approaches at ISO 13855's speeds (Iso13855).
  /// A person may touch a robot at rest (ISO/TS 15066: a robot at standstill is not a moving hazard).
  kSsm = 1,
};
/// \brief "separation" or "ssm".
std::string safetyName(Safety safety);
/// \brief Parse a safety name (exact). False for an unknown name (*safety unchanged).
bool parseSafety(const std::string& name, Safety* safety);
/// \brief The names parseSafety accepts, for messages ("separation, ssm").
std::string safetyNames();

/// \brief ISO 13855's approach distance S = K t + C of a person not monitored: K = hand_speed while S is at most
///        reach_distance (a hand or an arm reaching), else K = body_speed (a walking body) and S at least
///        reach_distance. The speeds are the standard's; C is the sensors' (their detection capability).
struct Iso13855 {
  double hand_speed = 2.0;      ///< m/s
  double body_speed = 1.6;      ///< m/s
  double reach_distance = 0.5;  ///< m
  double intrusion = 0.0;       ///< m, C: how far a part may intrude before the sensors detect it
  /// \brief "" when valid (speeds > 0, distances >= 0, all finite), else what is wrong.
  std::string problem() const;
  /// \brief S (m) for t >= 0 s. \throws std::invalid_argument for a negative or non-finite t, or a problem().
  double distance(double t) const;
};

/// \brief The margin rule: what the map shows may have come closer by the time the robot is at a state, over the map's
///        age + the move's duration + latency: speed_bound times that (separation), or ISO 13855's distance for it
///        plus the position uncertainties (ssm).
struct SensedMarginRule {
  Safety safety = Safety::kSeparation;
  double speed_bound = 0.0;   ///< m/s (separation)
  Iso13855 iso;               ///< ssm: how a person approaches
  double uncertainty = 0.0;   ///< m (ssm): Z_d, the sensors' position error beyond the map's cells
  double latency = 0.0;       ///< s
  double plan_horizon = 0.0;  ///< s: the longest a plan may last (the shield refuses slower ones)
  double max_age = 0.0;       ///< s: an older map knows nothing free (fail closed)
  double max_margin = 0.0;    ///< m: the largest margin the checker builds

  /// \brief m/s: the fastest anything the cameras miss may come (hidden space, the lockstep lag's cost): speed_bound
  ///        (separation) or ISO's hand speed (ssm).
  double speed() const;
  /// \brief m: how far a sensed obstacle may have come in `seconds` (>= 0): the margin before the padding.
  double reach(double seconds) const;
  /// \brief "" when the rule's ssm terms are valid (always under separation), else what is wrong.
  std::string problem() const;

  /// \brief The margins of a move of `duration` s (infinite: a plan, plan_horizon) from a state whose map is
  ///        `map_age` s old: the start with no move, the end with the move, a plan with plan_horizon. False with
  ///        *why when the map is blind or older than max_age, or the end's margin exceeds max_margin. A plan's margin
  ///        beyond max_margin is infinite: no plan can be checked (straight moves still can).
  bool compute(double map_age, double duration, SensedMargins* out, std::string* why) const;

  /// \brief The largest margin a check may use: how far an obstacle may come within the oldest map a check accepts
  ///        and the longest plan, reach(max_age + plan_horizon + latency) (at most FclCollisionChecker::kMaxMargin; 0
  ///        under separation without a speed bound), plus two cells of `resolution` (m). max_margin
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
