#include "scene_access.h"

#include <stdexcept>

#include "moverl_planning_scene/ros_param.h"
#include "moverl_planning_scene/scene_server.h"

namespace moverl_shield {
namespace mps = moverl_planning_scene;
namespace {

class InProcessScene : public SceneAccess {
 public:
  InProcessScene(ros::NodeHandle nh, const std::string& ns) : server_(nh, ros::NodeHandle(nh, ns)), ns_(ns) {
    std::string error;
    if (!server_.init(&error)) throw std::runtime_error("planning scene (in process, " + ns + "): " + error);
  }
  std::string name() const override { return ns_ + " (in process)"; }
  CallEnd validate(moverl_msgs::ValidateMotion& vm, double) override {
    server_.validateMotion(vm.request, vm.response);
    return CallEnd::kAnswered;
  }
  CallEnd plan(moverl_msgs::PlanPath& plan, double) override {
    server_.plan(plan.request, plan.response);
    return CallEnd::kAnswered;
  }
  CallEnd world(moverl_msgs::GetWorld& world, double) override {
    world.response.world = server_.world();
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

class ServiceScene : public SceneAccess {
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
  CallEnd validate(moverl_msgs::ValidateMotion& vm, double timeout) override { return validate_.call(vm, timeout); }
  CallEnd plan(moverl_msgs::PlanPath& plan, double timeout) override { return plan_.call(plan, timeout); }
  CallEnd world(moverl_msgs::GetWorld& world, double timeout) override { return world_.call(world, timeout); }
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
  DirectServiceClient<moverl_msgs::ValidateMotion> validate_;
  DirectServiceClient<moverl_msgs::PlanPath> plan_;
  DirectServiceClient<moverl_msgs::GetWorld> world_;
  std::unique_ptr<mps::RobotModel> model_;
};

}  // namespace

std::unique_ptr<SceneAccess> SceneAccess::create(const std::string& mode, ros::NodeHandle nh, const std::string& ns) {
  if (mode == "in_process") return std::make_unique<InProcessScene>(nh, ns);
  if (mode == "service") return std::make_unique<ServiceScene>(nh, ns);
  throw std::runtime_error("unknown ~scene '" + mode + "' (expected in_process or service)");
}

}  // namespace moverl_shield
