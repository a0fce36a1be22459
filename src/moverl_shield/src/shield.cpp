#include "moverl_shield/shield.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <utility>

namespace moverl_shield {
namespace mps = moverl_planning_scene;

Nanos toNanos(double s) { return static_cast<Nanos>(std::llround(s * 1e9)); }

Shield::Shield(const ShieldOptions& options, Driver* driver, Scene* scene, const Clock* clock)
    : options_(options), driver_(driver), scene_(scene), clock_(clock) {
  const mps::RobotModel& model = scene_->model();
  joints_ = model.jointNames();
  options_.limits.velocity = model.velocityLimits();  // the URDF's: the one source of the velocity limits
  if (!options_.limits.acceleration.empty() && options_.limits.acceleration.size() != joints_.size()) {
    throw std::invalid_argument("the robot's acceleration limits must have one value per controlled joint (" +
                                std::to_string(joints_.size()) + ")");
  }
}

std::string Shield::describe(CallEnd end, double timeout) const {
  switch (end) {
    case CallEnd::kTimedOut:
      return "service " + scene_->name() + " did not answer within its deadline of " + std::to_string(timeout) + " s";
    case CallEnd::kClosed:
      return "service " + scene_->name() + " closed the connection while its answer was awaited";
    case CallEnd::kFailed:
      return "service " + scene_->name() + " failed to answer";
    default:
      return "service " + scene_->name() + " is unreachable";
  }
}

bool Shield::lastState(RobotState* state) const {
  if (!have_state_) return false;
  *state = last_;
  return true;
}

void Shield::adopt(const RobotState& s) {
  last_ = s;
  have_state_ = true;
}

// ----------------------------------------------------------------------------------------------------------- set-up
bool Shield::ensureSceneFacts(std::string* error) {
  if (scene_facts_) return true;
  const double timeout = options_.scene_margin;
  Nanos epoch = 0;
  const CallEnd end = scene_->motionEpoch(&epoch, timeout);
  if (end != CallEnd::kAnswered) {
    *error = describe(end, timeout);
    return false;
  }
  SceneFacts facts;
  if (!scene_->facts(&facts, error)) return false;
  if (facts.joint_radius_bounds.size() != joints_.size()) {
    *error = "the planning scene's joint_radius_bounds has " + std::to_string(facts.joint_radius_bounds.size()) +
             " values for " + std::to_string(joints_.size()) + " joints";
    return false;
  }
  // The padding leaves padding - path_resolution / 2 between the robot and any obstacle along a checked path
  // (checked states are `padding` clear; between two of them no point moves more than path_resolution). Tracking
  // errors must stay within that.
  const double slack = facts.padding - facts.path_resolution / 2.0;
  if (options_.tracking_budget > slack + 1e-12) {
    *error = "tracking_budget " + std::to_string(options_.tracking_budget) +
             " m exceeds what the padding leaves along a path (" + std::to_string(slack) +
             " m = padding - path_resolution / 2)";
    return false;
  }
  driver_->setPathTolerance(pathTolerances(options_.tracking_budget, facts.joint_radius_bounds));
  if (!epoch_known_) motion_epoch_ = epoch;  // a teleport before this told a newer one
  epoch_known_ = true;
  planning_time_ = facts.planning_time;
  scene_facts_ = true;
  return true;
}

// ------------------------------------------------------------------------------------------------------------- step
void Shield::step(const StepRequest& req, StepResult* res, bool record_executed) {
  res->message.clear();
  res->pairs.clear();
  res->start.q.clear();
  res->start.measured.clear();
  res->start.stamp = 0;
  res->contacts.available = driver_->sensesContacts();
  res->contacts.stamp = 0;
  res->contacts.substeps = res->contacts.substeps_in_contact = 0;
  res->contacts.world_contacts = res->contacts.self_contacts = 0;
  res->contacts.moving_contacts = res->contacts.resting_contacts = 0;
  res->contacts.pairs.clear();
  res->state_check_time = res->path_check_time = res->planning_time = res->execution_time = 0.0;
  res->unsafe_cause = 0;
  res->truncated_fraction = -1.0;
  res->driver_error_code = 0;
  res->map_age = -1.0;
  res->sensed_margin = 0.0;
  res->executed = TimedTrajectory();
  res->verdict = run(req, res, record_executed);
  if (res->contacts.stamp == 0) {
    // No motion this step: no contacts, as far as the driver's last report goes.
    res->contacts.stamp = last_.stamp;
    res->contacts.total_contact_substeps = total_contact_substeps_;
  }
}

Verdict Shield::run(const StepRequest& req, StepResult* res, bool record_executed) {
  if (req.not_after > 0.0 && clock_->wall() > req.not_after) {
    res->message = "request served after its caller gave up on it (the shield was stalled): nothing moves";
    return Verdict::kInvalidRequest;
  }
  std::string bad = validateTarget(req.target, joints_.size());
  if (bad.empty() && !(std::isfinite(req.duration) && req.duration >= 0.0 && req.duration <= kMaxStepDuration)) {
    bad = "duration must be finite, >= 0 and <= " + std::to_string(kMaxStepDuration) + " s, got " +
          std::to_string(req.duration);
  }
  if (!bad.empty()) {
    res->message = bad;
    return Verdict::kInvalidRequest;
  }
  std::string error;
  RobotState& s = res->start;
  if (!driver_->currentState(&s, &error)) {
    res->message = "joint states: " + error;
    return Verdict::kStateUnavailable;
  }
  adopt(s);
  const bool real_time = driver_->realTime();
  if (!ensureSceneFacts(&error)) {
    res->message = "planning scene: " + error + ": failing closed, robot held";
    return Verdict::kSceneUnavailable;
  }
  if (!options_.enabled)
    return move(passThrough(s.q, req.target).waypoints, Verdict::kUnchecked, req.duration, options_.limits, res,
                record_executed);
  mps::MotionRequest& q = query_;
  q.start = s.q;
  q.goal = req.target;
  q.measured_start = s.measured;
  q.plan_on_path_collision = wantsPlan(options_.strategy);
  q.find_last_free = wantsLastFree(options_.strategy);
  double straight;
  try {
    straight =
        timeTrajectory(options_.profile, {s.q, req.target}, options_.limits, req.duration, options_.sample_period)
            .duration();
  } catch (const std::exception& e) {
    res->message = std::string("cannot time the move: ") + e.what();
    return Verdict::kExecutionFailed;
  }
  q.retreat_reach.clear();
  if (options_.strategy == Strategy::kRetreat) {
    // A move that backs away lasts as long as the commanded one would, at the velocity limits.
    const double t = std::max(req.duration, straight);
    q.retreat_reach.resize(joints_.size());
    for (std::size_t i = 0; i < joints_.size(); ++i) {
      q.retreat_reach[i] = options_.limits.velocity[i] * options_.limits.velocity_scale * t;
    }
  }
  const double check_begin = real_time ? clock_->now() : 0.0;
  setWindow(s, check_begin, straight, &q);
  const double timeout = sceneTimeout();
  q.time_budget = timeout;  // the scene answers within it (a wait for clouds, a retreat search end early)
  mps::MotionCheck& a = answer_;
  const CallEnd end = scene_->validate(q, &a, timeout);
  if (end != CallEnd::kAnswered) {
    res->message = "planning scene: " + describe(end, timeout) + ": failing closed, robot held";
    return Verdict::kSceneUnavailable;
  }
  res->pairs.swap(a.pairs);
  res->map_age = a.map_age;
  res->sensed_margin = a.sensed_margin;
  res->state_check_time = a.state_check_time;
  res->path_check_time = a.path_check_time;
  res->planning_time = a.planning_time;
  res->message = a.message;
  SceneAnswer answer;
  answer.outcome = a.outcome;
  answer.replanned = a.replanned;
  answer.plan.swap(a.path);
  answer.last_free_fraction = a.last_free_fraction;
  answer.last_free_state.swap(a.last_free_state);
  answer.retreat_state.swap(a.retreat_state);
  Decision decision = decide(options_.strategy, answer, s.q, req.target);
  res->unsafe_cause = decision.unsafe_cause;
  res->truncated_fraction = decision.truncated_fraction;
  const bool windowed = decision.verdict == Verdict::kSafe || decision.verdict == Verdict::kTruncated;
  if (real_time && windowed && clock_->now() - check_begin > options_.check_budget) {
    // The window checked assumed the move starts within check_budget + start_lead of the check: too late now.
    res->message = "planning scene answered after " + std::to_string(clock_->now() - check_begin) +
                   " s, beyond the real-time check_budget of " + std::to_string(options_.check_budget) +
                   " s: the move was not sent (failing closed)";
    return Verdict::kSceneUnavailable;
  }
  // Lockstep: a robot held still holds through the driver for the step's duration, so that the obstacles keep
  // moving. Safe: it rests at a state checked free of every obstacle's whole motion envelope.
  const bool hold_through_driver = !real_time && a.moving_obstacles && req.duration > 0.0;
  if (decision.waypoints.empty() && hold_through_driver && decision.verdict != Verdict::kSceneUnavailable &&
      decision.verdict != Verdict::kInvalidRequest) {
    decision.waypoints = {s.q};
  }
  if (decision.verdict == Verdict::kReplanned && a.plan_horizon > 0.0) {
    // Sensed obstacles: the plan was checked with the margin of a move that ends plan_horizon after the state's
    // stamp. In real time the move ends (time since the state: its age and the planning) + start_lead + the plan +
    // goal_time after it; a longer window is not covered by that check.
    double planned = 0.0;
    try {
      planned =
          timeTrajectory(options_.profile, decision.waypoints, options_.limits, req.duration, options_.sample_period)
              .duration();
    } catch (const std::exception& e) {
      res->message = std::string("cannot time the plan: ") + e.what();
      return Verdict::kExecutionFailed;
    }
    const double since_state = real_time ? clock_->now() - seconds(s.stamp) : 0.0;
    const double window = real_time ? since_state + options_.start_lead + planned + options_.goal_time : planned;
    if (window > a.plan_horizon) {
      res->message += "; the plan lasts " + std::to_string(planned) + " s" +
                      (real_time ? " (" + std::to_string(window) +
                                       " s from the state's stamp to its end with the state's age, the planning, the "
                                       "start lead and the goal time)"
                                 : "") +
                      ", longer than the sensed margin covers (" + std::to_string(a.plan_horizon) + " s): held still";
      decision.verdict = Verdict::kDiscardedPath;
      decision.waypoints.clear();
      if (hold_through_driver) decision.waypoints = {s.q};
    }
  }
  if (decision.verdict == Verdict::kTruncated) {
    res->message += "; truncated: moved to the last safe state at fraction " +
                    std::to_string(decision.truncated_fraction) + " of the straight path";
  }
  if (decision.waypoints.empty()) return decision.verdict;
  return move(decision.waypoints, decision.verdict, req.duration, options_.limits, res, record_executed);
}

void Shield::setWindow(const RobotState& s, double check_begin, double duration, mps::MotionRequest* q) const {
  if (driver_->realTime()) {
    const MotionWindow w =
        realTimeWindow(seconds(s.stamp), seconds(motion_epoch_),
                       check_begin + options_.check_budget + options_.start_lead, duration, options_.goal_time);
    q->start_time = w.start_time;
    q->duration = w.duration;
  } else {
    q->start_time = seconds(s.stamp - motion_epoch_);
    q->duration = duration;
  }
  // The absolute time of start_time (the sensed map's age is measured against it); never 0 (0: unstamped).
  const double stamp = seconds(motion_epoch_) + q->start_time;
  q->stamp = stamp > 0.0 ? stamp : 1e-9;
}

Verdict Shield::move(const Waypoints& waypoints, Verdict decided, double min_duration, const TimingLimits& limits,
                     StepResult* res, bool record_executed) {
  TimedTrajectory trajectory;
  try {
    trajectory = timeTrajectory(options_.profile, waypoints, limits, min_duration, options_.sample_period);
  } catch (const std::exception& e) {
    res->message = std::string("cannot time the trajectory: ") + e.what();
    return Verdict::kExecutionFailed;
  }
  if (!(trajectory.duration() > 0.0)) return decided;  // nothing to move (e.g. a reset to where the robot stands)
  const double start = driver_->realTime() ? clock_->now() + options_.start_lead : 0.0;
  MoveResult r = driver_->execute(trajectory, start);
  if (record_executed) res->executed = std::move(trajectory);
  res->execution_time = r.seconds;
  res->driver_error_code = r.error_code;
  if (r.contacts.available) {
    res->contacts = std::move(r.contacts);
    total_contact_substeps_ = res->contacts.total_contact_substeps;
  }
  const Verdict verdict = verdictForDriverEnd(decided, r.end, r.error_code);
  if (verdict != decided) {
    res->message =
        "driver " + driver_->name() + ": " + r.message + (res->message.empty() ? "" : " (" + res->message + ")");
  }
  if (resultKnown(r.end)) {
    RobotState after;
    std::string error;
    if (!driver_->currentState(&after, &error)) {
      res->message = "joint states after the move: " + error;
      return Verdict::kStateUnavailable;
    }
    adopt(after);
  }
  return verdict;
}

// ------------------------------------------------------------------------------------------------------------ reset
void Shield::reset(const ResetRequest& req, ResetResult* res) {
  *res = ResetResult();
  std::string error;
  if (req.not_after > 0.0 && clock_->wall() > req.not_after) {
    res->message = "reset served after its caller gave up on it (the shield was stalled): nothing moves";
    return;
  }
  if (req.positions.empty()) {  // start the episode where the robot is
    RobotState s;
    if (!driver_->currentState(&s, &error)) {
      res->message = "joint states: " + error;
      return;
    }
    adopt(s);
    if (!ensureSceneFacts(&error)) {
      res->message = "planning scene: " + error;
      return;
    }
    res->success = true;
    res->motion_epoch = motion_epoch_;
    return;
  }
  const std::string bad = validateTarget(req.positions, joints_.size());
  if (!bad.empty()) {
    res->message = bad;
    return;
  }
  if (driver_->canTeleport()) {
    RobotState after;
    Nanos epoch = 0;
    if (!driver_->teleport(req.positions, &after, &epoch, &error, &res->unreachable)) {
      res->message = error;
      return;
    }
    motion_epoch_ = epoch;  // the simulator's: the teleport's stamp where it restarted the obstacles' motions
    epoch_known_ = true;
    adopt(after);
    res->success = true;
  } else if (!ensureSceneFacts(&error)) {
    res->message = "planning scene: " + error;
    return;
  } else {
    plannedReset(req.positions, res);
  }
  res->motion_epoch = motion_epoch_;
}

namespace {
/// The straight path a -> b cut into equal pieces, each lasting at most `horizon` s at this timing: the waypoints
/// after a (b last).
Waypoints piecesOf(const std::vector<double>& a, const std::vector<double>& b, Profile profile,
                   const TimingLimits& limits, double sample_period, double horizon) {
  const double whole = timeTrajectory(profile, {a, b}, limits, 0.0, sample_period).duration();
  int n = std::max(1, static_cast<int>(std::ceil(whole / horizon)));
  for (;; ++n) {  // min_jerk under acceleration limits: duration grows slower than length, so check a piece
    std::vector<double> first(a.size());
    for (std::size_t i = 0; i < a.size(); ++i) first[i] = a[i] + (b[i] - a[i]) / n;
    if (timeTrajectory(profile, {a, first}, limits, 0.0, sample_period).duration() <= horizon + 1e-9 || n > 10000) {
      break;
    }
  }
  Waypoints out;
  for (int k = 1; k <= n; ++k) {
    std::vector<double> p(a.size());
    for (std::size_t i = 0; i < a.size(); ++i) p[i] = k == n ? b[i] : a[i] + (b[i] - a[i]) * k / n;
    out.push_back(std::move(p));
  }
  return out;
}
}  // namespace

void Shield::plannedReset(const std::vector<double>& target, ResetResult* res) {
  RobotState s;
  std::string error;
  if (!driver_->currentState(&s, &error)) {
    res->message = "joint states: " + error;
    return;
  }
  adopt(s);
  TimingLimits limits = options_.limits;
  limits.velocity_scale = options_.reset_velocity_scale;
  StepResult step;  // a move's report, for its message
  if (!options_.enabled) {
    const Verdict v = move({s.q, target}, Verdict::kUnchecked, 0.0, limits, &step, false);
    res->success = v == Verdict::kUnchecked;
    res->message = step.message;
    res->moves = 1;
    return;
  }
  // The straight move, checked with the window of its whole duration; if only its path collides, an OMPL plan.
  Waypoints path{s.q, target};
  double duration = 0.0;
  try {
    duration = timeTrajectory(options_.profile, path, limits, 0.0, options_.sample_period).duration();
  } catch (const std::exception& e) {
    res->message = std::string("cannot time the reset move: ") + e.what();
    return;
  }
  mps::MotionRequest q;
  q.start = s.q;
  q.goal = target;
  q.measured_start = s.measured;
  const double check_begin = clock_->now();
  setWindow(s, check_begin, duration, &q);
  mps::MotionCheck a;
  const double timeout = sceneTimeout();
  q.time_budget = timeout;
  CallEnd end = scene_->validate(q, &a, timeout);
  if (end != CallEnd::kAnswered) {
    res->message = "planning scene: " + describe(end, timeout);
    return;
  }
  const bool sensed = a.map_age >= 0.0;  // obstacles that may move unseen: the path runs in checked pieces
  switch (a.outcome) {
    case MotionOutcome::kValid:
      if (!sensed && clock_->now() - check_begin > options_.check_budget) {
        res->message = "planning scene answered beyond the real-time check_budget: reset move not sent";
        return;
      }
      break;
    case MotionOutcome::kPathCollision: {
      mps::PlanResult plan;
      const double plan_timeout = options_.reset_planning_time + options_.scene_margin;
      end = scene_->plan(s.q, target, options_.reset_planning_time, &plan, plan_timeout);
      if (end != CallEnd::kAnswered) {
        res->message = "planning scene: " + describe(end, plan_timeout);
        return;
      }
      if (plan.status != mps::PlanStatus::kSuccess || plan.waypoints.size() < 2) {
        res->unreachable = plan.status == mps::PlanStatus::kNoSolution;
        res->message = "no collision-free path to the reset target: " + plan.message;
        return;
      }
      path.swap(plan.waypoints);
      path.front() = s.q;
      break;
    }
    case MotionOutcome::kStartInCollision:
      res->message = "the robot is not free where it stands (" + a.message +
                     "): a planned reset cannot start from there; move the robot out by hand (or with its teach "
                     "pendant) and reset again";
      return;
    default:
      if (!sensed) {
        res->message = "reset target refused: " + a.message;
        return;
      }
      break;  // sensed: the straight move's margin of its whole duration is far larger than a piece's
  }
  try {
    res->planned_duration = timeTrajectory(options_.profile, path, limits, 0.0, options_.sample_period).duration();
  } catch (const std::exception& e) {
    res->message = std::string("cannot time the reset path: ") + e.what();
    return;
  }
  if (!sensed) {
    // Checked whole: the straight move with its window, a plan against every moving obstacle's whole envelope.
    const Verdict v = move(path, Verdict::kSafe, 0.0, limits, &step, false);
    res->success = v == Verdict::kSafe;
    res->moves = 1;
    res->message = step.message;
    return;
  }
  // Sensed obstacles: a plan was checked with the margin of plan_horizon, a straight move of seconds cannot be. Each
  // piece (at most reset_horizon long) is checked from the state it starts at, with the margin of its own window (the
  // state's age, the check, the start lead, the piece, the goal time), then executed: every instant of the reset is
  // covered. A piece refused (something came close) ends the reset: the env samples another start.
  for (std::size_t k = 1; k < path.size(); ++k) {
    const Waypoints pieces =
        piecesOf(path[k - 1], path[k], options_.profile, limits, options_.sample_period, options_.reset_horizon);
    for (const std::vector<double>& piece_end : pieces) {
      if (!driver_->currentState(&s, &error)) {
        res->message = "joint states: " + error;
        return;
      }
      adopt(s);
      double piece = 0.0;
      try {
        piece = timeTrajectory(options_.profile, {s.q, piece_end}, limits, 0.0, options_.sample_period).duration();
      } catch (const std::exception& e) {
        res->message = std::string("cannot time the reset move: ") + e.what();
        return;
      }
      q.start = s.q;
      q.goal = piece_end;
      q.measured_start = s.measured;
      const double begin = clock_->now();
      setWindow(s, begin, piece, &q);
      end = scene_->validate(q, &a, timeout);
      if (end != CallEnd::kAnswered) {
        res->message = "planning scene: " + describe(end, timeout);
        return;
      }
      if (a.outcome != MotionOutcome::kValid || clock_->now() - begin > options_.check_budget) {
        res->unreachable = a.outcome != MotionOutcome::kValid && a.outcome != MotionOutcome::kStartInCollision &&
                           a.outcome != MotionOutcome::kInvalidRequest;
        res->message =
            "reset stopped after " + std::to_string(res->moves) +
            " of its moves: the next one is not "
            "free with the sensed margin of its window (" +
            (a.outcome == MotionOutcome::kValid ? std::string("the check took beyond check_budget") : a.message) + ")";
        return;
      }
      const Verdict v = move({s.q, piece_end}, Verdict::kSafe, 0.0, limits, &step, false);
      ++res->moves;
      if (v != Verdict::kSafe) {
        res->message = step.message;
        return;
      }
    }
  }
  res->success = true;
}

}  // namespace moverl_shield
