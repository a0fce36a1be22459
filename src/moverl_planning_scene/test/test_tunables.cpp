/**
 * \file test_tunables.cpp
 * \brief The sensed-obstacle monitor's tunables (readOctomapMonitorOptions) as config/planning_scene.yaml ships them,
 *        and the values it refuses, with their messages. No roscore.
 */
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <fstream>
#include <functional>
#include <limits>
#include <map>
#include <set>
#include <string>
#include <variant>

#include <yaml-cpp/yaml.h>

#include "moverl_planning_scene/octomap_monitor_options.h"
#include "moverl_planning_scene/tunables.h"
#include "panda_support.h"

namespace mps = moverl_planning_scene;

namespace {

const double kInf = std::numeric_limits<double>::infinity();

/// The shipped tunables with some keys replaced (a value of another type: as a parameter of the wrong type) or
/// removed; it records every key asked for.
class EditedTunables : public mps::Tunables {
 public:
  using Value = std::variant<std::monostate, double, int, bool, std::string>;  // monostate: removed
  explicit EditedTunables(std::map<std::string, Value> edits = {}) : edits_(std::move(edits)) {}
  bool get(const std::string& key, double* value) const override { return fetch(key, value); }
  bool get(const std::string& key, int* value) const override { return fetch(key, value); }
  bool get(const std::string& key, bool* value) const override { return fetch(key, value); }
  bool get(const std::string& key, std::string* value) const override { return fetch(key, value); }
  std::string describe(const std::string& key) const override { return "edited " + key; }
  const std::set<std::string>& asked() const { return asked_; }

 private:
  template <class T>
  bool fetch(const std::string& key, T* value) const {
    asked_.insert(key);
    const auto it = edits_.find(key);
    if (it == edits_.end()) return mps::panda::shippedTunables().get(key, value);
    const T* edited = std::get_if<T>(&it->second);
    if (edited == nullptr) return false;
    *value = *edited;
    return true;
  }
  std::map<std::string, Value> edits_;
  mutable std::set<std::string> asked_;
};

/// The error readOctomapMonitorOptions gives these tunables ("" when it accepts them).
std::string refusal(const mps::Tunables& t) {
  mps::OctomapMonitorOptions o;
  std::string error;
  return mps::readOctomapMonitorOptions(t, &o, &error) ? "" : error;
}

template <class T>
T shipped(const std::string& key) {
  return mps::panda::shippedTunables().require<T>(key);
}

}  // namespace

// Every value lands in its field, as the file gives it.
TEST(OctomapMonitorOptions, ShippedValues) {
  mps::OctomapMonitorOptions o;
  std::string error;
  ASSERT_TRUE(mps::readOctomapMonitorOptions(mps::panda::shippedTunables(), &o, &error)) << error;
  EXPECT_EQ(o.map.resolution, shipped<double>("octomap/resolution"));
  EXPECT_EQ(o.map.max_range, shipped<double>("octomap/max_range"));
  EXPECT_EQ(o.map.prob_hit, shipped<double>("octomap/prob_hit"));
  EXPECT_EQ(o.map.prob_miss, shipped<double>("octomap/prob_miss"));
  EXPECT_EQ(o.map.clamp_min, shipped<double>("octomap/clamp_min"));
  EXPECT_EQ(o.map.clamp_max, shipped<double>("octomap/clamp_max"));
  EXPECT_EQ(o.map.occupancy_threshold, shipped<double>("octomap/occupancy_threshold"));
  EXPECT_EQ(o.map.watch_time, shipped<double>("octomap/watch_time"));
  EXPECT_EQ(o.cloud_topic, shipped<std::string>("octomap/cloud_topic"));
  EXPECT_EQ(o.joint_states_topic, shipped<std::string>("octomap/joint_states_topic"));
  EXPECT_EQ(o.queue_size, shipped<int>("octomap/queue_size"));
  EXPECT_EQ(o.startup_timeout, shipped<double>("octomap/startup_timeout"));
  EXPECT_EQ(o.camera_wait, shipped<double>("octomap/camera_wait"));
  EXPECT_EQ(o.batch_wait, shipped<double>("octomap/batch_wait"));
  EXPECT_EQ(o.transform_timeout, shipped<double>("octomap/transform_timeout"));
  EXPECT_EQ(o.joint_state_wait, shipped<double>("octomap/joint_state_wait"));
  EXPECT_EQ(o.future_tolerance, shipped<double>("octomap/future_tolerance"));
  EXPECT_EQ(o.self_filter_padding, shipped<double>("octomap/self_filter_padding"));
  EXPECT_EQ(o.static_filter_padding, shipped<double>("octomap/static_filter_padding"));
  mps::Integration integration = mps::Integration::kRayCasting;
  ASSERT_TRUE(mps::parseIntegration(shipped<std::string>("octomap/integration"), &integration, &error)) << error;
  EXPECT_EQ(o.integration, integration);
  EXPECT_EQ(o.integration_threads, shipped<int>("octomap/integration_threads"));
  EXPECT_EQ(o.lockstep, shipped<bool>("octomap/lockstep"));
  EXPECT_EQ(o.lockstep_lag, o.lockstep && shipped<bool>("octomap/lockstep_lag"));
  EXPECT_EQ(o.lockstep_lag_max_margin, shipped<double>("octomap/lockstep_lag_max_margin"));
  mps::Safety safety = mps::Safety::kSsm;
  ASSERT_TRUE(mps::parseSafety(shipped<std::string>("octomap/safety"), &safety));
  EXPECT_EQ(o.margin.safety, safety);
  EXPECT_EQ(o.margin.speed_bound, shipped<double>("octomap/speed_bound"));
  EXPECT_EQ(o.margin.latency, shipped<double>("octomap/latency"));
  EXPECT_EQ(o.margin.plan_horizon, shipped<double>("octomap/plan_horizon"));
  EXPECT_EQ(o.margin.max_age, shipped<double>("octomap/max_age"));
  EXPECT_EQ(o.stale_wait, shipped<double>("octomap/stale_wait"));
  // The file's own values, where the margin and the map's size depend on them.
  EXPECT_EQ(o.integration, mps::Integration::kProjective);
  EXPECT_FALSE(o.lockstep);  // launch/planning_scene.launch sets it from its lockstep argument
}

// The octomap: section holds 29 keys; it asks for each (octomap/lockstep_lag in lockstep only), and for no other.
TEST(OctomapMonitorOptions, ReadsEveryKeyOfTheFile) {
  const std::set<std::string> keys = {"octomap/cloud_topic",
                                      "octomap/joint_states_topic",
                                      "octomap/queue_size",
                                      "octomap/lockstep",
                                      "octomap/lockstep_lag",
                                      "octomap/lockstep_lag_max_margin",
                                      "octomap/resolution",
                                      "octomap/max_range",
                                      "octomap/integration",
                                      "octomap/integration_threads",
                                      "octomap/self_filter_padding",
                                      "octomap/static_filter_padding",
                                      "octomap/transform_timeout",
                                      "octomap/joint_state_wait",
                                      "octomap/prob_hit",
                                      "octomap/prob_miss",
                                      "octomap/clamp_min",
                                      "octomap/clamp_max",
                                      "octomap/occupancy_threshold",
                                      "octomap/startup_timeout",
                                      "octomap/camera_wait",
                                      "octomap/watch_time",
                                      "octomap/batch_wait",
                                      "octomap/future_tolerance",
                                      "octomap/safety",
                                      "octomap/speed_bound",
                                      "octomap/ssm/intrusion",
                                      "octomap/ssm/sensor_uncertainty",
                                      "octomap/ssm/tracking/use",
                                      "octomap/ssm/tracking/max_speed",
                                      "octomap/ssm/tracking/position_error",
                                      "octomap/ssm/tracking/max_age",
                                      "octomap/ssm/tracking/parts",
                                      "octomap/latency",
                                      "octomap/plan_horizon",
                                      "octomap/max_age",
                                      "octomap/stale_wait"};
  ASSERT_EQ(keys.size(), 37u);
  std::set<std::string> in_file;  // (a mapping's keys, at any depth: octomap/ssm/tracking/...)
  std::function<void(const std::string&, const YAML::Node&)> leaves = [&](const std::string& key, const YAML::Node& n) {
    if (!n.IsMap()) {
      in_file.insert(key);
      return;
    }
    for (const auto& sub : n) leaves(key + "/" + sub.first.as<std::string>(), sub.second);
  };
  leaves("octomap", YAML::LoadFile(MOVERL_CONFIG_DIR "/planning_scene.yaml")["octomap"]);
  EXPECT_EQ(in_file, keys) << "a key of the octomap: section that the monitor does not read, or the other way round";
  for (const auto& key : keys) {
    bool b = false;
    int i = 0;
    double d = 0.0;
    std::string s;
    const mps::Tunables& t = mps::panda::shippedTunables();
    EXPECT_TRUE(t.get(key, &b) || t.get(key, &i) || t.get(key, &d) || t.get(key, &s)) << key << " not in the file";
  }
  EditedTunables lockstep({{"octomap/lockstep", true}});
  mps::OctomapMonitorOptions o;
  std::string error;
  ASSERT_TRUE(mps::readOctomapMonitorOptions(lockstep, &o, &error)) << error;
  EXPECT_EQ(lockstep.asked(), keys);
  EXPECT_TRUE(o.lockstep);
  EXPECT_EQ(o.lockstep_lag, shipped<bool>("octomap/lockstep_lag"));

  std::set<std::string> real_time = keys;
  real_time.erase("octomap/lockstep_lag");
  EditedTunables shipped_file;
  ASSERT_TRUE(mps::readOctomapMonitorOptions(shipped_file, &o, &error)) << error;
  EXPECT_EQ(shipped_file.asked(), real_time);
}

// In real time the lag is off whatever octomap/lockstep_lag says, and the key need not be set.
TEST(OctomapMonitorOptions, LockstepLagOnlyInLockstep) {
  EXPECT_EQ(refusal(EditedTunables({{"octomap/lockstep", false}, {"octomap/lockstep_lag", std::monostate()}})), "");
  EXPECT_EQ(refusal(EditedTunables({{"octomap/lockstep", true}, {"octomap/lockstep_lag", std::monostate()}})),
            "edited octomap/lockstep_lag is not set or has the wrong type");
  mps::OctomapMonitorOptions o;
  std::string error;
  ASSERT_TRUE(mps::readOctomapMonitorOptions(
      EditedTunables({{"octomap/lockstep", false}, {"octomap/lockstep_lag", true}}), &o, &error));
  EXPECT_FALSE(o.lockstep_lag);
  ASSERT_TRUE(mps::readOctomapMonitorOptions(
      EditedTunables({{"octomap/lockstep", true}, {"octomap/lockstep_lag", false}}), &o, &error));
  EXPECT_FALSE(o.lockstep_lag);
}

// A missing key, or one of another type, is named (where it lives: Tunables::describe).
TEST(OctomapMonitorOptions, RefusesAMissingKey) {
  EXPECT_EQ(refusal(EditedTunables({{"octomap/camera_wait", std::monostate()}})),
            "edited octomap/camera_wait is not set or has the wrong type");
  EXPECT_EQ(refusal(EditedTunables({{"octomap/resolution", std::monostate()}})),
            "edited octomap/resolution is not set or has the wrong type");
  EXPECT_EQ(refusal(EditedTunables({{"octomap/queue_size", 4.5}})),
            "edited octomap/queue_size is not set or has the wrong type");
  EXPECT_EQ(refusal(EditedTunables({{"octomap/cloud_topic", 1}})),
            "edited octomap/cloud_topic is not set or has the wrong type");
  // The first missing one, in the order they are read.
  EXPECT_EQ(refusal(EditedTunables({{"octomap/integration_threads", std::monostate()},
                                    {"octomap/self_filter_padding", std::monostate()}})),
            "edited octomap/self_filter_padding is not set or has the wrong type");
  // The file itself names its path.
  std::string error;
  const auto file = mps::YamlTunables::fromFile(MOVERL_CONFIG_DIR "/planning_scene.yaml", &error);
  ASSERT_TRUE(file) << error;
  EXPECT_EQ(file->describe("octomap/camera_wait"),
            std::string(MOVERL_CONFIG_DIR "/planning_scene.yaml") + ": key octomap/camera_wait");
}

// The durations and paddings must be finite and >= 0.
TEST(OctomapMonitorOptions, RefusesANegativeOrInfiniteValue) {
  for (const char* name : {"speed_bound", "latency", "plan_horizon", "ssm/intrusion", "ssm/sensor_uncertainty",
                           "stale_wait", "self_filter_padding", "static_filter_padding", "future_tolerance",
                           "camera_wait", "batch_wait", "lockstep_lag_max_margin"}) {
    const std::string key = std::string("octomap/") + name;
    const std::string message = key + " must be finite and >= 0";
    EXPECT_EQ(refusal(EditedTunables({{key, -0.001}})), message);
    EXPECT_EQ(refusal(EditedTunables({{key, kInf}})), message);
    EXPECT_EQ(refusal(EditedTunables({{key, std::nan("")}})), message);
    EXPECT_EQ(refusal(EditedTunables({{key, 0.0}})), "") << key;
  }
}

TEST(OctomapMonitorOptions, RefusesAnUnknownIntegration) {
  EXPECT_EQ(refusal(EditedTunables({{"octomap/integration", std::string("raycast")}})),
            "octomap/integration 'raycast' unknown: one of projective, ray_casting");
  mps::OctomapMonitorOptions o;
  std::string error;
  ASSERT_TRUE(
      mps::readOctomapMonitorOptions(EditedTunables({{"octomap/integration", std::string("ray_casting")}}), &o, &error))
      << error;
  EXPECT_EQ(o.integration, mps::Integration::kRayCasting);
}

TEST(OctomapMonitorOptions, RefusesNoIntegrationThread) {
  EXPECT_EQ(refusal(EditedTunables({{"octomap/integration_threads", 0}})),
            "octomap/integration_threads must be >= 1, not 0");
  EXPECT_EQ(refusal(EditedTunables({{"octomap/integration_threads", -2}})),
            "octomap/integration_threads must be >= 1, not -2");
  EXPECT_EQ(refusal(EditedTunables({{"octomap/integration_threads", 1}})), "");
}

// max_age > 0; .inf: no age limit.
TEST(OctomapMonitorOptions, RefusesNoMaxAge) {
  const std::string message = "octomap/max_age must be > 0 (.inf: no limit)";
  EXPECT_EQ(refusal(EditedTunables({{"octomap/max_age", 0.0}})), message);
  EXPECT_EQ(refusal(EditedTunables({{"octomap/max_age", -1.0}})), message);
  EXPECT_EQ(refusal(EditedTunables({{"octomap/max_age", std::nan("")}})), message);
  EXPECT_EQ(refusal(EditedTunables({{"octomap/max_age", kInf}})), "");
}

// The checks come in a fixed order: the margin's keys as they are read, then the ranges of the durations, the
// integration, its threads.
TEST(OctomapMonitorOptions, NamesTheFirstBadValue) {
  EXPECT_EQ(refusal(EditedTunables({{"octomap/max_age", 0.0},
                                    {"octomap/integration_threads", 0},
                                    {"octomap/integration", std::string("x")},
                                    {"octomap/batch_wait", -1.0}})),
            "octomap/max_age must be > 0 (.inf: no limit)");
  EXPECT_EQ(refusal(EditedTunables({{"octomap/integration_threads", 0},
                                    {"octomap/integration", std::string("x")},
                                    {"octomap/batch_wait", -1.0}})),
            "octomap/batch_wait must be finite and >= 0");
  EXPECT_EQ(refusal(EditedTunables({{"octomap/integration_threads", 0}, {"octomap/integration", std::string("x")}})),
            "octomap/integration 'x' unknown: one of projective, ray_casting");
}

// octomap/safety: separation or ssm; another name is refused naming both.
TEST(OctomapMonitorOptions, RefusesAnUnknownSafety) {
  EXPECT_EQ(refusal(EditedTunables({{"octomap/safety", std::string("iso")}})),
            "octomap/safety: unknown safety definition 'iso' (valid: separation, ssm)");
  mps::OctomapMonitorOptions o;
  std::string error;
  ASSERT_TRUE(mps::readOctomapMonitorOptions(EditedTunables({{"octomap/safety", std::string("ssm")}}), &o, &error))
      << error;
  EXPECT_EQ(o.margin.safety, mps::Safety::kSsm);
  EXPECT_EQ(o.margin.iso.intrusion, shipped<double>("octomap/ssm/intrusion"));
  EXPECT_EQ(o.margin.uncertainty, shipped<double>("octomap/ssm/sensor_uncertainty"));
}

// With a YAML file as its source (a tool's, a test's): a bad value in the file is refused as from the parameters.
TEST(OctomapMonitorOptions, RefusesABadValueInAFile) {
  const std::string path = ::testing::TempDir() + "octomap_monitor_options_test.yaml";
  std::string text = mps::panda::readFile(MOVERL_CONFIG_DIR "/planning_scene.yaml");
  const std::string line = "\n  integration_threads: ";
  const auto at = text.find(line);
  ASSERT_NE(at, std::string::npos);
  const auto end = text.find('\n', at + 1);
  text.replace(at, end - at, line + "0");
  {
    std::ofstream out(path);
    out << text;
  }
  std::string error;
  const auto file = mps::YamlTunables::fromFile(path, &error);
  ASSERT_TRUE(file) << error;
  EXPECT_EQ(refusal(*file), "octomap/integration_threads must be >= 1, not 0");
  std::remove(path.c_str());
}

int main(int argc, char** argv) {
  ::testing::InitGoogleTest(&argc, argv);
  return RUN_ALL_TESTS();
}

// octomap/ssm/tracking: ssm's only; the parts' list parsed, a bad entry named.
TEST(OctomapMonitorOptions, TrackedPeopleAreSsmsAndTheirPartsParsed) {
  EXPECT_EQ(refusal(EditedTunables({{"octomap/ssm/tracking/use", true}})),
            "octomap/ssm/tracking/use: the tracked people are ssm's (octomap/safety is separation)");
  mps::OctomapMonitorOptions o;
  std::string error;
  ASSERT_TRUE(mps::readOctomapMonitorOptions(
      EditedTunables({{"octomap/safety", std::string("ssm")}, {"octomap/ssm/tracking/use", true}}), &o, &error))
      << error;
  EXPECT_TRUE(o.track_people);
  EXPECT_EQ(o.tracking.motion.max_speed, shipped<double>("octomap/ssm/tracking/max_speed"));
  EXPECT_EQ(o.tracking.motion.max_acceleration, 0.0) << "REP 155 reports no velocity";
  ASSERT_FALSE(o.part_radii.empty());
  EXPECT_EQ(refusal(EditedTunables({{"octomap/ssm/tracking/parts", std::string("head 0.1, r_wrist")}})),
            "octomap/ssm/tracking/parts: ' r_wrist': expected \"<frame> <radius>\" (a frame of letters, digits and _, "
            "once; a radius >= 0 m)");
  EXPECT_NE(refusal(EditedTunables({{"octomap/ssm/tracking/parts", std::string("head 0.1, head 0.2")}})), "");
  EXPECT_NE(refusal(EditedTunables({{"octomap/ssm/tracking/parts", std::string("head -0.1")}})), "");
  EXPECT_NE(refusal(EditedTunables({{"octomap/ssm/tracking/max_speed", 0.0}})), "");
  ASSERT_TRUE(
      mps::readOctomapMonitorOptions(EditedTunables({{"octomap/ssm/tracking/parts", std::string("")}}), &o, &error))
      << error;
  EXPECT_TRUE(o.part_radii.empty());
}
