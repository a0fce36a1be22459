#include "scene_access.h"

#include <stdexcept>

#include <moverl_msgs/GetWorld.h>
#include <moverl_msgs/PlanPath.h>
#include <moverl_msgs/ValidateMotion.h>

#include "moverl_planning_scene/ros_param.h"
#include "moverl_planning_scene/scene_server.h"
#include "moverl_tcpros/client.h"

namespace moverl_shield {
namespace mps = moverl_planning_scene;
namespace {

class InProcessScene : public Scene {
 public:
  InProcessScene(ros::NodeHandle nh, const std::string& ns) : server_(nh, ros::NodeHandle(nh, ns)), ns_(ns) {
    std::string error;
    if (!server_.init(&error)) throw std::runtime_error("planning scene (in process, " + ns + "): " + error);
  }
  std::string name() const override { return ns_ + " (in process)"; }
  CallEnd validate(const mps::MotionRequest& request, mps::MotionCheck* answer, double) override {
    server_.validate(request, answer);
    return CallEnd::kAnswered;
  }
  CallEnd plan(const std::vector<double>& start, const std::vector<double>& goal, double time_limit,
               mps::PlanResult* answer, double) override {
    server_.plan(start, goal, "", time_limit, answer);
    return CallEnd::kAnswered;
  }
  CallEnd motionEpoch(Nanos* epoch, double) override {
    *epoch = static_cast<Nanos>(server_.motionEpoch().toNSec());
    return CallEnd::kAnswered;
  }
  bool facts(SceneFacts* f, std::string*) override {
    f->joint_radius_bounds = server_.jointRadiusBounds();
    f->padding = server_.checkerOptions().padding;
    f->path_resolution = server_.checkerOptions().path_resolution;
    f->planning_time = server_.planningTime();
    return true;
  }
  const mps::RobotModel& model() const override { return server_.model(); }

 private:
  mps::SceneServer server_;
  std::string ns_;
};

class ServiceScene : public Scene {
 public:
  ServiceScene(ros::NodeHandle nh, const std::string& ns)
      : scene_nh_(nh, ns),
        validate_(scene_nh_.resolveName("validate_motion")),
        plan_(scene_nh_.resolveName("plan")),
        world_(scene_nh_.resolveName("get_world")) {
    // The same model the scene builds, from the same parameters (the robot config and the scene's urdf_dir).
    std::string urdf, error;
    mps::RobotModelOptions o = mps::robotOptions(nh, &urdf);
    o.mesh_base_dir = mps::requiredParam<std::string>(scene_nh_, "urdf_dir", "load config/planning_scene.yaml");
    model_ = mps::RobotModel::fromUrdf(urdf, o, &error);
    if (!model_) throw std::runtime_error("cannot build the robot model: " + error);
  }
  std::string name() const override { return validate_.name(); }

  CallEnd validate(const mps::MotionRequest& q, mps::MotionCheck* a, double timeout) override {
    moverl_msgs::ValidateMotion& vm = vm_;  // reused: no allocation per step once its vectors have grown
    vm.request.start = q.start;
    vm.request.goal = q.goal;
    vm.request.measured_start = q.measured_start;
    vm.request.plan_on_path_collision = q.plan_on_path_collision;
    vm.request.find_last_free = q.find_last_free;
    vm.request.start_time = q.start_time;
    vm.request.duration = q.duration;
    vm.request.stamp = q.stamp > 0.0 ? ros::Time(q.stamp) : ros::Time();
    vm.request.retreat_reach = q.retreat_reach;
    vm.request.time_budget = q.time_budget;
    const CallEnd end = validate_.call(vm, timeout);
    if (end != CallEnd::kAnswered) return end;
    const auto& r = vm.response;
    a->outcome = static_cast<mps::MotionOutcome>(r.outcome);
    a->replanned = r.replanned;
    a->path.resize(r.path.points.size());
    for (std::size_t k = 0; k < r.path.points.size(); ++k) a->path[k] = r.path.points[k].positions;
    a->pairs.resize(r.pairs.size());
    for (std::size_t k = 0; k < r.pairs.size(); ++k) {
      a->pairs[k].a = r.pairs[k].a;
      a->pairs[k].b = r.pairs[k].b;
      a->pairs[k].depth = r.pairs[k].depth;
    }
    a->message = r.message;
    a->state_check_time = r.state_check_time;
    a->path_check_time = r.path_check_time;
    a->planning_time = r.planning_time;
    a->last_free_fraction = r.last_free_fraction;
    a->last_free_state = r.last_free_state;
    a->moving_obstacles = r.moving_obstacles;
    a->map_age = r.map_age;
    a->sensed_margin = r.sensed_margin;
    a->plan_horizon = r.plan_horizon;
    a->threatened = r.threatened;
    a->clearance = r.clearance;
    a->retreat_state = r.retreat_state;
    a->retreat_clearance = r.retreat_clearance;
    return end;
  }
  CallEnd plan(const std::vector<double>& start, const std::vector<double>& goal, double time_limit,
               mps::PlanResult* answer, double timeout) override {
    moverl_msgs::PlanPath plan;
    plan.request.start = start;
    plan.request.goal = goal;
    plan.request.time_limit = time_limit;
    const CallEnd end = plan_.call(plan, timeout);
    if (end != CallEnd::kAnswered) return end;
    answer->status = static_cast<mps::PlanStatus>(plan.response.outcome);
    answer->waypoints.clear();
    for (const auto& p : plan.response.path.points) answer->waypoints.push_back(p.positions);
    answer->planning_time = plan.response.planning_time;
    answer->path_length = plan.response.path_length;
    answer->message = plan.response.message;
    return end;
  }
  CallEnd motionEpoch(Nanos* epoch, double timeout) override {
    moverl_msgs::GetWorld gw;
    const CallEnd end = world_.call(gw, timeout);
    if (end == CallEnd::kAnswered) *epoch = static_cast<Nanos>(gw.response.world.motion_epoch.toNSec());
    return end;
  }
  bool facts(SceneFacts* f, std::string* error) override {
    // Published by the scene server once it is up (joint_radius_bounds) or loaded with its YAML (the rest).
    if (!scene_nh_.getParam("joint_radius_bounds", f->joint_radius_bounds) ||
        !scene_nh_.getParam("padding", f->padding) || !scene_nh_.getParam("path_resolution", f->path_resolution) ||
        !scene_nh_.getParam("planning_time", f->planning_time)) {
      *error =
          "the planning scene's parameters joint_radius_bounds, padding, path_resolution and planning_time are "
          "not set in " +
          scene_nh_.getNamespace() + " (is the scene up?)";
      return false;
    }
    return true;
  }
  const mps::RobotModel& model() const override { return *model_; }

 private:
  ros::NodeHandle scene_nh_;
  moverl_tcpros::DirectServiceClient<moverl_msgs::ValidateMotion> validate_;
  moverl_tcpros::DirectServiceClient<moverl_msgs::PlanPath> plan_;
  moverl_tcpros::DirectServiceClient<moverl_msgs::GetWorld> world_;
  moverl_msgs::ValidateMotion vm_;
  std::unique_ptr<mps::RobotModel> model_;
};

}  // namespace

std::unique_ptr<Scene> createScene(const std::string& mode, ros::NodeHandle nh, const std::string& ns) {
  if (mode == "in_process") return std::make_unique<InProcessScene>(nh, ns);
  if (mode == "service") return std::make_unique<ServiceScene>(nh, ns);
  throw std::runtime_error("unknown ~scene '" + mode + "' (expected in_process or service)");
}

}  // namespace moverl_shield
