/**
 * \file robot_model.h
 * \brief Kinematic model of one robot built from URDF text (ROS-free).
 */
#pragma once

#include <Eigen/Geometry>
#include <functional>
#include <map>
#include <memory>
#include <string>
#include <vector>

namespace KDL {
class Tree;
}

namespace moverl_planning_scene {

/// \brief Kinds of collision shapes found in a URDF <collision> element or a world object.
enum class ShapeType { kBox, kSphere, kCylinder, kCone, kMesh };

/// \brief One <collision> element of a link, expressed in the link frame.
struct CollisionShapeSpec {
  ShapeType type = ShapeType::kBox;
  /// Box: size x,y,z. Sphere: (radius, 0, 0). Cylinder: (radius, length, 0).
  Eigen::Vector3d dims = Eigen::Vector3d::Zero();
  std::string mesh_path;  ///< resolved absolute file name (meshes only)
  Eigen::Vector3d scale = Eigen::Vector3d::Ones();
  Eigen::Isometry3d origin = Eigen::Isometry3d::Identity();  ///< shape frame in the link frame
};

/// \brief Options describing which joints are controlled; everything else comes from the URDF.
struct RobotModelOptions {
  std::vector<std::string> joint_names;                 ///< controlled joints, in service order
  std::map<std::string, double> fixed_joint_positions;  ///< other movable joints (default 0)
  std::string base_link;                                ///< empty: URDF root
  std::string ee_link;                                  ///< empty: last link of the last controlled joint
  /// Folder used to resolve relative mesh names and package://<rest> as <mesh_base_dir>/<rest>.
  std::string mesh_base_dir;
  /// Optional resolver tried first for package:// URLs (the node plugs ROS package lookup here).
  std::function<std::string(const std::string&)> package_resolver;
};

/// \brief Robot kinematics: joints, limits, link transforms, collision shape descriptions.
///
/// Non-controlled movable joints are held at their fixed positions (mimic tags are ignored).
/// Continuous joints get limits [-2 pi, 2 pi]. Floating/planar joints cannot be controlled and are held at identity.
class RobotModel {
 public:
  /// Limits given to continuous joints (rad).
  static constexpr double kContinuousJointLimit = 2.0 * 3.14159265358979323846;

  /// \brief Parse URDF text; returns nullptr and fills *error (naming the problem) on failure.
  static std::unique_ptr<RobotModel> fromUrdf(const std::string& urdf_xml, const RobotModelOptions& options,
                                              std::string* error);
  ~RobotModel();

  /// \brief Number of controlled joints.
  std::size_t dof() const { return joint_names_.size(); }
  /// \brief Controlled joint names in service order.
  const std::vector<std::string>& jointNames() const { return joint_names_; }
  /// \brief Lower position limits (rad or m) of the controlled joints.
  const std::vector<double>& lowerLimits() const { return lower_; }
  /// \brief Upper position limits of the controlled joints.
  const std::vector<double>& upperLimits() const { return upper_; }
  /// \brief Velocity limits from the URDF (0 when absent).
  const std::vector<double>& velocityLimits() const { return velocity_; }
  /// \brief True when controlled joint i is prismatic.
  bool isPrismatic(std::size_t i) const { return joint_is_prismatic_[i]; }

  /// \brief All links, parents before children.
  const std::vector<std::string>& linkNames() const { return link_names_; }
  /// \brief Index of a link in linkNames(), -1 when unknown.
  int linkIndex(const std::string& name) const;
  /// \brief Parent link index (-1 for the root).
  int parentLink(int link) const { return link_parent_[link]; }
  /// \brief True when no controlled joint lies between the link and the root (it never moves).
  bool isStatic(int link) const { return link_static_[link]; }
  /// \brief Index of the nearest controlled joint above the link (-1 when static).
  int drivingJoint(int link) const { return link_driving_joint_[link]; }
  /// \brief True when the controlled joint moves the link (the joint is among its ancestors).
  bool jointMovesLink(std::size_t joint, int link) const;
  /// \brief Upper bound of the distance between controlled joint i's origin and the origin of a link it moves,
  ///        valid for every configuration (sum of joint-origin offsets plus prismatic travel). -1 if not moved.
  double chainOffsetBound(std::size_t joint, int link) const { return offset_bound_[joint][link]; }
  /// \brief Collision shapes of a link (may be empty).
  const std::vector<CollisionShapeSpec>& collisionShapes(int link) const { return shapes_[link]; }

  const std::string& baseLink() const { return base_link_; }
  const std::string& eeLink() const { return ee_link_; }
  const std::string& urdfText() const { return urdf_; }
  /// \brief Fixed positions of non-controlled movable joints, as used (for cache keys).
  const std::map<std::string, double>& fixedPositions() const { return fixed_used_; }

  /// \brief Poses of all links in the base frame for configuration q (dof() values). out is resized once.
  void computeLinkTransforms(const double* q, std::vector<Eigen::Isometry3d>* out) const;
  /// \brief Pose of one link in the base frame computed independently with KDL (TreeFkSolverPos_recursive).
  bool linkPoseKdl(const std::vector<double>& q, const std::string& link, Eigen::Isometry3d* pose) const;

 private:
  RobotModel();
  struct Joint {
    int type = 0;  // 0 fixed, 1 revolute, 2 prismatic
    Eigen::Isometry3d origin = Eigen::Isometry3d::Identity();
    Eigen::Vector3d axis = Eigen::Vector3d::UnitZ();
    int controlled = -1;  // index in joint_names_ or -1
    double fixed_value = 0.0;
  };

  std::string urdf_;
  std::vector<std::string> joint_names_;
  std::vector<double> lower_, upper_, velocity_;
  std::vector<bool> joint_is_prismatic_;
  std::vector<std::string> link_names_;
  std::map<std::string, int> link_index_;
  std::vector<int> link_parent_;
  std::vector<Joint> link_joint_;  // joint from parent to link (identity fixed for the root)
  std::vector<bool> link_static_;
  std::vector<int> link_driving_joint_;
  std::vector<int> joint_child_link_;  // child link of each controlled joint
  std::vector<std::vector<double>> offset_bound_;
  std::vector<std::vector<CollisionShapeSpec>> shapes_;
  std::string base_link_, ee_link_;
  int base_index_ = 0;
  Eigen::Isometry3d root_to_base_inv_ = Eigen::Isometry3d::Identity();
  std::map<std::string, double> fixed_used_;
  std::unique_ptr<KDL::Tree> kdl_tree_;
  std::map<std::string, int> kdl_joint_index_;  // every KDL movable joint -> q_nr
};

}  // namespace moverl_planning_scene
