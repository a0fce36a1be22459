// What the shield needs from a robot driver, without ROS: reading measured joint states by name, accepting states
// slightly outside the joint limits, the path tolerance the padding covers, the real-time window of a move, and what
// a driver's result means for the step.
#pragma once

#include <cstdint>
#include <map>
#include <string>
#include <vector>

#include "moverl_shield/shield_core.h"
#include "moverl_tcpros/call_end.h"

namespace moverl_shield {

/// \brief Picks the controlled joints out of a measured joint state, by name (never by order): real drivers publish
///        gripper and other joints too, in any order, sometimes merged from several sources.
class JointStateMapper {
 public:
  explicit JointStateMapper(std::vector<std::string> joints);
  /// \brief Fill q (and v when velocities has one value per name, else zeros) in the controlled order.
  /// \return "" on success, else why not (a controlled joint missing or listed twice, sizes that do not match).
  std::string extract(const std::vector<std::string>& names, const std::vector<double>& positions,
                      const std::vector<double>& velocities, std::vector<double>* q, std::vector<double>* v) const;
  const std::vector<std::string>& joints() const { return joints_; }

 private:
  std::vector<std::string> joints_;
  std::map<std::string, std::size_t> index_;
};

/// \brief Real encoders report states a little outside the limits (a joint pushed against its stop, controller
///        overshoot). Within `tolerance` of a limit the value is clamped onto it (the checks need states within the
///        limits); beyond it the state is refused.
/// \return "" when every value is within [lower - tolerance, upper + tolerance] (q clamped), else the joint, its value
///         and its limits (q unchanged).
std::string clampToLimits(std::vector<double>* q, const std::vector<double>& lower, const std::vector<double>& upper,
                          double tolerance);
/// \brief clampToLimits, keeping the measured values in *measured when any was clamped (else *measured is cleared):
///        the robot stands there, and the scene checks that state too (ValidateMotion.measured_start).
std::string clampToLimits(std::vector<double>* q, std::vector<double>* measured, const std::vector<double>& lower,
                          const std::vector<double>& upper, double tolerance);

/// \brief Path tolerance per joint (rad or m) that keeps every robot point within `budget` metres of the checked path:
///        a joint error e_i moves no robot point more than r_i * e_i (r_i: the scene's bound on the distance of any
///        robot point from joint i, 1 for prismatic joints), so giving each of the n joints an equal share,
///        e_i = budget / (n * r_i), bounds the sum. \throws std::invalid_argument for a non-positive budget or bound.
std::vector<double> pathTolerances(double budget, const std::vector<double>& radius_bounds);

/// How a call with a deadline ended (the shield's service calls go over moverl_tcpros; its CallEnd is ROS-free).
using moverl_tcpros::CallEnd;

/// \brief control_msgs/FollowJointTrajectoryResult error codes (checked against the message in the node).
enum class TrajectoryError : std::int32_t {
  kSuccessful = 0,
  kInvalidGoal = -1,
  kInvalidJoints = -2,
  kOldHeaderTimestamp = -3,
  kPathToleranceViolated = -4,
  kGoalToleranceViolated = -5,
};

/// \brief How a driver ended a move the shield sent.
enum class DriverEnd {
  kSucceeded,    ///< the move finished within its tolerances
  kAborted,      ///< the driver aborted it while executing
  kRejected,     ///< the driver refused it before moving
  kPreempted,    ///< another goal replaced it (someone else commands the robot)
  kTimedOut,     ///< no result by the deadline (the shield cancelled it)
  kUnreachable,  ///< the driver is not there (no action server, or its connection broke before the move was sent)
  kLost,         ///< the move was sent but no result came back: the connection closed while it was awaited, or the
                 ///< driver answered with an error. It may have been made; it is never sent again
};

/// \brief What a driver call over a service (the simulator's ExecuteTrajectory, ResetRobot) that ended `end` means
///        for its move: kTimedOut -> kTimedOut, kUnreachable -> kUnreachable (never delivered), kClosed and kFailed ->
///        kLost (delivered, result unknown). kAnswered -> kSucceeded (the answer then says how the move ended).
DriverEnd driverEndForCall(CallEnd end);

/// \brief Whether the driver's state after a move that ended `end` is known (the shield adopts it), i.e. not
///        kTimedOut, kUnreachable or kLost.
bool resultKnown(DriverEnd end);

/// \brief The verdict of a step whose decision was `decided` and whose move ended as `end` with `code`.
///
/// | end         | code                                   | verdict                                   |
/// |-------------|----------------------------------------|-------------------------------------------|
/// | succeeded   | any                                    | decided (SAFE, REPLANNED, TRUNCATED, ...) |
/// | aborted     | PATH_ / GOAL_TOLERANCE_VIOLATED        | ABORTED: the robot stopped on the way; the episode ends |
/// | aborted     | anything else                          | EXECUTION_FAILED                          |
/// | rejected    | any (INVALID_GOAL, INVALID_JOINTS, ...) | EXECUTION_FAILED: the driver is unusable as configured |
/// | preempted   | -                                      | EXECUTION_FAILED: another client commands the robot |
/// | timed out   | -                                      | DRIVER_UNAVAILABLE (the goal was cancelled) |
/// | unreachable | -                                      | DRIVER_UNAVAILABLE                        |
/// | lost        | -                                      | DRIVER_UNAVAILABLE (it may have moved: not sent again) |
Verdict verdictForDriverEnd(Verdict decided, DriverEnd end, std::int32_t code);

/// \brief Name of a control_msgs/FollowJointTrajectoryResult error code ("PATH_TOLERANCE_VIOLATED", ...; "CODE <n>"
///        for unknown ones).
std::string trajectoryErrorName(std::int32_t code);

/// \brief The interval of motion time a move may occupy in real time, for the moving-obstacle check.
///
/// The move is checked from the measured state stamped `state_stamp` (it rests there until the move starts) and is
/// stamped to start at `start` (header.stamp of the goal: the controller holds until then); it lasts `duration` and the
/// controller may take `goal_time` more to settle within the goal tolerance. The window [state_stamp, start +
/// duration + goal_time] therefore covers every instant the robot is on the move's path. Times in seconds on the
/// driver's clock; the returned pair is (motion time at state_stamp, window length).
struct MotionWindow {
  double start_time = 0.0;  ///< motion time of the state the move starts from
  double duration = 0.0;    ///< length of the interval the move may occupy
};
MotionWindow realTimeWindow(double state_stamp, double motion_epoch, double start, double duration, double goal_time);

}  // namespace moverl_shield
