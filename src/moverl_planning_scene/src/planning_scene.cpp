#include "moverl_planning_scene/planning_scene.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>
#include <random>
#include <sstream>

namespace moverl_planning_scene {
namespace {

using Clock = std::chrono::steady_clock;
constexpr std::size_t kAllPairs = std::numeric_limits<std::size_t>::max();

double since(Clock::time_point t0) { return std::chrono::duration<double>(Clock::now() - t0).count(); }

CheckOutcome toOutcome(CollisionStatus s) {
  switch (s) {
    case CollisionStatus::kSelf:
      return CheckOutcome::kSelfCollision;
    case CollisionStatus::kWorld:
      return CheckOutcome::kWorldCollision;
    default:
      return CheckOutcome::kValid;
  }
}

std::string describe(const std::vector<ContactPair>& pairs) {
  std::string s;
  for (std::size_t i = 0; i < pairs.size(); ++i) {
    if (i > 0) s += ", ";
    s += pairs[i].a + " / " + pairs[i].b;
  }
  return s;
}

}  // namespace

std::unique_ptr<PlanningScene> PlanningScene::create(const std::string& urdf_xml, const PlanningSceneOptions& options,
                                                     std::string* error) {
  std::string dummy;
  if (error == nullptr) error = &dummy;
  if (!MotionPlanner::isKnownPlanner(options.planner.planner)) {
    *error = "unknown planner '" + options.planner.planner + "'";
    return nullptr;
  }
  if (!(options.planner.planning_time > 0.0) || options.planner.planning_time > kMaxPlanningTime) {
    *error = "planning_time must be in (0, 60] s";
    return nullptr;
  }
  if (!(options.planner.range >= 0.0) || !std::isfinite(options.planner.range)) {
    *error = "planner_range must be >= 0";
    return nullptr;
  }
  std::unique_ptr<PlanningScene> s(new PlanningScene());
  s->model_ = RobotModel::fromUrdf(urdf_xml, options.robot, error);
  if (!s->model_) return nullptr;
  s->checker_ = FclCollisionChecker::create(*s->model_, options.checker, error);
  if (!s->checker_) return nullptr;
  s->planner_ = std::make_unique<MotionPlanner>(*s->model_, s->checker_.get(), options.planner);
  s->all_pairs_.max_pairs = kAllPairs;
  s->start_.resize(s->model_->dof());
  s->goal_.resize(s->model_->dof());
  return s;
}

std::string PlanningScene::validateConfiguration(const std::vector<double>& q, const char* what) const {
  const std::size_t dof = model_->dof();
  if (q.size() != dof) {
    std::ostringstream m;
    m << what << " has " << q.size() << " values, expected " << dof << " (one per joint of ~joint_names)";
    return m.str();
  }
  for (std::size_t i = 0; i < dof; ++i) {
    if (!std::isfinite(q[i])) {
      std::ostringstream m;
      m << what << "[" << i << "] (" << model_->jointNames()[i] << ") is not finite";
      return m.str();
    }
    const double lo = model_->lowerLimits()[i], hi = model_->upperLimits()[i];
    if (q[i] < lo - kLimitTolerance || q[i] > hi + kLimitTolerance) {
      std::ostringstream m;
      m << what << "[" << i << "] = " << q[i] << " is outside the limits [" << lo << ", " << hi << "] of joint "
        << model_->jointNames()[i];
      return m.str();
    }
  }
  return "";
}

std::string PlanningScene::prepare(const std::vector<double>& q, const char* what, std::vector<double>* clamped) const {
  std::string error = validateConfiguration(q, what);
  if (!error.empty()) return error;
  for (std::size_t i = 0; i < q.size(); ++i) {
    (*clamped)[i] = std::min(std::max(q[i], model_->lowerLimits()[i]), model_->upperLimits()[i]);
  }
  return error;
}

void PlanningScene::checkState(const std::vector<double>& q, StateCheck* out, bool compute_depth) {
  const auto t0 = Clock::now();
  out->pairs.clear();
  out->message = prepare(q, "positions", &start_);
  if (!out->message.empty()) {
    out->outcome = CheckOutcome::kInvalidRequest;
    out->check_time = since(t0);
    return;
  }
  CollisionRequest request = all_pairs_;
  request.compute_depth = compute_depth;
  checker_->checkState(start_.data(), request, &state_result_);
  out->outcome = toOutcome(state_result_.status);
  out->pairs = state_result_.pairs;
  if (state_result_.collision()) {
    out->message = (state_result_.status == CollisionStatus::kSelf ? "self collision: " : "world collision: ") +
                   describe(out->pairs);
  }
  out->check_time = since(t0);
}

void PlanningScene::checkPath(const std::vector<double>& start, const std::vector<double>& goal, PathCheck* out) {
  const auto t0 = Clock::now();
  out->pairs.clear();
  out->collision_fraction = -1.0;
  out->checked_states = 0;
  out->message = prepare(start, "start", &start_);
  if (out->message.empty()) out->message = prepare(goal, "goal", &goal_);
  if (!out->message.empty()) {
    out->outcome = CheckOutcome::kInvalidRequest;
    out->check_time = since(t0);
    return;
  }
  PathCheckRequest request;
  request.state = all_pairs_;
  checker_->checkPath(start_.data(), goal_.data(), request, &path_result_);
  out->outcome = toOutcome(path_result_.status);
  out->pairs = path_result_.pairs;
  out->collision_fraction = path_result_.collision_fraction;
  out->checked_states = path_result_.checked_states;
  if (path_result_.status != CollisionStatus::kFree) {
    std::ostringstream m;
    m << (path_result_.status == CollisionStatus::kSelf ? "self" : "world") << " collision at fraction "
      << path_result_.collision_fraction << ": " << describe(out->pairs);
    out->message = m.str();
  }
  out->check_time = since(t0);
}

void PlanningScene::plan(const std::vector<double>& start, const std::vector<double>& goal, const std::string& planner,
                         double time_limit, PlanResult* out) {
  const auto t0 = Clock::now();
  out->waypoints.clear();
  out->path_length = 0.0;
  std::string error = prepare(start, "start", &start_);
  if (error.empty()) error = prepare(goal, "goal", &goal_);
  if (error.empty() && !MotionPlanner::isKnownPlanner(planner)) error = "unknown planner '" + planner + "'";
  if (error.empty() && (!std::isfinite(time_limit) || time_limit < 0.0 || time_limit > kMaxPlanningTime)) {
    error = "time_limit must be in [0, 60] s (0: default)";
  }
  if (!error.empty()) {
    out->status = PlanStatus::kInvalidRequest;
    out->message = error;
    out->planning_time = since(t0);
    return;
  }
  planner_->plan(start_, goal_, planner, time_limit, out);
  out->planning_time = since(t0);
}

bool PlanningScene::fk(const std::vector<double>& q, const std::vector<std::string>& links,
                       std::vector<Eigen::Isometry3d>* poses, std::string* error) {
  *error = prepare(q, "positions", &start_);
  if (!error->empty()) return false;
  model_->computeLinkTransforms(start_.data(), &link_poses_);
  poses->clear();
  if (links.empty()) {
    poses->push_back(link_poses_[model_->linkIndex(model_->eeLink())]);
    return true;
  }
  for (const std::string& l : links) {
    const int index = model_->linkIndex(l);
    if (index < 0) {
      *error = "unknown link '" + l + "'";
      poses->clear();
      return false;
    }
    poses->push_back(link_poses_[index]);
  }
  return true;
}

void PlanningScene::findLastFree(bool goal_checked, MotionCheck* out) {
  // path_result_ holds a find_first check of start_ -> goal_ (start checked or known free).
  double t;
  if (path_result_.status != CollisionStatus::kFree) {
    t = path_result_.collision_fraction <= 0.0 ? 0.0 : path_result_.last_valid_fraction;
  } else if (goal_checked) {
    t = 1.0;  // not reached by the callers (the path collided)
  } else {
    // All checked states free but the goal (unchecked here) collides: the last interior state.
    const std::size_t n = checker_->interiorStateCount(start_.data(), goal_.data());
    t = static_cast<double>(n) / static_cast<double>(n + 1);
  }
  const std::size_t dof = start_.size();
  std::vector<double> q(dof);
  auto at = [&](double f) {
    for (std::size_t i = 0; i < dof; ++i) q[i] = start_[i] + f * (goal_[i] - start_[i]);
  };
  // Every state of start -> q(t) lies within the resolution of a state checked free above. Make the guarantee
  // literal: q(t) passes the state check and start -> q(t) passes checkPath (own discretization); if not
  // (rounding), fall back to that check's last free state.
  for (int attempt = 0; attempt < 4 && t > 0.0; ++attempt) {
    at(t);
    PathCheckRequest request;
    request.state = verdict_only_;
    request.check_start = false;  // free (checked above)
    request.check_goal = true;
    request.find_first = true;
    PathCheckResult verify;
    checker_->checkPath(start_.data(), q.data(), request, &verify);
    if (verify.status == CollisionStatus::kFree) {
      out->last_free_fraction = t;
      out->last_free_state = q;
      return;
    }
    t *= verify.collision_fraction <= 0.0 ? 0.0 : verify.last_valid_fraction;
  }
  out->last_free_fraction = 0.0;
  out->last_free_state = start_;
}

void PlanningScene::validateMotion(const std::vector<double>& start, const std::vector<double>& goal,
                                   bool plan_on_path_collision, MotionCheck* out, bool find_last_free,
                                   double start_time, double duration, const SensedMargins* sensed) {
  MotionRequest request;
  request.start = start;
  request.goal = goal;
  request.plan_on_path_collision = plan_on_path_collision;
  request.find_last_free = find_last_free;
  request.start_time = start_time;
  request.duration = duration;
  validateMotion(request, out, sensed);
}

void PlanningScene::validateMotion(const MotionRequest& req, MotionCheck* out, const SensedMargins* sensed) {
  const bool plan_on_path_collision = req.plan_on_path_collision, find_last_free = req.find_last_free;
  const double start_time = req.start_time, duration = req.duration;
  auto t0 = Clock::now();
  const Clock::time_point deadline = req.time_budget > 0.0
                                         ? t0 + std::chrono::duration_cast<Clock::duration>(
                                                    std::chrono::duration<double>(std::min(req.time_budget, 1e6)))
                                         : Clock::time_point::max();
  // Sensed obstacles: each check with the margin of the time it covers; back to none when done.
  const SensedMargins none;
  const SensedMargins& margin = sensed != nullptr ? *sensed : none;
  const OctreeMarginScope scope(checker_.get(), margin.end);
  const TrackedPartsScope tracked(checker_.get(), &margin.parts);
  const bool moving = checker_->hasMovingObstacles();
  out->moving_obstacles = moving;
  out->replanned = false;
  out->last_free_fraction = -1.0;
  out->last_free_state.clear();
  out->path.clear();
  out->pairs.clear();
  out->message.clear();
  out->state_check_time = out->path_check_time = out->planning_time = 0.0;
  out->threatened = false;
  out->clearance = out->retreat_clearance = -1.0;
  out->retreat_state.clear();
  std::string error = prepare(req.start, "start", &start_);
  if (error.empty()) error = prepare(req.goal, "goal", &goal_);
  if (error.empty() && (!std::isfinite(start_time) || std::isnan(duration) || duration < 0.0)) {
    error = "start_time must be finite and duration >= 0";
  }
  const bool measured = !req.measured_start.empty() && req.measured_start != req.start;
  if (error.empty() && !req.retreat_reach.empty()) {
    if (req.retreat_reach.size() != model_->dof()) {
      error = "retreat_reach has " + std::to_string(req.retreat_reach.size()) + " values, expected " +
              std::to_string(model_->dof());
    }
    for (double v : req.retreat_reach) {
      if (error.empty() && !(std::isfinite(v) && v >= 0.0)) error = "retreat_reach must be finite and >= 0";
    }
  }
  if (error.empty() && measured) {
    // Where the robot stands when its driver clamped its state onto a limit: any finite state of the right size (the
    // shield bounds how far beyond a limit it accepts one).
    if (req.measured_start.size() != model_->dof()) {
      error = "measured_start has " + std::to_string(req.measured_start.size()) + " values, expected " +
              std::to_string(model_->dof());
    }
    for (double v : req.measured_start) {
      if (error.empty() && !std::isfinite(v)) error = "measured_start is not finite";
    }
    measured_ = req.measured_start;
  }
  if (!error.empty()) {
    out->outcome = MotionOutcome::kInvalidRequest;
    out->message = error;
    out->state_check_time = since(t0);
    return;
  }
  // Moving obstacles are their whole motion envelope here (the checker's default), except for the straight path.
  // Goal: self then world (one state check), then the start; both, and the straight path between them in a world
  // without moving obstacles, skip the shape pairs that cannot meet on the way (prepareSegment: the same answers).
  checker_->prepareSegment(start_.data(), goal_.data());
  checker_->checkState(goal_.data(), all_pairs_, &state_result_);
  if (state_result_.status == CollisionStatus::kSelf) {
    out->outcome = MotionOutcome::kSelfCollision;
    out->message = "goal in self collision: " + describe(state_result_.pairs);
  } else if (state_result_.status == CollisionStatus::kWorld) {
    out->outcome = MotionOutcome::kPoseCollision;
    out->message = "goal collides with the world: " + describe(state_result_.pairs);
  } else {
    checker_->setOctreeMargin(margin.start);
    checker_->checkState(start_.data(), all_pairs_, &state_result_);
    const char* which = "start state";
    if (!state_result_.collision() && measured) {
      // The robot stands at the measured state, a little beyond a limit: that state, and the way from it to the
      // clamped start the moves begin at (a controller bridges it), must be free too. A clamp of 0.02 rad moves the
      // Panda's flange by about 2 cm: more than the padding.
      which = "measured start state (beyond a joint limit)";
      checker_->checkState(measured_.data(), all_pairs_, &state_result_);
      if (!state_result_.collision()) {
        PathCheckRequest bridge;
        bridge.state = all_pairs_;
        bridge.check_start = false;  // both ends checked above
        bridge.check_goal = false;
        checker_->checkPath(measured_.data(), start_.data(), bridge, &path_result_);
        if (path_result_.status != CollisionStatus::kFree) {
          state_result_.status = path_result_.status;
          state_result_.pairs = path_result_.pairs;
          which = "way from the measured start state (beyond a joint limit) to the clamped one";
        }
      }
    }
    checker_->setOctreeMargin(margin.end);
    if (state_result_.collision()) {
      out->outcome = MotionOutcome::kStartInCollision;
      out->message = std::string(which) + " not free (" +
                     (state_result_.status == CollisionStatus::kSelf ? "self" : "world") +
                     "): " + describe(state_result_.pairs);
    }
  }
  out->state_check_time = since(t0);
  if (state_result_.collision()) {
    out->pairs = state_result_.pairs;
    if (find_last_free && out->outcome != MotionOutcome::kStartInCollision) {
      // The goal collides: walk the straight segment from the start (checked too) to find its last free state.
      t0 = Clock::now();
      PathCheckRequest request;
      request.state = verdict_only_;
      request.check_start = true;
      request.check_goal = false;  // known to collide
      request.find_first = true;
      checker_->checkPath(start_.data(), goal_.data(), request, &path_result_);
      findLastFree(/*goal_checked=*/false, out);
      out->path_check_time = since(t0);
    }
    if (!measured) retreat(req, margin.end, margin.hold_when_threatened, deadline, out);
    return;
  }
  // Straight path (interior states only: both ends are free).
  t0 = Clock::now();
  PathCheckRequest request;
  request.state = all_pairs_;
  request.check_start = false;
  request.check_goal = false;
  if (moving) checker_->setMotionWindow(start_time - kTimeSlack, start_time + duration + kTimeSlack);
  checker_->checkPath(start_.data(), goal_.data(), request, &path_result_);
  if (moving) checker_->setMotionWindow(0.0, std::numeric_limits<double>::infinity());  // back to the envelope
  out->path_check_time = since(t0);
  if (path_result_.status == CollisionStatus::kFree) {
    out->outcome = MotionOutcome::kValid;
    return;
  }
  out->outcome = MotionOutcome::kPathCollision;
  out->pairs = path_result_.pairs;
  std::ostringstream m;
  m << "straight path collides at fraction " << path_result_.collision_fraction << " (" << describe(path_result_.pairs)
    << ")";
  if (find_last_free) {
    t0 = Clock::now();
    findLastFree(/*goal_checked=*/true, out);
    out->path_check_time += since(t0);
    m << "; last free fraction " << out->last_free_fraction;
  }
  if (plan_on_path_collision && !(margin.plan <= FclCollisionChecker::kMaxMargin)) {
    m << "; no plan: a plan's sensed margin is beyond the largest the checker builds (speed bound x plan horizon)";
  } else if (plan_on_path_collision) {
    t0 = Clock::now();
    checker_->setOctreeMargin(margin.plan);
    checker_->setTrackedParts(nullptr);  // the parts' balls are for the move's window, not a plan's
    planner_->plan(start_, goal_, "", 0.0, &plan_result_, /*try_straight=*/false);
    out->planning_time = since(t0);
    out->replanned = plan_result_.status == PlanStatus::kSuccess;
    if (out->replanned) {
      out->path.swap(plan_result_.waypoints);
      m << "; replanned: " << out->path.size() << " waypoints";
    } else {
      m << "; no plan: " << plan_result_.message;
    }
  }
  out->message = m.str();
  if (!out->replanned && !measured) retreat(req, margin.end, margin.hold_when_threatened, deadline, out);
}

void PlanningScene::retreat(const MotionRequest& req, double end_margin, bool hold, Clock::time_point deadline,
                            MotionCheck* out) {
  FclCollisionChecker& c = *checker_;
  if (req.retreat_reach.empty() || !c.hasOccupancy()) return;
  const auto t0 = Clock::now();
  checker_->setOctreeMargin(end_margin);
  if (out->outcome == MotionOutcome::kStartInCollision) {
    // Within the start's own margin. Only the sensed cells may stand in the way: backing away does not help a start in
    // self collision or in a world object.
    if (state_result_.status != CollisionStatus::kWorld) return;
    for (const ContactPair& p : state_result_.pairs) {
      if (p.b != FclCollisionChecker::kOctomapId) return;
    }
  }
  // Threatened: a cell a camera saw occupied (a person) lies within padding + the end margin of where the robot rests.
  // Space occupied only because no camera has seen it (unknown_occupied) is no threat to back away from: it is where
  // the robot's own links and the person hide from the cameras, and the robot cannot leave it behind (resting next to
  // its own shadow, the KUKA iiwa searched for a retreat at every step and found none).
  if (c.occupancyFree(start_.data(), CellClass::kSeen)) return;  // resting here is covered by the margin
  out->threatened = true;
  std::ostringstream m;
  m << out->message << (out->message.empty() ? "" : "; ") << "the robot rests within the sensed margin of seen cells";
  auto done = [&](const char* why) {
    m << why;
    out->message = m.str();
    out->path_check_time += since(t0);
  };
  if (hold) return done(" (safety ssm): held still, as a person may touch a robot at rest but not one backing away");
  // Not free at padding + end margin: the clearance is below that (plus the inflation's rounding).
  const double reach = c.options().padding + end_margin + FclCollisionChecker::kMarginStep;
  const double seen = c.occupancyDistance(start_.data(), 0.0, reach, CellClass::kSeen);
  if (!(seen > 0.0)) return done(" touching them: no move is known to back away, held");
  // The clearance from every occupied cell, seen or unseen: a retreat ends clearer of them, and no state of it comes
  // closer to any of them than the robot stands, so nothing (the seen person, or one hidden in unseen space) can reach
  // it sooner than if it held.
  const double clear = c.occupancyDistance(start_.data(), 0.0, seen, CellClass::kAll);
  if (!(clear > 0.0)) return done("; it touches space no camera has seen: no move is known to back away, held");
  out->clearance = clear;
  m << " (" << clear << " m clear" << (clear < seen ? " of every cell, " : ", ") << seen << " m of the seen ones)";
  const auto late = [&] { return Clock::now() >= deadline; };
  // The commanded move itself, when it backs away: accepted as it is.
  double g = clearanceAbove(goal_, clear);
  if (g >= clear + kRetreatGain && pathBacksAway(goal_, clear)) {
    out->outcome = MotionOutcome::kValid;
    out->pairs.clear();
    out->last_free_fraction = -1.0;
    out->last_free_state.clear();
    out->retreat_clearance = g;
    m << "; the commanded move backs away (to " << g << " m clear)";
    return done("");
  }
  // Candidates within reach: each joint alone (both ways) and seeded random directions, then the joints that gained
  // alone combined; ranked by the clearance they end at, the first whose path backs away. Then the same at half the
  // reach (a wall or a limit may be nearer than the full reach). The search stops, holding, at the deadline.
  const std::size_t dof = start_.size();
  std::vector<std::vector<double>> candidates;
  std::vector<double> ends;
  for (double scale : {1.0, 0.5}) {
    candidates.clear();
    ends.clear();
    auto add = [&](std::vector<double> q) {
      for (std::size_t i = 0; i < dof; ++i) {
        q[i] = std::min(std::max(q[i], model_->lowerLimits()[i]), model_->upperLimits()[i]);
      }
      if (q == start_) return;
      ends.push_back(clearanceAbove(q, clear));
      candidates.push_back(std::move(q));
    };
    std::vector<double> gain(dof, 0.0);  // per joint: the gain of its move alone, signed by its direction
    for (std::size_t i = 0; i < dof; ++i) {
      for (double f : {scale, -scale}) {
        if (late()) return done("; no move backing away found in the time the caller waits, held");
        std::vector<double> q = start_;
        q[i] += f * req.retreat_reach[i];
        const std::size_t before = candidates.size();
        add(std::move(q));
        if (candidates.size() > before && ends.back() - clear > std::fabs(gain[i])) {
          gain[i] = std::copysign(ends.back() - clear, f);
        }
      }
    }
    std::mt19937 rng(1234567u);  // the same directions every time: a decision is repeatable
    std::uniform_real_distribution<double> unit(-1.0, 1.0);
    for (int k = 0; k < kRetreatDirections; ++k) {
      if (late()) return done("; no move backing away found in the time the caller waits, held");
      std::vector<double> q = start_;
      for (std::size_t i = 0; i < dof; ++i) q[i] += scale * unit(rng) * req.retreat_reach[i];
      add(std::move(q));
    }
    double best_gain = 0.0;
    for (double v : gain) best_gain = std::max(best_gain, std::fabs(v));
    if (best_gain > 0.0) {
      std::vector<double> q = start_;
      for (std::size_t i = 0; i < dof; ++i) q[i] = start_[i] + scale * gain[i] / best_gain * req.retreat_reach[i];
      add(std::move(q));
    }
    std::vector<std::size_t> order;
    for (std::size_t k = 0; k < candidates.size(); ++k) {
      if (ends[k] >= clear + kRetreatGain) order.push_back(k);
    }
    std::stable_sort(order.begin(), order.end(), [&](std::size_t a, std::size_t b) { return ends[a] > ends[b]; });
    for (std::size_t k : order) {
      if (late()) return done("; no move backing away found in the time the caller waits, held");
      if (!pathBacksAway(candidates[k], clear)) continue;
      out->retreat_state = candidates[k];
      out->retreat_clearance = ends[k];
      m << "; a move backs away (to " << ends[k] << " m clear)";
      return done("");
    }
  }
  done("; no move within reach backs away (boxed in), held");
}

double PlanningScene::clearanceAbove(const std::vector<double>& q, double clearance) {
  double motion = 0.0;
  for (std::size_t i = 0; i < q.size(); ++i) motion += checker_->jointRadiusBound(i) * std::fabs(q[i] - start_[i]);
  // No robot point moved more than `motion`: the clearance grew by at most that.
  return checker_->occupancyDistance(q.data(), clearance + kRetreatGain, clearance + motion + kRetreatGain);
}

bool PlanningScene::pathBacksAway(const std::vector<double>& q, double clearance) {
  FclCollisionChecker& c = *checker_;
  CollisionRequest fixed = verdict_only_;
  fixed.check_occupancy = false;  // the sensed cells: by clearance below
  c.checkState(q.data(), fixed, &retreat_result_);
  if (retreat_result_.collision()) return false;
  PathCheckRequest request;
  request.state = fixed;
  request.check_start = false;
  request.check_goal = false;
  request.find_first = false;
  c.checkPath(start_.data(), q.data(), request, &retreat_path_);
  if (retreat_path_.status != CollisionStatus::kFree) return false;
  double motion = 0.0;
  for (std::size_t i = 0; i < q.size(); ++i) motion += c.jointRadiusBound(i) * std::fabs(q[i] - start_[i]);
  const int n = std::max(1, static_cast<int>(std::ceil(motion / kRetreatResolution)));
  std::vector<double> s(q.size());
  for (int k = 1; k <= n; ++k) {  // k = n: q itself
    const double t = static_cast<double>(k) / n;
    for (std::size_t i = 0; i < q.size(); ++i) s[i] = start_[i] + t * (q[i] - start_[i]);
    if (c.occupancyDistance(s.data(), clearance, clearance) < clearance) return false;
  }
  return true;
}

}  // namespace moverl_planning_scene
