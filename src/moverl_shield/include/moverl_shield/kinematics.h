// End-effector forward kinematics and joint limits read from a URDF, with KDL. ROS-free.
#pragma once

#include <array>
#include <map>
#include <memory>
#include <string>
#include <vector>

#include <kdl/chain.hpp>
#include <kdl/chainfksolverpos_recursive.hpp>

namespace moverl_shield {

/// \brief Position (x, y, z) and orientation quaternion (x, y, z, w) of a link in the base frame.
struct Pose {
  std::array<double, 3> position{};
  std::array<double, 4> orientation{0, 0, 0, 1};
};

/// \brief Forward kinematics of the base -> end-effector chain of any URDF robot.
///
/// Controlled joints are given by name in the order used by every MoveRL interface; other movable joints
/// of the chain are held at fixed positions (default 0).
class ChainKinematics {
 public:
  /// \throws std::runtime_error when the URDF does not parse, a link or a controlled joint is missing.
  ChainKinematics(const std::string& urdf_xml, const std::string& base_link, const std::string& ee_link,
                  const std::vector<std::string>& joints, const std::map<std::string, double>& fixed_positions = {});

  /// \brief Pose of the end-effector link for controlled joint positions q (size must match).
  Pose endEffectorPose(const std::vector<double>& q) const;

  /// \brief Velocity limits (rad/s or m/s) of the controlled joints, from the URDF.
  const std::vector<double>& velocityLimits() const { return velocity_limits_; }
  const std::vector<double>& lowerLimits() const { return lower_; }
  const std::vector<double>& upperLimits() const { return upper_; }

 private:
  KDL::Chain chain_;
  std::unique_ptr<KDL::ChainFkSolverPos_recursive> solver_;
  std::vector<int> chain_to_controlled_;  // per chain joint: index in q, or -1 when held fixed
  std::vector<double> chain_fixed_;       // per chain joint: fixed position when not controlled
  std::vector<double> velocity_limits_, lower_, upper_;
  size_t num_controlled_ = 0;
};

}  // namespace moverl_shield
