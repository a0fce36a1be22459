/**
 * \file scene_benchmark.cpp
 * \brief Timing of the hot-path queries on the Panda (pybullet_data URDF, table + thin wall worlds), with the repo's
 *        config/robots/panda.yaml and config/planning_scene.yaml.
 *        Usage: scene_benchmark [panda.urdf|""] [acm_samples] [planner] [planning_time]
 */
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <random>

#include <fstream>
#include <sstream>

#include "moverl_planning_scene/planning_scene.h"
#include "moverl_planning_scene/tunables.h"

namespace mps = moverl_planning_scene;
using Clock = std::chrono::steady_clock;

namespace {

constexpr int kStateSamples = 5000;
constexpr int kPathSamples = 2000;
constexpr int kPlanSamples = 30;
constexpr double kStepRad = 0.1;

/// An axis-aligned box obstacle centred at (x, y, z).
mps::WorldObject box(const std::string& id, double sx, double sy, double sz, double x, double y, double z) {
  mps::WorldObject o;
  o.id = id;
  o.type = mps::ShapeType::kBox;
  o.dimensions = {sx, sy, sz};
  o.pose.translation() = Eigen::Vector3d(x, y, z);
  return o;
}

void report(const char* what, std::vector<double> t) {
  if (t.empty()) return;
  std::sort(t.begin(), t.end());
  auto pct = [&](double p) { return t[std::min(t.size() - 1, static_cast<std::size_t>(p * t.size()))]; };
  std::printf("%-44s n=%5zu  p50 %9.1f us  p99 %9.1f us  max %9.1f us\n", what, t.size(), pct(0.5) * 1e6,
              pct(0.99) * 1e6, t.back() * 1e6);
}

}  // namespace

int main(int argc, char** argv) {
  const std::string urdf_file = argc > 1 && argv[1][0] != '\0' ? argv[1] : MOVERL_PANDA_URDF;
  if (urdf_file.empty()) {
    std::fprintf(stderr, "usage: scene_benchmark panda.urdf [acm_samples] (pybullet_data not found at build time)\n");
    return 1;
  }
  mps::PlanningSceneOptions o;
  std::string error, uri;
  const auto tunables = mps::YamlTunables::fromFile(MOVERL_CONFIG_DIR "/planning_scene.yaml", &error);
  if (!tunables || !mps::loadRobotConfig(MOVERL_CONFIG_DIR "/robots/panda.yaml", &o.robot, &uri, &error)) {
    std::fprintf(stderr, "error: %s\n", error.c_str());
    return 1;
  }
  mps::readSceneTunables(*tunables, &o);
  o.robot.mesh_base_dir = urdf_file.substr(0, urdf_file.rfind('/'));
  if (argc > 2) o.checker.acm_samples = std::atoi(argv[2]);
  if (argc > 3) o.planner.planner = argv[3];
  if (argc > 4) o.planner.planning_time = std::atof(argv[4]);
  std::ifstream urdf_in(urdf_file);
  std::stringstream urdf;
  urdf << urdf_in.rdbuf();
  const auto t0 = Clock::now();
  auto scene = mps::PlanningScene::create(urdf.str(), o, &error);
  if (!scene) {
    std::fprintf(stderr, "error: %s\n", error.c_str());
    return 1;
  }
  const auto& acm = scene->checker().acmStats();
  std::printf(
      "scene built in %.3f s; ACM (%d samples, no cache) %.3f s: adjacent %d rigid %d always %d never %d "
      "checked %d; never pairs: closest approach by search %.1f mm, %d found touching\n",
      std::chrono::duration<double>(Clock::now() - t0).count(), o.checker.acm_samples, acm.seconds, acm.adjacent,
      acm.rigid, acm.always, acm.never, acm.enabled, acm.never_min_distance * 1e3, acm.never_refuted);
  std::printf("joint radius bounds r_i:");
  for (std::size_t i = 0; i < scene->model().dof(); ++i) std::printf(" %.3f", scene->checker().jointRadiusBound(i));
  std::printf("\n");

  const std::vector<double> home = {0.0, -0.785, 0.0, -2.356, 0.0, 1.571, 0.785};
  mps::WorldObject table;  // worlds/table.yaml's table top
  if (!mps::loadWorldBox(MOVERL_CONFIG_DIR "/../worlds/table.yaml", "table", &table, &error)) {
    std::fprintf(stderr, "error: %s\n", error.c_str());
    return 1;
  }
  scene->setWorld({table}, &error);
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> jitter(-0.5, 0.5);
  auto near_home = [&] {
    std::vector<double> q = home;
    for (std::size_t i = 0; i < q.size(); ++i) {
      q[i] = std::min(std::max(q[i] + jitter(rng), scene->model().lowerLimits()[i]), scene->model().upperLimits()[i]);
    }
    return q;
  };
  std::vector<double> times;
  mps::StateCheck sc;
  int free_states = 0;
  for (int k = 0; k < kStateSamples; ++k) {
    const auto q = near_home();
    const auto t = Clock::now();
    scene->checkState(q, &sc);
    times.push_back(std::chrono::duration<double>(Clock::now() - t).count());
    free_states += sc.outcome == mps::CheckOutcome::kValid;
  }
  std::printf("(%d of %d states near home free)\n", free_states, kStateSamples);
  report("checkState (table world, near home)", times);

  // Path checks, with checkPath's pair culling (the default) and without (every shape pair at every state),
  // interleaved on the same moves; their answers must agree.
  mps::PlanningSceneOptions uncut = o;
  uncut.checker.cull_path_pairs = false;
  auto all_pairs = mps::PlanningScene::create(urdf.str(), uncut, &error);
  if (!all_pairs) {
    std::fprintf(stderr, "error: %s\n", error.c_str());
    return 1;
  }
  all_pairs->setWorld({table}, &error);
  // validateMotion on a scene of its own: a scene reuses the culling of the segment it checked last.
  auto motions = mps::PlanningScene::create(urdf.str(), o, &error);
  if (!motions) {
    std::fprintf(stderr, "error: %s\n", error.c_str());
    return 1;
  }
  motions->setWorld({table}, &error);
  std::uniform_int_distribution<int> sign(0, 1);
  // Moves from random states near home, and a walk as an env steps (each move starts where the last one ended, back
  // near home every 50 moves or after a colliding one): the culling's memory of the last move is of use there.
  struct Moves {
    double step;
    bool walk;
  };
  for (const Moves moves : {Moves{kStepRad, false}, Moves{0.5 * kStepRad, false}, Moves{0.5 * kStepRad, true}}) {
    const double step = moves.step;
    std::vector<double> culled_times, all_times, vtimes, ptimes, vall;
    mps::MotionCheck mc;
    mps::PathCheck pc, pa;
    std::size_t states = 0, differ = 0;
    std::vector<double> last;  // the walk's end so far (empty: start near home)
    for (int k = 0; k < kPathSamples; ++k) {
      const auto q0 = moves.walk && !last.empty() && k % 50 != 0 ? last : near_home();
      last.clear();
      auto q1 = q0;
      for (std::size_t i = 0; i < q1.size(); ++i) {
        q1[i] = std::min(std::max(q0[i] + (sign(rng) ? step : -step), scene->model().lowerLimits()[i]),
                         scene->model().upperLimits()[i]);
      }
      if (k % 2 == 0) {
        scene->checkPath(q0, q1, &pc);
        all_pairs->checkPath(q0, q1, &pa);
      } else {
        all_pairs->checkPath(q0, q1, &pa);
        scene->checkPath(q0, q1, &pc);
      }
      differ += pc.outcome != pa.outcome || pc.checked_states != pa.checked_states;
      if (pc.outcome != mps::CheckOutcome::kValid) continue;
      last = q1;
      culled_times.push_back(pc.check_time);
      all_times.push_back(pa.check_time);
      states += pc.checked_states;
      auto t = Clock::now();
      motions->validateMotion(q0, q1, false, &mc);
      vtimes.push_back(std::chrono::duration<double>(Clock::now() - t).count());
      ptimes.push_back(mc.path_check_time);
      t = Clock::now();
      all_pairs->validateMotion(q0, q1, false, &mc);
      vall.push_back(std::chrono::duration<double>(Clock::now() - t).count());
    }
    std::printf(
        "(%.2f rad per joint moves%s: %.1f checked states on average; answers that differ without culling: %zu)\n",
        step, moves.walk ? ", a walk" : "",
        culled_times.empty() ? 0.0 : static_cast<double>(states) / culled_times.size(), differ);
    char what[64];
    std::snprintf(what, sizeof what, "checkPath, %.2f rad/joint %s (free)", step, moves.walk ? "walk" : "move");
    report(what, culled_times);
    std::snprintf(what, sizeof what, "  the same, every pair at every state");
    report(what, all_times);
    report("validateMotion path_check_time (same moves)", ptimes);
    report("validateMotion total (same moves)", vtimes);
    report("  the same, every pair at every state", vall);
  }

  // Planning around a 5 mm wall (OMPL's random numbers come from one global stream: two scenes planning in turn get
  // different samples, so this is not a comparison of the two).
  scene->setWorld({table, box("wall", 0.4, 0.005, 0.5, 0.45, 0.0, 0.45)}, &error);
  std::vector<double> a = home, b = home;
  a[0] = -0.8;
  b[0] = 0.8;
  times.clear();
  int replanned = 0;
  mps::MotionCheck mc;
  for (int k = 0; k < kPlanSamples; ++k) {
    scene->validateMotion(a, b, true, &mc);
    if (mc.outcome != mps::MotionOutcome::kPathCollision) {
      std::printf("unexpected outcome %d: %s\n", static_cast<int>(mc.outcome), mc.message.c_str());
      break;
    }
    times.push_back(mc.planning_time);
    replanned += mc.replanned;
  }
  std::printf("(wall: %d of %d replanned with %s, time limit %.2f s)\n", replanned, kPlanSamples,
              o.planner.planner.c_str(), o.planner.planning_time);
  report("validateMotion planning_time (wall)", times);
  return 0;
}
