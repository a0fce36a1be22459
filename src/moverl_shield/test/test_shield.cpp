// Unit tests of the shield's decisions (moverl_shield/shield.h), without ROS: a fake driver, scene and clock inject
// every answer and every fault, and the tests check the verdict, what the driver was asked to do, and what the scene
// was asked. One test (at least) per verdict and per failure path of a step and a reset.
#include <gtest/gtest.h>

#include <cmath>
#include <deque>
#include <functional>
#include <limits>
#include <memory>
#include <string>
#include <vector>

#include "moverl_shield/shield.h"

using namespace moverl_shield;
namespace mps = moverl_planning_scene;

namespace {

// A 3-joint arm: three revolute joints about z, y, y; 1 rad/s velocity limits; limits +-2 rad.
const char* const kUrdf = R"(<robot name="arm3">
  <link name="base"/>
  <link name="l1"><collision><geometry><box size="0.1 0.1 0.3"/></geometry></collision></link>
  <link name="l2"><collision><origin xyz="0 0 0.2"/><geometry><box size="0.08 0.08 0.4"/></geometry></collision></link>
  <link name="l3"><collision><origin xyz="0 0 0.15"/><geometry><box size="0.06 0.06 0.3"/></geometry></collision></link>
  <joint name="j1" type="revolute"><parent link="base"/><child link="l1"/><axis xyz="0 0 1"/>
    <limit lower="-2" upper="2" velocity="1" effort="1"/></joint>
  <joint name="j2" type="revolute"><parent link="l1"/><child link="l2"/><origin xyz="0 0 0.3"/><axis xyz="0 1 0"/>
    <limit lower="-2" upper="2" velocity="1" effort="1"/></joint>
  <joint name="j3" type="revolute"><parent link="l2"/><child link="l3"/><origin xyz="0 0 0.4"/><axis xyz="0 1 0"/>
    <limit lower="-2" upper="2" velocity="1" effort="1"/></joint>
</robot>)";

const std::vector<double> kStart{0.0, 0.0, 0.0};
const std::vector<double> kTarget{0.05, -0.05, 0.02};
constexpr double kDt = 0.05;

class FakeClock : public Clock {
 public:
  double now() const override { return now_; }
  double wall() const override { return wall_; }
  double now_ = 100.0;
  double wall_ = 1.7e9;
};

/// A robot: its state moves to a trajectory's last point when a move succeeds; in real time the clock advances by the
/// move's duration (and each state read by read_delay).
class FakeDriver : public Driver {
 public:
  explicit FakeDriver(FakeClock* clock) : clock_(clock) {}
  std::string name() const override { return "fake"; }
  bool realTime() const override { return real_time; }
  bool canTeleport() const override { return can_teleport; }
  bool sensesContacts() const override { return senses_contacts; }
  bool currentState(RobotState* s, std::string* error) override {
    ++state_reads;
    if (!state_errors.empty()) {
      const std::string e = state_errors.front();
      state_errors.pop_front();
      if (!e.empty()) {
        *error = e;
        return false;
      }
    }
    clock_->now_ += read_delay;
    *s = state;
    if (!measured.empty()) s->measured = measured;
    return true;
  }
  MoveResult execute(const TimedTrajectory& t, double start) override {
    executed.push_back(t);
    starts.push_back(start);
    MoveResult r;
    if (!ends.empty()) {
      r.end = ends.front();
      ends.pop_front();
    } else {
      r.end = DriverEnd::kSucceeded;
    }
    r.error_code = r.end == DriverEnd::kAborted    ? static_cast<std::int32_t>(TrajectoryError::kPathToleranceViolated)
                   : r.end == DriverEnd::kRejected ? static_cast<std::int32_t>(TrajectoryError::kInvalidGoal)
                                                   : 0;
    r.message = "fake end";
    r.contacts = contacts;
    if (real_time) clock_->now_ = std::max(clock_->now_, start) + t.duration();
    sim_time_ += toNanos(t.duration());
    if (r.end == DriverEnd::kSucceeded) state.q = t.positions.back();
    state.stamp = real_time ? toNanos(clock_->now_) : sim_time_;
    if (r.contacts.available) r.contacts.stamp = state.stamp;
    return r;
  }
  bool teleport(const std::vector<double>& q, RobotState* after, Nanos* motion_epoch, std::string* error,
                bool* unreachable) override {
    teleports.push_back(q);
    if (!teleport_error.empty()) {
      *error = teleport_error;
      *unreachable = teleport_unreachable;
      return false;
    }
    state.q = q;
    sim_time_ += 1000;
    state.stamp = sim_time_;
    *after = state;
    if (restarts_motions) epoch_ = state.stamp;
    *motion_epoch = epoch_;
    return true;
  }
  void setPathTolerance(const std::vector<double>& t) override { tolerance = t; }

  bool real_time = false, can_teleport = true, senses_contacts = true;
  bool restarts_motions = true;  // a teleport restarts the obstacles' motions (not with sensed obstacles)
  Nanos epoch_ = 0;              // when their motion time was 0
  RobotState state{kStart, {}, 5'000'000'000};
  std::vector<double> measured;          // reported as RobotState::measured when set
  std::deque<std::string> state_errors;  // "" = a good read, else that error
  std::deque<DriverEnd> ends;
  ContactReport contacts;
  std::string teleport_error;
  bool teleport_unreachable = false;  // the driver refused the target itself
  double read_delay = 0.0;
  std::vector<TimedTrajectory> executed;
  std::vector<double> starts;
  std::vector<std::vector<double>> teleports;
  std::vector<double> tolerance;
  int state_reads = 0;

 private:
  FakeClock* clock_;
  Nanos sim_time_ = 5'000'000'000;
};

/// A planning scene: answers from a function of the request (default: everything valid), records every request.
class FakeScene : public Scene {
 public:
  explicit FakeScene(FakeClock* clock) : clock_(clock) {
    mps::RobotModelOptions o;
    o.joint_names = {"j1", "j2", "j3"};
    std::string error;
    model_ = mps::RobotModel::fromUrdf(kUrdf, o, &error);
    if (!model_) throw std::runtime_error(error);
    facts_.joint_radius_bounds = {1.0, 0.8, 0.4};
    facts_.padding = 0.01;
    facts_.path_resolution = 0.01;
    facts_.planning_time = 0.1;
  }
  std::string name() const override { return "fake scene"; }
  CallEnd validate(const mps::MotionRequest& q, mps::MotionCheck* a, double timeout) override {
    requests.push_back(q);
    timeouts.push_back(timeout);
    if (!validate_ends.empty()) {
      const CallEnd e = validate_ends.front();
      validate_ends.pop_front();
      if (e != CallEnd::kAnswered) return e;
    }
    *a = mps::MotionCheck();
    if (answer) answer(q, a);
    clock_->now_ += check_delay;
    return CallEnd::kAnswered;
  }
  CallEnd plan(const std::vector<double>& start, const std::vector<double>& goal, double time_limit, mps::PlanResult* a,
               double) override {
    plans.push_back({start, goal});
    plan_limits.push_back(time_limit);
    if (plan_end != CallEnd::kAnswered) return plan_end;
    *a = mps::PlanResult();
    a->status = plan_status;
    if (plan_status == mps::PlanStatus::kSuccess) a->waypoints = {start, plan_via, goal};
    a->message = "fake plan";
    return CallEnd::kAnswered;
  }
  CallEnd motionEpoch(Nanos* epoch, double) override {
    ++epoch_calls;
    if (epoch_end == CallEnd::kAnswered) *epoch = epoch_;
    return epoch_end;
  }
  bool facts(SceneFacts* f, std::string* error) override {
    if (!facts_error.empty()) {
      *error = facts_error;
      return false;
    }
    *f = facts_;
    return true;
  }
  const mps::RobotModel& model() const override { return *model_; }

  std::function<void(const mps::MotionRequest&, mps::MotionCheck*)> answer;
  std::deque<CallEnd> validate_ends;
  CallEnd plan_end = CallEnd::kAnswered;
  mps::PlanStatus plan_status = mps::PlanStatus::kSuccess;
  std::vector<double> plan_via{0.3, 0.3, 0.3};
  CallEnd epoch_end = CallEnd::kAnswered;
  Nanos epoch_ = 4'000'000'000;
  SceneFacts facts_;
  std::string facts_error;
  double check_delay = 0.0;
  std::vector<mps::MotionRequest> requests;
  std::vector<double> timeouts;
  std::vector<std::pair<std::vector<double>, std::vector<double>>> plans;
  std::vector<double> plan_limits;
  int epoch_calls = 0;

 private:
  FakeClock* clock_;
  std::unique_ptr<mps::RobotModel> model_;
};

ShieldOptions options() {
  ShieldOptions o;
  o.enabled = true;
  o.strategy = Strategy::kPlan;
  o.profile = Profile::kLinear;
  o.limits.velocity_scale = 1.0;
  o.reset_velocity_scale = 0.5;
  o.sample_period = 0.01;
  o.scene_margin = 1.0;
  o.check_budget = 0.1;
  o.reset_planning_time = 1.0;
  o.reset_horizon = 0.5;
  o.tracking_budget = 0.005;
  o.start_lead = 0.02;
  o.goal_time = 0.5;
  return o;
}

/// A scene answer with this outcome (and a plan / last free state when relevant).
std::function<void(const mps::MotionRequest&, mps::MotionCheck*)> outcome(mps::MotionOutcome o) {
  return [o](const mps::MotionRequest& q, mps::MotionCheck* a) {
    a->outcome = o;
    a->message = "fake outcome";
    a->pairs = {{"l3", "box", 0.0}};
  };
}

class ShieldTest : public ::testing::Test {
 protected:
  void make(const ShieldOptions& o = options()) { shield = std::make_unique<Shield>(o, &driver, &scene, &clock); }
  StepResult step(const std::vector<double>& target = kTarget, double duration = kDt, double not_after = 0.0) {
    StepRequest req;
    req.target = target;
    req.duration = duration;
    req.not_after = not_after;
    StepResult res;
    shield->step(req, &res, /*record_executed=*/true);
    return res;
  }
  ResetResult reset(const std::vector<double>& q) {
    ResetRequest req;
    req.positions = q;
    ResetResult res;
    shield->reset(req, &res);
    return res;
  }

  FakeClock clock;
  FakeDriver driver{&clock};
  FakeScene scene{&clock};
  std::unique_ptr<Shield> shield;
};

}  // namespace

// --------------------------------------------------------------------------------------------------- step verdicts

TEST_F(ShieldTest, SafeMoveExecutesTheStraightMoveAtLeastDtLong) {
  make();
  const StepResult r = step();
  EXPECT_EQ(r.verdict, Verdict::kSafe) << r.message;
  ASSERT_EQ(driver.executed.size(), 1u);
  EXPECT_EQ(driver.executed[0].positions.front(), kStart);
  EXPECT_EQ(driver.executed[0].positions.back(), kTarget);
  EXPECT_NEAR(driver.executed[0].duration(), kDt, 1e-12);  // 0.05 rad at 1 rad/s: the step's duration binds
  EXPECT_EQ(driver.starts[0], 0.0);                        // lockstep: no start stamp
  ASSERT_EQ(scene.requests.size(), 1u);
  const mps::MotionRequest& q = scene.requests[0];
  EXPECT_EQ(q.start, kStart);
  EXPECT_EQ(q.goal, kTarget);
  EXPECT_TRUE(q.plan_on_path_collision);  // strategy plan
  EXPECT_FALSE(q.find_last_free);
  // Lockstep window: from the state's motion time, the move's duration; the stamp is that instant.
  EXPECT_NEAR(q.start_time, 1.0, 1e-9);  // state 5 s - epoch 4 s
  EXPECT_NEAR(q.duration, kDt, 1e-12);
  EXPECT_NEAR(q.stamp, 5.0, 1e-9);
  EXPECT_NEAR(scene.timeouts[0], 0.1 + 1.0, 1e-12);  // planning_time + scene_margin
  RobotState last;
  ASSERT_TRUE(shield->lastState(&last));
  EXPECT_EQ(last.q, kTarget);
  // The path tolerance the padding leaves, from the scene's facts: budget / (n r_i).
  ASSERT_EQ(driver.tolerance.size(), 3u);
  EXPECT_NEAR(driver.tolerance[0], 0.005 / 3.0, 1e-12);
  EXPECT_NEAR(driver.tolerance[2], 0.005 / (3 * 0.4), 1e-12);
  EXPECT_EQ(scene.epoch_calls, 1);  // the scene's facts are read once
  step();
  EXPECT_EQ(scene.epoch_calls, 1);
}

TEST_F(ShieldTest, ReplannedStepExecutesThePlanFromTheMeasuredState) {
  make();
  scene.answer = [](const mps::MotionRequest& q, mps::MotionCheck* a) {
    a->outcome = mps::MotionOutcome::kPathCollision;
    a->replanned = true;
    a->path = {{0.001, 0, 0}, {0.02, 0.1, 0}, q.goal};
  };
  const StepResult r = step();
  EXPECT_EQ(r.verdict, Verdict::kReplanned);
  ASSERT_EQ(driver.executed.size(), 1u);
  ASSERT_EQ(driver.executed[0].positions.size(), 3u);
  EXPECT_EQ(driver.executed[0].positions.front(), kStart);
  EXPECT_EQ(driver.executed[0].positions.back(), kTarget);
  EXPECT_EQ(r.unsafe_cause, static_cast<std::uint8_t>(mps::MotionOutcome::kPathCollision));
}

TEST_F(ShieldTest, UnsafeTargetsAreHeldWithTheirVerdicts) {
  make();
  const std::pair<mps::MotionOutcome, Verdict> cases[] = {
      {mps::MotionOutcome::kSelfCollision, Verdict::kDiscardedSelf},
      {mps::MotionOutcome::kPoseCollision, Verdict::kDiscardedPose},
      {mps::MotionOutcome::kPathCollision, Verdict::kDiscardedPath},
      {mps::MotionOutcome::kStartInCollision, Verdict::kDiscardedStart},
      {mps::MotionOutcome::kMapStale, Verdict::kDiscardedUnseen},
  };
  for (const auto& c : cases) {
    scene.answer = outcome(c.first);
    const StepResult r = step();
    EXPECT_EQ(r.verdict, c.second) << verdictName(c.second);
    EXPECT_EQ(r.pairs.size(), 1u);
    EXPECT_EQ(r.message, "fake outcome");
  }
  EXPECT_TRUE(driver.executed.empty());  // no moving obstacles: nothing to hold through the driver
}

TEST_F(ShieldTest, LockstepHoldsThroughTheDriverWhileObstaclesMove) {
  make();
  scene.answer = [](const mps::MotionRequest&, mps::MotionCheck* a) {
    a->outcome = mps::MotionOutcome::kPoseCollision;
    a->moving_obstacles = true;
  };
  const StepResult r = step();
  EXPECT_EQ(r.verdict, Verdict::kDiscardedPose);
  ASSERT_EQ(driver.executed.size(), 1u);  // a hold of dt, so that simulated time (and the obstacles) go on
  EXPECT_EQ(driver.executed[0].positions.front(), kStart);
  EXPECT_EQ(driver.executed[0].positions.back(), kStart);
  EXPECT_NEAR(driver.executed[0].duration(), kDt, 1e-12);
  // A step of duration 0 asks for no hold.
  step(kTarget, 0.0);
  EXPECT_EQ(driver.executed.size(), 1u);
}

TEST_F(ShieldTest, StrategiesDiscardAndLastSafe) {
  ShieldOptions o = options();
  o.strategy = Strategy::kDiscard;
  make(o);
  scene.answer = [](const mps::MotionRequest& q, mps::MotionCheck* a) {
    a->outcome = mps::MotionOutcome::kPathCollision;
    a->replanned = true;  // a plan on offer is ignored
    a->path = {q.start, q.goal};
  };
  EXPECT_EQ(step().verdict, Verdict::kDiscardedPath);
  EXPECT_FALSE(scene.requests.back().plan_on_path_collision);
  EXPECT_TRUE(driver.executed.empty());

  o.strategy = Strategy::kLastSafe;
  make(o);
  scene.answer = [](const mps::MotionRequest& q, mps::MotionCheck* a) {
    a->outcome = mps::MotionOutcome::kPoseCollision;
    a->last_free_fraction = 0.5;
    a->last_free_state = {0.025, -0.025, 0.01};
  };
  const StepResult r = step();
  EXPECT_EQ(r.verdict, Verdict::kTruncated);
  EXPECT_TRUE(scene.requests.back().find_last_free);
  EXPECT_DOUBLE_EQ(r.truncated_fraction, 0.5);
  EXPECT_NE(r.message.find("truncated"), std::string::npos);
  ASSERT_EQ(driver.executed.size(), 1u);
  EXPECT_EQ(driver.executed[0].positions.back(), (std::vector<double>{0.025, -0.025, 0.01}));
}

TEST_F(ShieldTest, RetreatAsksForMovesWithinTheStepsReachAndExecutesThem) {
  ShieldOptions o = options();
  o.strategy = Strategy::kRetreat;
  o.limits.velocity_scale = 0.5;
  make(o);
  const std::vector<double> away{-0.01, 0.01, 0.0};
  scene.answer = [&](const mps::MotionRequest& q, mps::MotionCheck* a) {
    a->outcome = mps::MotionOutcome::kStartInCollision;
    a->moving_obstacles = true;
    a->threatened = true;
    a->retreat_state = away;
  };
  const StepResult r = step();
  EXPECT_EQ(r.verdict, Verdict::kRetreated) << r.message;
  EXPECT_EQ(r.unsafe_cause, static_cast<std::uint8_t>(mps::MotionOutcome::kStartInCollision));
  const mps::MotionRequest& q = scene.requests.back();
  EXPECT_TRUE(q.plan_on_path_collision);
  // Each joint's reach: its velocity limit (the URDF's, 1 rad/s) x velocity_scale x the move's duration (the straight
  // move at half speed: 0.05 rad / 0.5 rad/s = 0.1 s, longer than dt).
  ASSERT_EQ(q.retreat_reach.size(), 3u);
  for (double v : q.retreat_reach) EXPECT_NEAR(v, 1.0 * 0.5 * 0.1, 1e-9);
  ASSERT_EQ(driver.executed.size(), 1u);  // the retreat, not a hold
  EXPECT_EQ(driver.executed[0].positions.front(), kStart);
  EXPECT_EQ(driver.executed[0].positions.back(), away);
  // Without a retreat on offer: held (through the driver: the obstacles move).
  scene.answer = outcome(mps::MotionOutcome::kStartInCollision);
  EXPECT_EQ(step().verdict, Verdict::kDiscardedStart);
  // The other strategies never ask for one.
  make(options());
  step();
  EXPECT_TRUE(scene.requests.back().retreat_reach.empty());
}

TEST_F(ShieldTest, DisabledShieldPassesThroughUnchecked) {
  ShieldOptions o = options();
  o.enabled = false;
  make(o);
  const StepResult r = step();
  EXPECT_EQ(r.verdict, Verdict::kUnchecked);
  EXPECT_TRUE(scene.requests.empty());
  ASSERT_EQ(driver.executed.size(), 1u);
  EXPECT_EQ(driver.executed[0].positions.back(), kTarget);
}

TEST_F(ShieldTest, InvalidRequestsMoveNothing) {
  make();
  EXPECT_EQ(step({0.1, 0.2}).verdict, Verdict::kInvalidRequest);
  EXPECT_EQ(step({0.1, std::nan(""), 0.0}).verdict, Verdict::kInvalidRequest);
  EXPECT_EQ(step(kTarget, -1.0).verdict, Verdict::kInvalidRequest);
  EXPECT_EQ(step(kTarget, Shield::kMaxStepDuration * 2).verdict, Verdict::kInvalidRequest);
  EXPECT_EQ(step(kTarget, std::numeric_limits<double>::infinity()).verdict, Verdict::kInvalidRequest);
  // A request whose caller gave up (not_after passed on the wall clock) is refused.
  const StepResult late = step(kTarget, kDt, clock.wall_ - 1.0);
  EXPECT_EQ(late.verdict, Verdict::kInvalidRequest);
  EXPECT_NE(late.message.find("gave up"), std::string::npos);
  EXPECT_EQ(step(kTarget, kDt, clock.wall_ + 1.0).verdict, Verdict::kSafe);  // not yet
  EXPECT_EQ(driver.executed.size(), 1u);
}

// ------------------------------------------------------------------------------------------------ failure paths

TEST_F(ShieldTest, NoStateFailsClosed) {
  make();
  driver.state_errors = {"no joint state for 0.6 s"};
  const StepResult r = step();
  EXPECT_EQ(r.verdict, Verdict::kStateUnavailable);
  EXPECT_NE(r.message.find("no joint state"), std::string::npos);
  EXPECT_TRUE(scene.requests.empty());
  EXPECT_FALSE(shield->lastState(nullptr));
}

TEST_F(ShieldTest, NoStateAfterTheMoveFailsClosed) {
  make();
  driver.state_errors = {"", "stalled"};
  const StepResult r = step();
  EXPECT_EQ(r.verdict, Verdict::kStateUnavailable);
  EXPECT_NE(r.message.find("after the move"), std::string::npos);
}

TEST_F(ShieldTest, SceneFactsMissingFailClosed) {
  make();
  scene.epoch_end = CallEnd::kTimedOut;
  StepResult r = step();
  EXPECT_EQ(r.verdict, Verdict::kSceneUnavailable);
  EXPECT_NE(r.message.find("did not answer within its deadline"), std::string::npos) << r.message;
  scene.epoch_end = CallEnd::kUnreachable;
  r = step();
  EXPECT_EQ(r.verdict, Verdict::kSceneUnavailable);
  EXPECT_NE(r.message.find("unreachable"), std::string::npos) << r.message;
  scene.epoch_end = CallEnd::kAnswered;
  scene.facts_error = "parameters not set";
  EXPECT_EQ(step().verdict, Verdict::kSceneUnavailable);
  scene.facts_error.clear();
  scene.facts_.joint_radius_bounds = {1.0};
  r = step();
  EXPECT_EQ(r.verdict, Verdict::kSceneUnavailable);
  EXPECT_NE(r.message.find("joint_radius_bounds"), std::string::npos);
  scene.facts_.joint_radius_bounds = {1.0, 0.8, 0.4};
  scene.facts_.padding = 0.005;  // leaves 0 m along a path: the tracking budget does not fit
  r = step();
  EXPECT_EQ(r.verdict, Verdict::kSceneUnavailable);
  EXPECT_NE(r.message.find("tracking_budget"), std::string::npos);
  EXPECT_TRUE(driver.executed.empty());
  scene.facts_.padding = 0.01;
  EXPECT_EQ(step().verdict, Verdict::kSafe);
}

TEST_F(ShieldTest, SceneThatDoesNotAnswerFailsClosed) {
  make();
  for (CallEnd end : {CallEnd::kTimedOut, CallEnd::kUnreachable, CallEnd::kClosed, CallEnd::kFailed}) {
    scene.validate_ends = {end};
    const StepResult r = step();
    EXPECT_EQ(r.verdict, Verdict::kSceneUnavailable);
    EXPECT_NE(r.message.find("failing closed"), std::string::npos);
  }
  EXPECT_TRUE(driver.executed.empty());
  EXPECT_EQ(scene.validate_ends.size(), 0u);
}

TEST_F(ShieldTest, UnknownSceneCodeFailsClosed) {
  make();
  scene.answer = [](const mps::MotionRequest&, mps::MotionCheck* a) {
    a->outcome = static_cast<mps::MotionOutcome>(42);
  };
  EXPECT_EQ(step().verdict, Verdict::kSceneUnavailable);
  scene.answer = outcome(mps::MotionOutcome::kInvalidRequest);
  EXPECT_EQ(step().verdict, Verdict::kInvalidRequest);
  EXPECT_TRUE(driver.executed.empty());
}

TEST_F(ShieldTest, DriverEndsMapToVerdicts) {
  make();
  driver.ends = {DriverEnd::kAborted};
  StepResult r = step();
  EXPECT_EQ(r.verdict, Verdict::kAborted);
  EXPECT_EQ(r.driver_error_code, static_cast<std::int32_t>(TrajectoryError::kPathToleranceViolated));
  EXPECT_NE(r.message.find("driver fake"), std::string::npos);
  driver.ends = {DriverEnd::kRejected};
  EXPECT_EQ(step().verdict, Verdict::kExecutionFailed);
  driver.ends = {DriverEnd::kPreempted};
  EXPECT_EQ(step().verdict, Verdict::kExecutionFailed);
  const int reads = driver.state_reads;
  driver.ends = {DriverEnd::kTimedOut};
  EXPECT_EQ(step().verdict, Verdict::kDriverUnavailable);
  EXPECT_EQ(driver.state_reads, reads + 1);  // no state read after a lost move (only the one before)
  driver.ends = {DriverEnd::kUnreachable};
  EXPECT_EQ(step().verdict, Verdict::kDriverUnavailable);
  driver.ends = {DriverEnd::kLost};  // sent, then the connection closed: it may have moved; fail closed, no state
  const int before = driver.state_reads;
  EXPECT_EQ(step().verdict, Verdict::kDriverUnavailable);
  EXPECT_EQ(driver.state_reads, before + 1);
}

TEST_F(ShieldTest, UntimeableMoveFailsAsExecution) {
  ShieldOptions o = options();
  o.limits.velocity_scale = 0.0;  // timing refuses it
  make(o);
  StepResult r = step();
  EXPECT_EQ(r.verdict, Verdict::kExecutionFailed);
  EXPECT_NE(r.message.find("cannot time"), std::string::npos);
  o.enabled = false;
  make(o);
  EXPECT_EQ(step().verdict, Verdict::kExecutionFailed);
  EXPECT_TRUE(driver.executed.empty());
}

TEST_F(ShieldTest, ContactsComeFromTheDriverAndAreKeptBetweenMoves) {
  make();
  driver.contacts.available = true;
  driver.contacts.world_contacts = 2;
  driver.contacts.total_contact_substeps = 7;
  driver.contacts.pairs = {{"l3", "box", 0.002}};
  StepResult r = step();
  EXPECT_TRUE(r.contacts.available);
  EXPECT_EQ(r.contacts.world_contacts, 2u);
  EXPECT_EQ(r.contacts.pairs.size(), 1u);
  EXPECT_GT(r.contacts.stamp, 0);
  EXPECT_EQ(shield->totalContactSubsteps(), 7u);
  // A step that moves nothing reports no contacts, the running total, and the state's stamp.
  scene.answer = outcome(mps::MotionOutcome::kPoseCollision);
  r = step();
  EXPECT_EQ(r.contacts.world_contacts, 0u);
  EXPECT_TRUE(r.contacts.pairs.empty());
  EXPECT_EQ(r.contacts.total_contact_substeps, 7u);
  EXPECT_EQ(r.contacts.stamp, driver.state.stamp);
}

// --------------------------------------------------------------------------------------------------- real time

TEST_F(ShieldTest, RealTimeWindowCoversCheckLeadAndGoalTime) {
  driver.real_time = true;
  driver.senses_contacts = false;
  make();
  driver.state.stamp = toNanos(clock.now_ - 0.1);  // a state 0.1 s old
  const double t0 = clock.now_;
  const StepResult r = step();
  EXPECT_EQ(r.verdict, Verdict::kSafe);
  const mps::MotionRequest& q = scene.requests[0];
  EXPECT_NEAR(q.start_time, (t0 - 0.1) - 4.0, 1e-6);
  // from the state's stamp to: the check's start + check_budget + start_lead, + the move, + goal_time
  EXPECT_NEAR(q.duration, 0.1 + 0.1 + 0.02 + kDt + 0.5, 1e-6);
  EXPECT_NEAR(driver.starts[0], t0 + 0.02, 1e-6);  // sent to start start_lead from now
}

TEST_F(ShieldTest, RealTimeCheckBeyondItsBudgetIsNotSent) {
  driver.real_time = true;
  make();
  scene.check_delay = 0.2;  // the check takes longer than check_budget: the window no longer holds
  const StepResult r = step();
  EXPECT_EQ(r.verdict, Verdict::kSceneUnavailable);
  EXPECT_NE(r.message.find("check_budget"), std::string::npos);
  EXPECT_TRUE(driver.executed.empty());
}

// Issue 23 item 4: a replanned move is covered by the margin of plan_horizon from the state's stamp. In real time its
// window also holds the state's age, the planning, start_lead and goal_time.
TEST_F(ShieldTest, SensedPlanLongerThanItsMarginCoversIsHeld) {
  make();
  auto plan_answer = [](double horizon) {
    return [horizon](const mps::MotionRequest& q, mps::MotionCheck* a) {
      a->outcome = mps::MotionOutcome::kPathCollision;
      a->replanned = true;
      a->plan_horizon = horizon;
      a->map_age = 0.1;
      a->path = {q.start, {0.5, 0.0, 0.0}, q.goal};  // 0.5 + ~0.45 rad at 1 rad/s: ~0.95 s
    };
  };
  scene.answer = plan_answer(0.9);
  StepResult r = step();
  EXPECT_EQ(r.verdict, Verdict::kDiscardedPath);
  EXPECT_NE(r.message.find("longer than the sensed margin covers"), std::string::npos) << r.message;
  scene.answer = plan_answer(1.0);
  EXPECT_EQ(step().verdict, Verdict::kReplanned);  // lockstep: the plan alone, 0.95 s
  driver.real_time = true;
  make();
  driver.state.stamp = toNanos(clock.now_ - 0.2);  // a state 0.2 s old
  r = step();  // 0.2 + 0.02 + 0.95 + 0.5 s > 1 s: not covered (issue 23: only the 0.95 s were compared)
  EXPECT_EQ(r.verdict, Verdict::kDiscardedPath) << r.message;
  EXPECT_NE(r.message.find("goal time"), std::string::npos) << r.message;
  scene.answer = plan_answer(2.0);
  driver.state.stamp = toNanos(clock.now_);
  EXPECT_EQ(step().verdict, Verdict::kReplanned);
}

// Issue 23 item 5: the state as measured, beyond a limit, goes to the scene beside the clamped one.
TEST_F(ShieldTest, MeasuredStateBeyondALimitIsChecked) {
  make();
  driver.measured = {2.015, 0.0, 0.0};
  driver.state.q = {2.0, 0.0, 0.0};
  step({1.98, 0.0, 0.0});
  ASSERT_EQ(scene.requests.size(), 1u);
  EXPECT_EQ(scene.requests[0].start, (std::vector<double>{2.0, 0.0, 0.0}));
  EXPECT_EQ(scene.requests[0].measured_start, (std::vector<double>{2.015, 0.0, 0.0}));
}

// ------------------------------------------------------------------------------------------------------- reset

TEST_F(ShieldTest, ATeleportThatDoesNotRestartTheMotionsKeepsTheirEpoch) {
  // With sensed obstacles the simulator teleports the robot but leaves the walk where it is (a person does not jump
  // back under the cameras' eyes): the motions' epoch is the simulator's, not the teleport's stamp.
  make();
  driver.restarts_motions = false;
  driver.epoch_ = 1'000'000'000;
  ResetResult r = reset({0.1, 0.2, 0.3});
  EXPECT_TRUE(r.success) << r.message;
  EXPECT_EQ(r.motion_epoch, 1'000'000'000);
  EXPECT_NE(r.motion_epoch, driver.state.stamp);
}

TEST_F(ShieldTest, ResetTeleportsWhenTheDriverCan) {
  make();
  ResetResult r = reset({0.1, 0.2, 0.3});
  EXPECT_TRUE(r.success) << r.message;
  ASSERT_EQ(driver.teleports.size(), 1u);
  EXPECT_EQ(r.motion_epoch, driver.state.stamp);  // the motions restart at the teleport
  RobotState s;
  ASSERT_TRUE(shield->lastState(&s));
  EXPECT_EQ(s.q, (std::vector<double>{0.1, 0.2, 0.3}));
  // The next step's window starts at the new epoch.
  step({0.12, 0.2, 0.3});
  EXPECT_NEAR(scene.requests.back().start_time, 0.0, 1e-9);
  driver.teleport_error = "a trajectory is executing";
  r = reset({0.1, 0.2, 0.3});
  EXPECT_FALSE(r.success);
  EXPECT_FALSE(r.unreachable);  // a failure: not a reason to try another target
  EXPECT_EQ(r.message, "a trajectory is executing");
  // A target the simulator refuses itself (it touches an obstacle where the motions restart): try another.
  driver.teleport_error = "the target touches the world where the obstacles' motions restart (l3 / person)";
  driver.teleport_unreachable = true;
  r = reset({0.1, 0.2, 0.3});
  EXPECT_FALSE(r.success);
  EXPECT_TRUE(r.unreachable);
}

TEST_F(ShieldTest, ResetWhereTheRobotStandsAndBadResets) {
  make();
  ResetResult r = reset({});
  EXPECT_TRUE(r.success) << r.message;
  EXPECT_EQ(r.motion_epoch, scene.epoch_);
  EXPECT_TRUE(driver.teleports.empty());
  EXPECT_FALSE(reset({0.1}).success);
  ResetRequest late;
  late.positions = kTarget;
  late.not_after = clock.wall_ - 1.0;
  shield->reset(late, &r);
  EXPECT_FALSE(r.success);
  EXPECT_NE(r.message.find("gave up"), std::string::npos);
  driver.state_errors = {"stale"};
  EXPECT_FALSE(reset({}).success);
  make();  // a new shield: it has not read the scene's facts yet
  scene.epoch_end = CallEnd::kTimedOut;
  r = reset({});
  EXPECT_FALSE(r.success);
  EXPECT_NE(r.message.find("planning scene"), std::string::npos);
}

class PlannedResetTest : public ShieldTest {
 protected:
  void SetUp() override {
    driver.real_time = true;
    driver.can_teleport = false;
    driver.senses_contacts = false;
    ShieldOptions o = options();
    o.profile = Profile::kMinJerk;
    make(o);
  }
};

TEST_F(PlannedResetTest, StraightResetMovesAtTheResetSpeed) {
  const ResetResult r = reset({0.4, 0.0, 0.0});
  EXPECT_TRUE(r.success) << r.message;
  ASSERT_EQ(driver.executed.size(), 1u);
  // min_jerk at half speed: 0.4 rad * 1.875 / 0.5 rad/s = 1.5 s.
  EXPECT_NEAR(driver.executed[0].duration(), 1.5, 1e-9);
  EXPECT_NEAR(r.planned_duration, 1.5, 1e-9);
  EXPECT_EQ(r.moves, 1u);
  EXPECT_FALSE(scene.requests[0].plan_on_path_collision);
}

TEST_F(PlannedResetTest, PathCollisionIsPlannedAroundOrUnreachable) {
  scene.answer = outcome(mps::MotionOutcome::kPathCollision);
  ResetResult r = reset({0.4, 0.0, 0.0});
  EXPECT_TRUE(r.success) << r.message;
  ASSERT_EQ(scene.plans.size(), 1u);
  EXPECT_DOUBLE_EQ(scene.plan_limits[0], 1.0);  // reset_planning_time
  ASSERT_EQ(driver.executed.size(), 1u);
  EXPECT_EQ(driver.executed[0].positions.back(), (std::vector<double>{0.4, 0.0, 0.0}));
  scene.plan_status = mps::PlanStatus::kNoSolution;
  r = reset({0.0, 0.0, 0.0});
  EXPECT_FALSE(r.success);
  EXPECT_TRUE(r.unreachable);
  scene.plan_status = mps::PlanStatus::kGoalInvalid;
  r = reset({0.0, 0.0, 0.0});
  EXPECT_FALSE(r.unreachable);
  scene.plan_end = CallEnd::kTimedOut;
  r = reset({0.0, 0.0, 0.0});
  EXPECT_FALSE(r.success);
  EXPECT_NE(r.message.find("did not answer"), std::string::npos);
}

TEST_F(PlannedResetTest, StartInCollisionOrRefusedTargetIsNotMoved) {
  scene.answer = outcome(mps::MotionOutcome::kStartInCollision);
  ResetResult r = reset({0.4, 0.0, 0.0});
  EXPECT_FALSE(r.success);
  EXPECT_NE(r.message.find("not free where it stands"), std::string::npos);
  scene.answer = outcome(mps::MotionOutcome::kPoseCollision);
  r = reset({0.4, 0.0, 0.0});
  EXPECT_FALSE(r.success);
  EXPECT_NE(r.message.find("refused"), std::string::npos);
  scene.answer = nullptr;
  scene.validate_ends = {CallEnd::kUnreachable};
  EXPECT_FALSE(reset({0.4, 0.0, 0.0}).success);
  scene.check_delay = 0.2;  // beyond check_budget: a real-time reset move is not sent
  r = reset({0.4, 0.0, 0.0});
  EXPECT_FALSE(r.success);
  EXPECT_NE(r.message.find("check_budget"), std::string::npos);
  EXPECT_TRUE(driver.executed.empty());
}

// Issue 23 item 4: with sensed obstacles a reset lasting seconds runs in moves of at most reset_horizon, each checked
// from where it starts with the margin of its own whole window; the old shield checked the straight move once (or a
// plan with the margin of plan_horizon) and executed seconds of motion on it.
TEST_F(PlannedResetTest, SensedResetRunsInPiecesEachCoveredForItsWindow) {
  scene.answer = [](const mps::MotionRequest&, mps::MotionCheck* a) {
    a->outcome = mps::MotionOutcome::kValid;
    a->map_age = 0.2;
    a->plan_horizon = 1.0;
  };
  const ResetResult r = reset({0.4, 0.0, 0.0});  // 1.5 s at reset speed
  EXPECT_TRUE(r.success) << r.message;
  EXPECT_EQ(r.moves, 3u);  // pieces of 0.5 s
  EXPECT_NEAR(r.planned_duration, 1.5, 1e-9);
  ASSERT_EQ(driver.executed.size(), 3u);
  ASSERT_EQ(scene.requests.size(), 4u);  // the whole path once, then each piece from where it starts
  for (std::size_t k = 0; k < 3; ++k) {
    const TimedTrajectory& t = driver.executed[k];
    EXPECT_LE(t.duration(), 0.5 + 1e-9);
    const mps::MotionRequest& q = scene.requests[k + 1];
    EXPECT_EQ(q.start, t.positions.front());
    EXPECT_EQ(q.goal, t.positions.back());
    // The window covers the piece, the check, the start lead and the goal time.
    EXPECT_GE(q.duration, t.duration() + 0.1 + 0.02 + 0.5 - 1e-9);
  }
  EXPECT_EQ(driver.executed.back().positions.back(), (std::vector<double>{0.4, 0.0, 0.0}));
}

TEST_F(PlannedResetTest, SensedResetStopsWhenAPieceIsNoLongerFree) {
  int calls = 0;
  scene.answer = [&calls](const mps::MotionRequest&, mps::MotionCheck* a) {
    a->map_age = 0.2;
    a->outcome = ++calls == 3 ? mps::MotionOutcome::kPoseCollision : mps::MotionOutcome::kValid;  // 2nd piece
    a->message = "person";
  };
  const ResetResult r = reset({0.4, 0.0, 0.0});
  EXPECT_FALSE(r.success);
  EXPECT_TRUE(r.unreachable);  // the env samples another start
  EXPECT_EQ(r.moves, 1u);
  EXPECT_EQ(driver.executed.size(), 1u);
  EXPECT_NE(r.message.find("person"), std::string::npos);
}

TEST_F(PlannedResetTest, SensedPlanIsExecutedInPiecesToo) {
  int calls = 0;
  scene.answer = [&calls](const mps::MotionRequest&, mps::MotionCheck* a) {
    a->map_age = 0.2;
    a->outcome = ++calls == 1 ? mps::MotionOutcome::kPathCollision : mps::MotionOutcome::kValid;
  };
  scene.plan_via = {0.4, 0.4, 0.0};
  const ResetResult r = reset({0.0, 0.8, 0.0});
  EXPECT_TRUE(r.success) << r.message;
  ASSERT_EQ(scene.plans.size(), 1u);
  EXPECT_GE(r.moves, 4u);  // two segments of 0.4 rad (1.5 s each at reset speed): 3 pieces each
  for (const TimedTrajectory& t : driver.executed) EXPECT_LE(t.duration(), 0.5 + 1e-9);
  EXPECT_EQ(driver.executed.back().positions.back(), (std::vector<double>{0.0, 0.8, 0.0}));
}

TEST_F(PlannedResetTest, FailuresOnTheWayFailTheReset) {
  // No state to start from; the scene's facts missing.
  driver.state_errors = {"no joint state"};
  ResetResult r = reset({0.4, 0.0, 0.0});
  EXPECT_FALSE(r.success);
  EXPECT_NE(r.message.find("joint states"), std::string::npos) << r.message;
  make();
  scene.epoch_end = CallEnd::kUnreachable;
  r = reset({0.4, 0.0, 0.0});
  EXPECT_FALSE(r.success);
  EXPECT_NE(r.message.find("planning scene"), std::string::npos) << r.message;
  scene.epoch_end = CallEnd::kAnswered;
  // Reset to where the robot stands: nothing to move, a success.
  r = reset(driver.state.q);
  EXPECT_TRUE(r.success) << r.message;
  EXPECT_TRUE(driver.executed.empty());
  // The driver aborts the reset move.
  driver.ends = {DriverEnd::kAborted};
  r = reset({0.4, 0.0, 0.0});
  EXPECT_FALSE(r.success);
  EXPECT_NE(r.message.find("driver fake"), std::string::npos) << r.message;
}

TEST_F(PlannedResetTest, SensedPieceFailuresStopTheReset) {
  auto sensed = [](const mps::MotionRequest&, mps::MotionCheck* a) {
    a->outcome = mps::MotionOutcome::kValid;
    a->map_age = 0.2;
  };
  scene.answer = sensed;
  driver.state_errors = {"", "", "stalled"};  // the reset's first read, the first piece's, then none
  ResetResult r = reset({0.4, 0.0, 0.0});
  EXPECT_FALSE(r.success);
  EXPECT_NE(r.message.find("stalled"), std::string::npos) << r.message;
  scene.validate_ends = {CallEnd::kAnswered, CallEnd::kTimedOut};  // the whole path, then the first piece
  r = reset({0.0, 0.0, 0.0});
  EXPECT_FALSE(r.success);
  EXPECT_NE(r.message.find("did not answer"), std::string::npos) << r.message;
  driver.ends = {DriverEnd::kSucceeded, DriverEnd::kAborted};
  r = reset({0.4, 0.0, 0.0});
  EXPECT_FALSE(r.success);
  EXPECT_EQ(r.moves, 2u);
  // Refused as a whole (its margin of seconds) but free piece by piece: the reset runs.
  int calls = 0;
  scene.answer = [&calls](const mps::MotionRequest&, mps::MotionCheck* a) {
    a->map_age = 0.2;
    a->outcome = ++calls == 1 ? mps::MotionOutcome::kPoseCollision : mps::MotionOutcome::kValid;
  };
  r = reset({0.0, 0.0, 0.0});
  EXPECT_TRUE(r.success) << r.message;
}

TEST_F(PlannedResetTest, DisabledShieldResetsUnchecked) {
  ShieldOptions o = options();
  o.enabled = false;
  make(o);
  const ResetResult r = reset({0.4, 0.0, 0.0});
  EXPECT_TRUE(r.success) << r.message;
  EXPECT_TRUE(scene.requests.empty());
  EXPECT_EQ(driver.executed.size(), 1u);
}

TEST(ShieldOptionsTest, AccelerationLimitsMustMatchTheJoints) {
  FakeClock clock;
  FakeDriver driver(&clock);
  FakeScene scene(&clock);
  ShieldOptions o = options();
  o.limits.acceleration = {1.0, 2.0};
  EXPECT_THROW(Shield(o, &driver, &scene, &clock), std::invalid_argument);
  o.limits.acceleration = {1.0, 2.0, 3.0};
  EXPECT_NO_THROW(Shield(o, &driver, &scene, &clock));
}

int main(int argc, char** argv) {
  ::testing::InitGoogleTest(&argc, argv);
  return RUN_ALL_TESTS();
}
