/**
 * \file tracked_parts.h
 * \brief People's parts a tracker reports, as the sensed checks use them under safety:=ssm (issue 53), ROS-free.
 *
 * Unmonitored, every occupied cell approaches at ISO 13855's speeds from when the map saw it (SensedMarginRule).
 * A tracked part is also known where it was at its own, newer, stamp. The cells a camera saw occupied within a part's
 * reach of where the part was at the map's time are the part's ("explained" by it), and the part lies both within
 * ISO's margin of them and within its ball: the part's radius, the tracker's error, Z_d and how far the part may
 * travel from its measurement to the end of the move, accelerating at most at max_acceleration from its measured speed
 * (plus the speed's error) up to max_speed (SaRA's model). So an explained cell stops a link only when the link also
 * meets the ball: never more often than ISO's margin alone, less where the track is newer than the map. ISO/TS 15066
 * speaks of this as speed and separation monitoring with the person's speed monitored.
 *
 * What is not trusted to a track:
 * - cells no camera saw occupied (unseen, or stale: possibly occupied since): they may hold anything, they keep ISO's
 *   margin whatever track lies near them;
 * - seen cells not wholly within a part's ball: ISO's margin (a track offset from where the person is explains none
 *   of the person's cells);
 * - a track older than max_age, one stamped in the future, or one with a non-finite value: lost (ISO's margin for
 *   what it would have explained, at once);
 * - a part whose ball holds ISO's margin around every cell it explains: not used (it would change nothing).
 * What is: that a reported part is where the tracker says within `position_error`, carries nothing beyond its radius,
 * that nothing else moves within its reach (a seen cell there is the part's, or still), and that it moved at the
 * reported speed within `speed_error` (ISO/TS 15066 asks the speed monitoring itself to be safety
 * rated: a tracker that under-reports a speed is the one assumption this rule rests on).
 */
#pragma once

#include <Eigen/Geometry>
#include <string>
#include <utility>
#include <vector>

namespace moverl_planning_scene {

/// \brief How far a tracked part may travel: accelerating at max_acceleration from its speed up to max_speed; a part
///        faster than max_speed keeps its speed (the cap never lowers what was measured).
struct PartMotionBound {
  double max_acceleration = 0.0;  ///< m/s^2 (SaRA's model of a person's joints: 20-50)
  double max_speed = 0.0;         ///< m/s
  /// \brief "" when both are finite and >= 0 (and max_speed > 0), else what is wrong.
  std::string problem() const;
  /// \brief m travelled in `t` s (>= 0) from speed `speed` (m/s, >= 0).
  double travel(double speed, double t) const;
};

/// \brief What the checks trust of a tracker (config/planning_scene.yaml octomap/ssm/tracking, each key commented).
struct TrackingRule {
  PartMotionBound motion;
  double position_error = 0.0;  ///< m: a reported position is within this of the part's
  double speed_error = 0.0;     ///< m/s: a reported speed is within this of the part's
  double max_age = 0.0;         ///< s: an older track is lost
  /// \brief "" when valid (finite, >= 0, motion's problem() empty), else what is wrong.
  std::string problem() const;
};

/// \brief One part of a tracked person as last reported (the base frame; REP 155: a frame of a tracked body).
struct TrackedPart {
  std::string id;            ///< the frame (e.g. "r_wrist_67dd1"), for the check's report
  Eigen::Vector3d position;  ///< m, base frame
  double speed = 0.0;        ///< m/s, its measured speed
  double stamp = 0.0;        ///< s: when it was measured (the clock of the checks' stamps)
  double radius = 0.0;       ///< m: the part's extent around position (the body model)
};

/// \brief A part as one check uses it: the seen cells wholly within `explains` of `centre` are its own, and it lies
///        within `keep_out` of `centre` over the move (explains <= keep_out).
struct ExplainedPart {
  std::string id;
  Eigen::Vector3d centre;
  double explains = 0.0;  ///< m
  double keep_out = 0.0;  ///< m
};

/// \brief The parts that a check of a move may use instead of ISO's margin. `now` (s): the check's time (a track
///        older than rule.max_age then, or stamped after it, is lost); `map_time` (s): the time of the map's cells
///        (now - its age); `end` (s): when the move's window ends (the state's time + the move + latency);
///        `iso_margin` (m): the margin the cells get (a part whose ball holds every explained cell grown by it is left
///        out); `uncertainty` (m): Z_d. \throws std::invalid_argument
///        on a rule's problem() or a non-finite time.
std::vector<ExplainedPart> explainParts(const std::vector<TrackedPart>& parts, const TrackingRule& rule, double now,
                                        double map_time, double end, double iso_margin, double uncertainty);

/// \brief The part frames and radii of "<frame> <radius>, ..." (octomap/ssm/tracking/parts): a frame a name of
///        letters, digits and '_', a radius a finite number >= 0 (m), no frame twice. False with *error naming the
///        entry.
bool parsePartRadii(const std::string& text, std::vector<std::pair<std::string, double>>* out, std::string* error);

}  // namespace moverl_planning_scene
