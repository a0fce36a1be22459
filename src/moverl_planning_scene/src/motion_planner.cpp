#include "moverl_planning_scene/motion_planner.h"

#include <ompl/base/MotionValidator.h>
#include <ompl/base/PlannerTerminationCondition.h>
#include <ompl/base/StateValidityChecker.h>
#include <ompl/base/spaces/RealVectorStateSpace.h>
#include <ompl/geometric/PathSimplifier.h>
#include <ompl/geometric/SimpleSetup.h>
#include <ompl/geometric/planners/est/BiEST.h>
#include <ompl/geometric/planners/est/EST.h>
#include <ompl/geometric/planners/est/ProjEST.h>
#include <ompl/geometric/planners/fmt/BFMT.h>
#include <ompl/geometric/planners/fmt/FMT.h>
#include <ompl/geometric/planners/informedtrees/BITstar.h>
#include <ompl/geometric/planners/kpiece/BKPIECE1.h>
#include <ompl/geometric/planners/kpiece/KPIECE1.h>
#include <ompl/geometric/planners/kpiece/LBKPIECE1.h>
#include <ompl/geometric/planners/pdst/PDST.h>
#include <ompl/geometric/planners/prm/LazyPRM.h>
#include <ompl/geometric/planners/prm/LazyPRMstar.h>
#include <ompl/geometric/planners/prm/PRM.h>
#include <ompl/geometric/planners/prm/PRMstar.h>
#include <ompl/geometric/planners/rrt/BiTRRT.h>
#include <ompl/geometric/planners/rrt/InformedRRTstar.h>
#include <ompl/geometric/planners/rrt/LazyRRT.h>
#include <ompl/geometric/planners/rrt/RRT.h>
#include <ompl/geometric/planners/rrt/RRTConnect.h>
#include <ompl/geometric/planners/rrt/RRTstar.h>
#include <ompl/geometric/planners/rrt/TRRT.h>
#include <ompl/geometric/planners/sbl/SBL.h>
#include <ompl/geometric/planners/stride/STRIDE.h>
#include <ompl/util/Console.h>
#include <ompl/util/RandomNumbers.h>

#include <chrono>
#include <cmath>
#include <functional>
#include <map>
#include <mutex>
#include <sstream>

namespace ob = ompl::base;
namespace og = ompl::geometric;

namespace moverl_planning_scene {
namespace {

using Clock = std::chrono::steady_clock;
using PlannerFactory = std::function<ob::PlannerPtr(const ob::SpaceInformationPtr&)>;

constexpr int kMaxSimplifyRounds = 10;       // bounds the number of simplification calls
constexpr int kSimplifyStepsPerCall = 5;     // motion checks per reduceVertices/shortcutPath call
constexpr int kMaxIdleSimplifyCalls = 4;     // stop after this many calls without improvement
constexpr double kMinSimplifyBudget = 1e-3;  // s; below this, the raw solution is returned
// The final re-validation of the path (the guaranteed path check on every segment) must also end by the time limit:
// the planner and the simplifier stop early enough to leave it time. Its cost is estimated from the number of states
// it checks times the measured cost of one state check (running average, initial guess below), with a margin.
constexpr double kInitialStateCheckCost = 60e-6;  // s per state check before any measurement
constexpr double kValidationMargin = 1.5;         // estimated validation time x this is reserved
constexpr double kSolveReserve = 0.1;             // the planner stops at 90 % of the limit (the rest: validation)

template <typename P>
PlannerFactory make() {
  return [](const ob::SpaceInformationPtr& si) { return std::make_shared<P>(si); };
}

const std::map<std::string, PlannerFactory>& factories() {
  static const std::map<std::string, PlannerFactory> kFactories = {
      {"RRT", make<og::RRT>()},
      {"RRTConnect", make<og::RRTConnect>()},
      {"RRTstar", make<og::RRTstar>()},
      {"InformedRRTstar", make<og::InformedRRTstar>()},
      {"BiTRRT", make<og::BiTRRT>()},
      {"TRRT", make<og::TRRT>()},
      {"LazyRRT", make<og::LazyRRT>()},
      {"PRM", make<og::PRM>()},
      {"PRMstar", make<og::PRMstar>()},
      {"LazyPRM", make<og::LazyPRM>()},
      {"LazyPRMstar", make<og::LazyPRMstar>()},
      {"EST", make<og::EST>()},
      {"BiEST", make<og::BiEST>()},
      {"ProjEST", make<og::ProjEST>()},
      {"KPIECE1", make<og::KPIECE1>()},
      {"BKPIECE1", make<og::BKPIECE1>()},
      {"LBKPIECE1", make<og::LBKPIECE1>()},
      {"SBL", make<og::SBL>()},
      {"FMT", make<og::FMT>()},
      {"BFMT", make<og::BFMT>()},
      {"PDST", make<og::PDST>()},
      {"STRIDE", make<og::STRIDE>()},
      {"BITstar", make<og::BITstar>()},
  };
  return kFactories;
}

const double* values(const ob::State* s) { return s->as<ob::RealVectorStateSpace::StateType>()->values; }

/// Hard deadline shared by the validity checker and the motion validator: once it has passed, every state and motion
/// is reported invalid, so that any planner (even one that checks its termination condition rarely, e.g. FMT) runs
/// out of work quickly. Rejecting valid states can only lose solutions, never produce invalid ones.
struct Deadline {
  Clock::time_point time = Clock::time_point::max();
  bool passed() const { return Clock::now() > time; }
};

/// OMPL state validity through the collision checker (verdict only, early exit).
class CheckerValidity : public ob::StateValidityChecker {
 public:
  CheckerValidity(const ob::SpaceInformationPtr& si, CollisionChecker* checker, const Deadline* deadline)
      : ob::StateValidityChecker(si), checker_(checker), deadline_(deadline) {}
  bool isValid(const ob::State* state) const override {
    return !deadline_->passed() && checker_->isStateValid(values(state));
  }

 private:
  CollisionChecker* checker_;
  const Deadline* deadline_;
};

/// OMPL motion validation with the same straight-segment check (and guarantee) as the path check service.
class CheckerMotionValidator : public ob::MotionValidator {
 public:
  CheckerMotionValidator(const ob::SpaceInformationPtr& si, CollisionChecker* checker, const Deadline* deadline)
      : ob::MotionValidator(si), checker_(checker), deadline_(deadline) {
    fast_.state.max_pairs = 0;
    fast_.check_start = false;  // OMPL guarantees s1 valid
    fast_.find_first = false;   // goal first, then bisection: fastest rejection
    first_ = fast_;
    first_.find_first = true;
  }
  bool checkMotion(const ob::State* s1, const ob::State* s2) const override {
    if (deadline_->passed()) return false;
    checker_->checkPath(values(s1), values(s2), fast_, &result_);
    const bool ok = result_.status == CollisionStatus::kFree;
    ok ? ++valid_ : ++invalid_;
    return ok;
  }
  bool checkMotion(const ob::State* s1, const ob::State* s2, std::pair<ob::State*, double>& last_valid) const override {
    if (deadline_->passed()) {
      last_valid.second = 0.0;
      if (last_valid.first != nullptr) si_->copyState(last_valid.first, s1);
      return false;
    }
    checker_->checkPath(values(s1), values(s2), first_, &result_);
    const bool ok = result_.status == CollisionStatus::kFree;
    if (!ok) {
      last_valid.second = result_.last_valid_fraction;
      if (last_valid.first != nullptr) si_->getStateSpace()->interpolate(s1, s2, last_valid.second, last_valid.first);
    }
    ok ? ++valid_ : ++invalid_;
    return ok;
  }

 private:
  CollisionChecker* checker_;
  const Deadline* deadline_;
  PathCheckRequest fast_, first_;
  mutable PathCheckResult result_;
};

}  // namespace

struct MotionPlanner::Impl {
  const RobotModel& model;
  CollisionChecker* checker;
  std::shared_ptr<ob::RealVectorStateSpace> space;
  std::unique_ptr<og::SimpleSetup> ss;
  PathCheckRequest validate_request;
  PathCheckResult path_result;
  CollisionResult state_result;
  Deadline deadline;
  double state_check_cost = kInitialStateCheckCost;  // running average (s per state) of the re-validations
  Impl(const RobotModel& m, CollisionChecker* c) : model(m), checker(c) {}
};

const std::vector<std::string>& MotionPlanner::knownPlanners() {
  static const std::vector<std::string> kNames = [] {
    std::vector<std::string> names;
    for (const auto& kv : factories()) names.push_back(kv.first);
    return names;
  }();
  return kNames;
}

bool MotionPlanner::isKnownPlanner(const std::string& name) { return name.empty() || factories().count(name) > 0; }

MotionPlanner::MotionPlanner(const RobotModel& model, CollisionChecker* checker, const PlannerOptions& options)
    : impl_(std::make_unique<Impl>(model, checker)), options_(options) {
  static std::once_flag seed_once;
  if (options.seed != 0) std::call_once(seed_once, [&] { ompl::RNG::setSeed(options.seed); });
  ompl::msg::setLogLevel(ompl::msg::LOG_ERROR);
  const std::size_t dof = model.dof();
  impl_->space = std::make_shared<ob::RealVectorStateSpace>(static_cast<unsigned>(dof));
  ob::RealVectorBounds bounds(static_cast<unsigned>(dof));
  for (std::size_t i = 0; i < dof; ++i) {
    bounds.setLow(static_cast<unsigned>(i), model.lowerLimits()[i]);
    bounds.setHigh(static_cast<unsigned>(i), model.upperLimits()[i]);
  }
  impl_->space->setBounds(bounds);
  impl_->ss = std::make_unique<og::SimpleSetup>(impl_->space);
  const ob::SpaceInformationPtr& si = impl_->ss->getSpaceInformation();
  impl_->ss->setStateValidityChecker(std::make_shared<CheckerValidity>(si, checker, &impl_->deadline));
  si->setMotionValidator(std::make_shared<CheckerMotionValidator>(si, checker, &impl_->deadline));
  si->setup();
  impl_->validate_request.state.max_pairs = 0;
  impl_->validate_request.check_start = false;
  impl_->validate_request.find_first = false;
}

MotionPlanner::~MotionPlanner() = default;

void MotionPlanner::plan(const std::vector<double>& start, const std::vector<double>& goal,
                         const std::string& planner_name, double time_limit, PlanResult* result, bool try_straight) {
  const auto t0 = Clock::now();
  auto elapsed = [&] { return std::chrono::duration<double>(Clock::now() - t0).count(); };
  result->waypoints.clear();
  result->path_length = 0.0;
  result->message.clear();
  auto finish = [&](PlanStatus status, const std::string& message) {
    result->status = status;
    result->message = message;
    result->planning_time = elapsed();
  };
  const std::string name = planner_name.empty() ? options_.planner : planner_name;
  const auto factory = factories().find(name);
  if (factory == factories().end()) return finish(PlanStatus::kInvalidRequest, "unknown planner '" + name + "'");
  if (time_limit <= 0.0) time_limit = options_.planning_time;
  Impl& im = *impl_;
  CollisionRequest names_request;
  names_request.max_pairs = 1;
  im.checker->checkState(start.data(), names_request, &im.state_result);
  if (im.state_result.collision()) {
    const auto& p = im.state_result.pairs.front();
    return finish(PlanStatus::kStartInvalid, "start state collides (" + p.a + " / " + p.b + ")");
  }
  im.checker->checkState(goal.data(), names_request, &im.state_result);
  if (im.state_result.collision()) {
    const auto& p = im.state_result.pairs.front();
    return finish(PlanStatus::kGoalInvalid, "goal state collides (" + p.a + " / " + p.b + ")");
  }
  if (try_straight) {
    im.validate_request.check_goal = false;
    im.checker->checkPath(start.data(), goal.data(), im.validate_request, &im.path_result);
    if (im.path_result.status == CollisionStatus::kFree) {
      result->waypoints = {start, goal};
      double len = 0.0;
      for (std::size_t i = 0; i < start.size(); ++i) len += (goal[i] - start[i]) * (goal[i] - start[i]);
      result->path_length = std::sqrt(len);
      return finish(PlanStatus::kSuccess, "straight segment is free");
    }
  }

  og::SimpleSetup& ss = *im.ss;
  ss.clear();
  const ob::SpaceInformationPtr& si = ss.getSpaceInformation();
  ob::PlannerPtr planner = factory->second(si);
  if (options_.range > 0.0 && planner->params().hasParam("range")) {
    planner->params().setParam("range", std::to_string(options_.range));
  }
  ss.setPlanner(planner);
  ob::ScopedState<> s(im.space), g(im.space);
  for (std::size_t i = 0; i < start.size(); ++i) {
    s[i] = start[i];
    g[i] = goal[i];
  }
  ss.setStartAndGoalStates(s, g);
  // Hard deadlines: the call returns by t0 + time_limit. The planner stops at t0 + (1 - kSolveReserve) time_limit
  // (its validity checks fail after it, so even planners that rarely poll stop quickly); the simplifier stops early
  // enough for the estimated re-validation; the re-validation itself gives up (no solution) at t0 + time_limit.
  const auto at = [&](double s) {
    return t0 + std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(s));
  };
  const double solve_limit = (1.0 - kSolveReserve) * time_limit;
  im.deadline.time = at(solve_limit);
  const ob::PlannerStatus status =
      ss.solve(ob::timedPlannerTerminationCondition(std::max(0.0, solve_limit - elapsed())));
  if (status != ob::PlannerStatus::EXACT_SOLUTION) {
    im.deadline.time = Clock::time_point::max();
    std::ostringstream m;
    m << name << " found no exact solution within " << time_limit << " s (" << status.asString() << ")";
    return finish(PlanStatus::kNoSolution, m.str());
  }
  og::PathGeometric raw = ss.getSolutionPath();
  og::PathGeometric path = raw;
  // States the re-validation of a path checks (interior states + the end of every segment).
  auto validation_states = [&](const og::PathGeometric& p) {
    double n = 0.0;
    for (std::size_t k = 0; k + 1 < p.getStateCount(); ++k) {
      n += 1.0 + static_cast<double>(im.checker->interiorStateCount(values(p.getState(k)), values(p.getState(k + 1))));
    }
    return n;
  };
  const double reserve = kValidationMargin * im.state_check_cost * validation_states(raw);
  const double budget = time_limit - reserve - elapsed();
  im.deadline.time = at(time_limit - reserve);
  if (options_.simplify && budget > kMinSimplifyBudget) {
    const ob::PlannerTerminationCondition ptc = ob::timedPlannerTerminationCondition(budget);
    og::PathSimplifier simplifier(si);
    // Small steps so the time budget is checked often (each step is one motion check).
    int idle = 0;
    for (int round = 0; round < kMaxSimplifyRounds * kSimplifyStepsPerCall && idle < kMaxIdleSimplifyCalls && !ptc;
         ++round) {
      bool improved = simplifier.reduceVertices(path, kSimplifyStepsPerCall, kSimplifyStepsPerCall);
      if (!ptc) improved = simplifier.shortcutPath(path, kSimplifyStepsPerCall, kSimplifyStepsPerCall) || improved;
      idle = improved ? 0 : idle + 1;
    }
    if (!ptc) simplifier.collapseCloseVertices(path);
  }
  im.deadline.time = Clock::time_point::max();
  // Re-validate the final path segment by segment with the guaranteed path check, within the time limit.
  const Deadline hard{at(time_limit)};
  bool late = false;
  auto valid = [&](const og::PathGeometric& p) {
    im.validate_request.check_goal = true;
    const auto v0 = Clock::now();
    std::size_t states = 0;
    bool ok = true;
    for (std::size_t k = 0; k + 1 < p.getStateCount(); ++k) {
      if (hard.passed()) {
        late = true;
        ok = false;
        break;
      }
      im.checker->checkPath(values(p.getState(k)), values(p.getState(k + 1)), im.validate_request, &im.path_result);
      states += im.path_result.checked_states;
      if (im.path_result.status != CollisionStatus::kFree) {
        ok = false;
        break;
      }
    }
    if (states > 0) {  // running average of the cost of one state check (for the next call's reserve)
      const double per_state = std::chrono::duration<double>(Clock::now() - v0).count() / static_cast<double>(states);
      im.state_check_cost = 0.8 * im.state_check_cost + 0.2 * per_state;
    }
    return ok;
  };
  const og::PathGeometric* chosen = &path;
  if (!valid(path)) {
    chosen = &raw;
    if (late || !valid(raw)) {
      return finish(PlanStatus::kNoSolution,
                    late ? name + " solution could not be re-validated within " + std::to_string(time_limit) + " s"
                         : name + " solution failed re-validation");
    }
  }
  const std::size_t dof = start.size();
  result->waypoints.resize(chosen->getStateCount());
  for (std::size_t k = 0; k < chosen->getStateCount(); ++k) {
    const double* v = values(chosen->getState(k));
    result->waypoints[k].assign(v, v + dof);
  }
  result->waypoints.front() = start;
  result->waypoints.back() = goal;
  for (std::size_t k = 0; k + 1 < result->waypoints.size(); ++k) {
    double len = 0.0;
    for (std::size_t i = 0; i < dof; ++i) {
      const double d = result->waypoints[k + 1][i] - result->waypoints[k][i];
      len += d * d;
    }
    result->path_length += std::sqrt(len);
  }
  finish(PlanStatus::kSuccess, name + " solution with " + std::to_string(result->waypoints.size()) + " waypoints");
}

}  // namespace moverl_planning_scene
