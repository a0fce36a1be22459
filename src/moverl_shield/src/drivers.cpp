#include "drivers.h"

#include <cmath>
#include <sstream>
#include <thread>

#include <ros/master.h>

namespace moverl_shield {
namespace {

double seconds(SteadyClock::duration d) { return std::chrono::duration<double>(d).count(); }

trajectory_msgs::JointTrajectory toMsg(const std::vector<std::string>& joints, const TimedTrajectory& t) {
  trajectory_msgs::JointTrajectory msg;
  msg.joint_names = joints;
  msg.points.resize(t.positions.size());
  for (std::size_t k = 0; k < t.positions.size(); ++k) {
    auto& p = msg.points[k];
    p.positions = t.positions[k];
    if (!t.velocities.empty()) p.velocities = t.velocities[k];
    if (!t.accelerations.empty()) p.accelerations = t.accelerations[k];
    p.time_from_start = ros::Duration(t.times[k]);
  }
  return msg;
}

}  // namespace

void fromMsg(const moverl_msgs::ContactReport& msg, ContactReport* out) {
  out->available = msg.available;
  out->stamp = toNanos(msg.header.stamp);
  out->substeps = msg.substeps;
  out->substeps_in_contact = msg.substeps_in_contact;
  out->world_contacts = msg.world_contacts;
  out->self_contacts = msg.self_contacts;
  out->moving_contacts = msg.moving_contacts;
  out->resting_contacts = msg.resting_contacts;
  out->pairs.resize(msg.pairs.size());
  for (std::size_t k = 0; k < msg.pairs.size(); ++k) {
    out->pairs[k].a = msg.pairs[k].a;
    out->pairs[k].b = msg.pairs[k].b;
    out->pairs[k].depth = msg.pairs[k].depth;
  }
  out->total_contact_substeps = msg.total_contact_substeps;
}

void toMsg(const ContactReport& r, moverl_msgs::ContactReport* out) {
  out->available = r.available;
  out->header.stamp.fromNSec(static_cast<std::uint64_t>(r.stamp));
  out->substeps = r.substeps;
  out->substeps_in_contact = r.substeps_in_contact;
  out->world_contacts = r.world_contacts;
  out->self_contacts = r.self_contacts;
  out->moving_contacts = r.moving_contacts;
  out->resting_contacts = r.resting_contacts;
  out->pairs.resize(r.pairs.size());
  for (std::size_t k = 0; k < r.pairs.size(); ++k) {
    out->pairs[k].a = r.pairs[k].a;
    out->pairs[k].b = r.pairs[k].b;
    out->pairs[k].depth = r.pairs[k].depth;
  }
  out->total_contact_substeps = r.total_contact_substeps;
}

// ------------------------------------------------------------------------------------------------ SimServiceDriver
SimServiceDriver::SimServiceDriver(ros::NodeHandle nh, const std::vector<std::string>& joints,
                                   const std::vector<double>& lower, const std::vector<double>& upper,
                                   const std::string& execute_service, const std::string& reset_service,
                                   const DriverOptions& options)
    : mapper_(joints),
      lower_(lower),
      upper_(upper),
      options_(options),
      execute_(nh.resolveName(execute_service)),
      reset_(nh.resolveName(reset_service)) {
  // States come with every response (in lockstep nothing moves between calls); the topic gives the first one only, so
  // that the simulator publishes nothing per step once this is done. Whoever else moves the simulated robot must
  // reset it through this shield before stepping through it (the tests with a second shield do).
  state_sub_ = nh.subscribe("joint_states", 1, &SimServiceDriver::onJointState, this);
}

void SimServiceDriver::onJointState(const sensor_msgs::JointStateConstPtr& msg) {
  std::lock_guard<std::mutex> lock(mutex_);
  if (have_state_) return;
  adopt(*msg, &state_error_);
}

bool SimServiceDriver::adopt(const sensor_msgs::JointState& msg, std::string* error) {
  RobotState s;
  std::vector<double> v;
  std::string bad = mapper_.extract(msg.name, msg.position, msg.velocity, &s.q, &v);
  if (bad.empty()) bad = clampToLimits(&s.q, &s.measured, lower_, upper_, options_.limit_tolerance);
  if (!bad.empty()) {
    *error = bad;
    return false;
  }
  s.stamp = toNanos(msg.header.stamp);
  state_ = std::move(s);
  have_state_ = true;
  error->clear();
  return true;
}

bool SimServiceDriver::currentState(RobotState* state, std::string* error) {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    if (!have_state_) {
      *error = state_error_.empty() ? "no joint state received yet from the simulator (topic joint_states or ~reset)"
                                    : state_error_;
      return false;
    }
    *state = state_;
  }
  if (state_sub_) state_sub_.shutdown();  // outside the lock: shutdown waits for a callback that is running
  return true;
}

MoveResult SimServiceDriver::execute(const TimedTrajectory& trajectory, double) {
  MoveResult out;
  moverl_msgs::ExecuteTrajectory ex;
  ex.request.trajectory = toMsg(mapper_.joints(), trajectory);
  ex.request.path_tolerance = path_tolerance_;
  const double timeout = trajectory.duration() + options_.result_margin;
  ex.request.not_after = wallSeconds() + timeout;  // a stalled simulator that wakes up must not start it late
  const auto t0 = SteadyClock::now();
  const CallEnd end = execute_.call(ex, timeout);
  out.seconds = seconds(SteadyClock::now() - t0);
  if (end != CallEnd::kAnswered) {
    out.end = driverEndForCall(end);  // closed or failed after the move was sent: lost, never sent again
    std::ostringstream m;
    m << "simulator service " << execute_.name() << ": " << callEndName(end) << " after " << out.seconds << " s ("
      << execute_.error() << ")";
    out.message = m.str();
    return out;
  }
  {
    std::lock_guard<std::mutex> lock(mutex_);
    std::string bad;
    if (!adopt(ex.response.state, &bad)) {
      out.end = DriverEnd::kUnreachable;
      out.message = "simulator returned an unusable state: " + bad;
      return out;
    }
  }
  fromMsg(ex.response.contacts, &out.contacts);
  using Res = moverl_msgs::ExecuteTrajectory::Response;
  switch (ex.response.outcome) {
    case Res::SUCCESS:
      out.end = DriverEnd::kSucceeded;
      break;
    case Res::PATH_TOLERANCE_VIOLATED:
      out.end = DriverEnd::kAborted;
      out.error_code = static_cast<std::int32_t>(TrajectoryError::kPathToleranceViolated);
      break;
    default:
      out.end = DriverEnd::kRejected;
      out.error_code = static_cast<std::int32_t>(TrajectoryError::kInvalidGoal);
      break;
  }
  out.message = ex.response.message;
  return out;
}

bool SimServiceDriver::teleport(const std::vector<double>& q, RobotState* after, Nanos* motion_epoch,
                                std::string* error, bool* unreachable) {
  moverl_msgs::ResetRobot srv;
  srv.request.positions = q;
  srv.request.not_after = wallSeconds() + options_.result_margin;
  const CallEnd end = reset_.call(srv, options_.result_margin);
  if (end != CallEnd::kAnswered) {
    *error = "simulator reset service " + reset_.name() + ": " + callEndName(end) +
             (end == CallEnd::kUnreachable ? " (hardware drivers have none): " : ": ") + reset_.error();
    return false;
  }
  if (!srv.response.success) {
    *error = srv.response.message;
    *unreachable = srv.response.unreachable;
    return false;
  }
  std::lock_guard<std::mutex> lock(mutex_);
  if (!adopt(srv.response.state, error)) return false;
  *after = state_;
  *motion_epoch = static_cast<Nanos>(srv.response.motion_epoch.toNSec());  // the simulator's: restarted or not
  return true;
}

// ------------------------------------------------------------------------------------ FollowJointTrajectoryDriver
FollowJointTrajectoryDriver::FollowJointTrajectoryDriver(ros::NodeHandle nh, const std::vector<std::string>& joints,
                                                         const std::vector<double>& lower,
                                                         const std::vector<double>& upper, const std::string& action,
                                                         const std::string& joint_states, const DriverOptions& options)
    : mapper_(joints),
      lower_(lower),
      upper_(upper),
      action_name_(action),
      joint_states_topic_(joint_states),
      options_(options) {
  client_ = std::make_unique<Client>(nh, action, /*spin_thread=*/false);
  state_sub_ = nh.subscribe(joint_states, 10, &FollowJointTrajectoryDriver::onJointState, this,
                            ros::TransportHints().tcpNoDelay());
}

void FollowJointTrajectoryDriver::onJointState(const sensor_msgs::JointStateConstPtr& msg) {
  std::vector<double> q, v;
  const std::string bad = mapper_.extract(msg->name, msg->position, msg->velocity, &q, &v);
  {
    std::lock_guard<std::mutex> lock(mutex_);
    state_error_ = bad;
    if (bad.empty()) {
      q_ = std::move(q);
      stamp_ = msg->header.stamp;
      received_ = SteadyClock::now();
      ++states_;
    }
  }
  state_cv_.notify_all();
}

bool FollowJointTrajectoryDriver::waitForStateAfter(SteadyClock::time_point after, SteadyClock::time_point until) {
  std::unique_lock<std::mutex> lock(mutex_);
  return state_cv_.wait_until(lock, until, [&] { return states_ > 0 && received_ > after; });
}

namespace {
/// Nodes that publish `topic` (from the master), for messages that name the driver's node.
std::string publishersOf(const std::string& topic) {
  XmlRpc::XmlRpcValue args, result, payload;
  args[0] = ros::this_node::getName();
  if (!ros::master::execute("getSystemState", args, result, payload, false)) return "";
  for (int i = 0; i < payload[0].size(); ++i) {
    if (static_cast<std::string>(payload[0][i][0]) != topic) continue;
    std::string nodes;
    for (int k = 0; k < payload[0][i][1].size(); ++k) {
      nodes += (nodes.empty() ? "" : ", ") + static_cast<std::string>(payload[0][i][1][k]);
    }
    return nodes;
  }
  return "";
}
}  // namespace

bool FollowJointTrajectoryDriver::waitUntilReady(double timeout, std::string* error) {
  const auto until = after(timeout);
  while (SteadyClock::now() < until) {
    bool have_state;
    {
      std::lock_guard<std::mutex> lock(mutex_);
      have_state = states_ > 0;
    }
    if (client_->isServerConnected() && have_state) {
      const std::string node = publishersOf(ros::names::resolve(action_name_) + "/status");
      if (!node.empty()) action_name_ += " (node " + node + ")";
      return true;
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(20));  // start-up only
  }
  std::lock_guard<std::mutex> lock(mutex_);
  *error = std::string(client_->isServerConnected() ? "" : "no action server " + action_name_ + "; ") +
           (states_ > 0 ? ""
                        : "no usable joint state on " + joint_states_topic_ +
                              (state_error_.empty() ? "" : " (" + state_error_ + ")")) +
           " after " + std::to_string(timeout) + " s";
  return false;
}

bool FollowJointTrajectoryDriver::currentState(RobotState* state, std::string* error) {
  // The state must have arrived after the last move ended (the robot's final state, not one on the way), and be
  // fresh: younger than max_state_age by arrival (a stalled driver stops publishing) and by stamp (clocks agree).
  const auto now = SteadyClock::now();
  const auto max_age =
      std::chrono::duration_cast<SteadyClock::duration>(std::chrono::duration<double>(options_.max_state_age));
  SteadyClock::time_point newer_than;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    newer_than = std::max(last_move_end_, now - max_age);
  }
  if (!waitForStateAfter(newer_than, now + max_age)) {
    std::lock_guard<std::mutex> lock(mutex_);
    std::ostringstream m;
    if (states_ == 0) {
      m << "no joint state on " << joint_states_topic_ << " yet";
    } else {
      m << "no joint state on " << joint_states_topic_ << " for " << seconds(SteadyClock::now() - received_)
        << " s (max_state_age " << options_.max_state_age << " s): failing closed";
    }
    if (!state_error_.empty()) m << "; the last message was unusable: " << state_error_;
    *error = m.str();
    return false;
  }
  std::lock_guard<std::mutex> lock(mutex_);
  const double stamp_age = ros::Time::now().toSec() - stamp_.toSec();  // doubles: any stamp is safe
  if (std::fabs(stamp_age) > options_.max_state_age) {
    std::ostringstream m;
    m << "the joint state's stamp is " << stamp_age << " s from this node's clock (max_state_age "
      << options_.max_state_age << " s): synchronise the clocks of the robot's host and this one, or check "
      << "/use_sim_time";
    *error = m.str();
    return false;
  }
  state->q = q_;
  state->stamp = toNanos(stamp_);
  const std::string bad = clampToLimits(&state->q, &state->measured, lower_, upper_, options_.limit_tolerance);
  if (!bad.empty()) {
    *error = "measured state refused: " + bad;
    return false;
  }
  return true;
}

MoveResult FollowJointTrajectoryDriver::execute(const TimedTrajectory& trajectory, double start_seconds) {
  const ros::Time start = start_seconds > 0.0 ? ros::Time(start_seconds) : ros::Time();
  MoveResult out;
  out.contacts.available = false;
  if (!client_->isServerConnected()) {
    out.end = DriverEnd::kUnreachable;
    out.message = "no FollowJointTrajectory action server at " + action_name_;
    return out;
  }
  control_msgs::FollowJointTrajectoryGoal goal;
  goal.trajectory = toMsg(mapper_.joints(), trajectory);
  goal.trajectory.header.stamp = start;
  const auto& joints = mapper_.joints();
  for (std::size_t i = 0; i < joints.size() && i < path_tolerance_.size(); ++i) {
    control_msgs::JointTolerance path;
    path.name = joints[i];
    path.position = path_tolerance_[i];
    goal.path_tolerance.push_back(path);
    control_msgs::JointTolerance end = path;
    end.velocity = options_.stopped_velocity_tolerance;
    goal.goal_tolerance.push_back(end);
  }
  goal.goal_time_tolerance = ros::Duration(options_.goal_time);

  std::uint64_t id;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    id = ++goal_id_;
    goal_done_ = false;
  }
  auto done = [this, id](const actionlib::SimpleClientGoalState& state,
                         const control_msgs::FollowJointTrajectoryResultConstPtr& result) {
    {
      std::lock_guard<std::mutex> lock(mutex_);
      if (id != goal_id_) return;  // a goal we gave up on
      goal_done_ = true;
      goal_state_ = state;
      goal_result_ = result ? *result : control_msgs::FollowJointTrajectoryResult();
    }
    result_cv_.notify_all();
  };
  const auto t0 = SteadyClock::now();
  // Deadlines. The move ends at start + duration on the driver's clock; the driver has goal_time + result_margin more
  // to report. The driver's clock may run slower than the wall (a simulator that cannot keep up), so that deadline is
  // checked on the driver's clock (ros::Time: /clock or wall). A stalled driver stops its clock and its joint states:
  // no joint state for max_state_age of wall time is a stall, whatever the clock says.
  const ros::Time move_end = (start.isZero() ? ros::Time::now() : start) + ros::Duration(trajectory.duration());
  const double driver_deadline = move_end.toSec() + options_.goal_time + options_.result_margin;
  const auto max_silence =
      std::chrono::duration_cast<SteadyClock::duration>(std::chrono::duration<double>(options_.max_state_age));
  client_->sendGoal(goal, done);
  bool finished = false;
  std::string why;
  {
    std::unique_lock<std::mutex> lock(mutex_);
    while (!finished) {
      finished = result_cv_.wait_for(lock, std::chrono::milliseconds(20), [&] { return goal_done_; });
      if (finished) break;
      const auto now = SteadyClock::now();
      if (now - std::max(received_, t0) > max_silence) {
        why = "sent no joint state for " + std::to_string(seconds(now - std::max(received_, t0))) + " s (stalled?)";
        break;
      }
      if (ros::Time::now().toSec() > driver_deadline) {
        why = "gave no result by the move's end + goal_time + result_margin (" +
              std::to_string(goal_time_plus_margin()) + " s after it, on the driver's clock)";
        break;
      }
    }
    if (!finished) ++goal_id_;  // ignore whatever comes for this goal from now on
    last_move_end_ = SteadyClock::now();
  }
  out.seconds = seconds(SteadyClock::now() - t0);
  if (!finished) {
    client_->cancelGoal();
    out.end = DriverEnd::kTimedOut;
    std::ostringstream m;
    m << "the FollowJointTrajectory driver " << action_name_ << " " << why << ", " << out.seconds
      << " s after the goal was sent: goal cancelled, failing closed (a stalled driver may not obey the cancel)";
    out.message = m.str();
    return out;
  }
  std::lock_guard<std::mutex> lock(mutex_);
  out.error_code = goal_result_.error_code;
  out.message = goal_result_.error_string;
  using S = actionlib::SimpleClientGoalState;
  switch (goal_state_.state_) {
    case S::SUCCEEDED:
      out.end = out.error_code == 0 ? DriverEnd::kSucceeded : DriverEnd::kAborted;
      break;
    case S::ABORTED:
      out.end = DriverEnd::kAborted;
      break;
    case S::REJECTED:
      out.end = DriverEnd::kRejected;
      break;
    case S::PREEMPTED:
    case S::RECALLED:
      out.end = DriverEnd::kPreempted;
      if (out.message.empty()) out.message = "the goal was preempted: another client commands the robot";
      break;
    default:
      out.end = DriverEnd::kUnreachable;
      out.message = "action ended in state " + goal_state_.toString();
      break;
  }
  if (out.end != DriverEnd::kSucceeded && out.error_code != 0) {
    out.message = trajectoryErrorName(out.error_code) + (out.message.empty() ? "" : ": " + out.message);
  }
  return out;
}

}  // namespace moverl_shield
