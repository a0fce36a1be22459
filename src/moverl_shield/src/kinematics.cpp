#include "moverl_shield/kinematics.h"

#include <kdl/tree.hpp>
#include <kdl_parser/kdl_parser.hpp>
#include <stdexcept>
#include <urdf_model/model.h>
#include <urdf_parser/urdf_parser.h>

namespace moverl_shield {

ChainKinematics::ChainKinematics(const std::string& urdf_xml, const std::string& base_link,
                                 const std::string& ee_link, const std::vector<std::string>& joints,
                                 const std::map<std::string, double>& fixed_positions)
    : num_controlled_(joints.size()) {
  urdf::ModelInterfaceSharedPtr model = urdf::parseURDF(urdf_xml);
  if (!model) throw std::runtime_error("the robot description is not a valid URDF");
  KDL::Tree tree;
  if (!kdl_parser::treeFromUrdfModel(*model, tree)) throw std::runtime_error("cannot build a KDL tree from the URDF");
  if (!tree.getChain(base_link, ee_link, chain_)) {
    throw std::runtime_error("no kinematic chain from link '" + base_link + "' to link '" + ee_link + "'");
  }
  for (const auto& name : joints) {
    auto joint = model->getJoint(name);
    if (!joint) throw std::runtime_error("controlled joint '" + name + "' is not in the URDF");
    if (!joint->limits) throw std::runtime_error("controlled joint '" + name + "' has no <limit> in the URDF");
    velocity_limits_.push_back(joint->limits->velocity);
    lower_.push_back(joint->limits->lower);
    upper_.push_back(joint->limits->upper);
  }
  std::vector<bool> used(joints.size(), false);
  for (const auto& segment : chain_.segments) {
    const KDL::Joint& j = segment.getJoint();
    if (j.getType() == KDL::Joint::None) continue;
    int index = -1;
    for (size_t i = 0; i < joints.size(); ++i) {
      if (joints[i] == j.getName()) index = static_cast<int>(i);
    }
    if (index >= 0) used[index] = true;
    chain_to_controlled_.push_back(index);
    auto fixed = fixed_positions.find(j.getName());
    chain_fixed_.push_back(fixed == fixed_positions.end() ? 0.0 : fixed->second);
  }
  solver_ = std::make_unique<KDL::ChainFkSolverPos_recursive>(chain_);
  (void)used;  // controlled joints off the ee chain (e.g. a gripper) are legal: they do not move the ee.
}

Pose ChainKinematics::endEffectorPose(const std::vector<double>& q) const {
  if (q.size() != num_controlled_) throw std::invalid_argument("wrong number of joint positions");
  KDL::JntArray jq(chain_.getNrOfJoints());
  for (size_t k = 0; k < chain_to_controlled_.size(); ++k) {
    const int i = chain_to_controlled_[k];
    jq(k) = i >= 0 ? q[i] : chain_fixed_[k];
  }
  KDL::Frame frame;
  if (solver_->JntToCart(jq, frame) < 0) throw std::runtime_error("KDL forward kinematics failed");
  Pose pose;
  for (int i = 0; i < 3; ++i) pose.position[i] = frame.p(i);
  frame.M.GetQuaternion(pose.orientation[0], pose.orientation[1], pose.orientation[2], pose.orientation[3]);
  return pose;
}

}  // namespace moverl_shield
