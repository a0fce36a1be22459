#include "moverl_planning_scene/robot_model.h"

#include <urdf_parser/urdf_parser.h>
#include <kdl/jntarray.hpp>
#include <kdl/tree.hpp>
#include <kdl/treefksolverpos_recursive.hpp>
#include <kdl_parser/kdl_parser.hpp>

#include <algorithm>
#include <cmath>
#include <deque>
#include <fstream>

namespace moverl_planning_scene {
namespace {

constexpr char kFilePrefix[] = "file://";
constexpr char kPackagePrefix[] = "package://";

Eigen::Isometry3d toEigen(const urdf::Pose& p) {
  double x, y, z, w;
  p.rotation.getQuaternion(x, y, z, w);
  Eigen::Isometry3d t = Eigen::Isometry3d::Identity();
  t.linear() = Eigen::Quaterniond(w, x, y, z).normalized().toRotationMatrix();
  t.translation() = Eigen::Vector3d(p.position.x, p.position.y, p.position.z);
  return t;
}

bool startsWith(const std::string& s, const char* prefix) { return s.rfind(prefix, 0) == 0; }

bool fileExists(const std::string& path) { return std::ifstream(path).good(); }

std::string joinPath(const std::string& dir, const std::string& rest) {
  if (dir.empty()) return rest;
  return dir.back() == '/' ? dir + rest : dir + "/" + rest;
}

/// Resolves a URDF mesh filename into a readable file, or "" with *error set.
std::string resolveMesh(const std::string& name, const RobotModelOptions& options, std::string* error) {
  std::vector<std::string> candidates;
  if (startsWith(name, kFilePrefix)) {
    candidates.push_back(name.substr(sizeof(kFilePrefix) - 1));
  } else if (startsWith(name, kPackagePrefix)) {
    const std::string rest = name.substr(sizeof(kPackagePrefix) - 1);
    if (options.package_resolver) {
      const std::string resolved = options.package_resolver(name);
      if (!resolved.empty()) candidates.push_back(resolved);
    }
    if (!options.mesh_base_dir.empty()) candidates.push_back(joinPath(options.mesh_base_dir, rest));
  } else if (!name.empty() && name[0] == '/') {
    candidates.push_back(name);
  } else {
    candidates.push_back(joinPath(options.mesh_base_dir, name));
  }
  for (const auto& c : candidates) {
    if (fileExists(c)) return c;
  }
  *error = "cannot resolve mesh '" + name + "'";
  if (!candidates.empty()) *error += " (tried '" + candidates.front() + "'";
  if (candidates.size() > 1) *error += ", '" + candidates.back() + "'";
  if (!candidates.empty()) *error += ")";
  if (startsWith(name, kPackagePrefix) && options.mesh_base_dir.empty()) *error += "; set ~urdf_dir";
  return "";
}

}  // namespace

RobotModel::RobotModel() = default;
RobotModel::~RobotModel() = default;

int RobotModel::linkIndex(const std::string& name) const {
  auto it = link_index_.find(name);
  return it == link_index_.end() ? -1 : it->second;
}

bool RobotModel::jointMovesLink(std::size_t joint, int link) const { return offset_bound_[joint][link] >= 0.0; }

std::unique_ptr<RobotModel> RobotModel::fromUrdf(const std::string& urdf_xml, const RobotModelOptions& options,
                                                 std::string* error) {
  std::string dummy;
  if (error == nullptr) error = &dummy;
  urdf::ModelInterfaceSharedPtr urdf_model;
  try {
    urdf_model = urdf::parseURDF(urdf_xml);
  } catch (const std::exception& e) {
    *error = std::string("URDF does not parse: ") + e.what();
    return nullptr;
  }
  if (!urdf_model || !urdf_model->getRoot()) {
    *error = "URDF does not parse (urdfdom rejected the robot description)";
    return nullptr;
  }
  if (options.joint_names.empty()) {
    *error = "no controlled joints configured";
    return nullptr;
  }
  std::unique_ptr<RobotModel> m(new RobotModel());
  m->urdf_ = urdf_xml;
  m->joint_names_ = options.joint_names;
  const std::size_t dof = options.joint_names.size();
  std::map<std::string, int> controlled;
  for (std::size_t i = 0; i < dof; ++i) {
    if (!controlled.emplace(options.joint_names[i], static_cast<int>(i)).second) {
      *error = "joint '" + options.joint_names[i] + "' is configured twice";
      return nullptr;
    }
  }
  for (const auto& kv : options.fixed_joint_positions) {
    if (!urdf_model->getJoint(kv.first)) {
      *error = "fixed_joint_positions names joint '" + kv.first + "' which is not in the URDF";
      return nullptr;
    }
    if (!std::isfinite(kv.second)) {
      *error = "fixed_joint_positions of '" + kv.first + "' is not finite";
      return nullptr;
    }
  }
  m->lower_.assign(dof, 0.0);
  m->upper_.assign(dof, 0.0);
  m->velocity_.assign(dof, 0.0);
  m->joint_is_prismatic_.assign(dof, false);
  m->joint_child_link_.assign(dof, -1);
  std::vector<bool> found(dof, false);

  // Breadth-first traversal: parents before children.
  std::deque<urdf::LinkConstSharedPtr> queue{urdf_model->getRoot()};
  std::vector<double> joint_offset;  // |origin translation| of each link's parent joint (+ prismatic travel)
  while (!queue.empty()) {
    urdf::LinkConstSharedPtr link = queue.front();
    queue.pop_front();
    const int index = static_cast<int>(m->link_names_.size());
    m->link_names_.push_back(link->name);
    m->link_index_[link->name] = index;
    Joint j;
    int parent = -1;
    double offset = 0.0;
    if (link->parent_joint) {
      const urdf::JointConstSharedPtr& uj = link->parent_joint;
      parent = m->link_index_.at(uj->parent_link_name);
      j.origin = toEigen(uj->parent_to_joint_origin_transform);
      j.axis = Eigen::Vector3d(uj->axis.x, uj->axis.y, uj->axis.z);
      if (j.axis.norm() > 0) j.axis.normalize();
      offset = j.origin.translation().norm();
      const auto ctrl = controlled.find(uj->name);
      const bool movable = uj->type == urdf::Joint::REVOLUTE || uj->type == urdf::Joint::CONTINUOUS ||
                           uj->type == urdf::Joint::PRISMATIC;
      if (ctrl != controlled.end()) {
        if (!movable) {
          *error = "configured joint '" + uj->name + "' is not revolute, continuous or prismatic";
          return nullptr;
        }
        const int ci = ctrl->second;
        found[ci] = true;
        j.controlled = ci;
        m->joint_child_link_[ci] = index;
        m->joint_is_prismatic_[ci] = uj->type == urdf::Joint::PRISMATIC;
        if (uj->type == urdf::Joint::CONTINUOUS) {
          m->lower_[ci] = -kContinuousJointLimit;
          m->upper_[ci] = kContinuousJointLimit;
        } else if (uj->limits) {
          m->lower_[ci] = uj->limits->lower;
          m->upper_[ci] = uj->limits->upper;
        } else {
          *error = "configured joint '" + uj->name + "' has no <limit> in the URDF";
          return nullptr;
        }
        if (!(m->lower_[ci] <= m->upper_[ci])) {
          *error = "joint '" + uj->name + "' has lower limit > upper limit";
          return nullptr;
        }
        if (uj->limits) m->velocity_[ci] = uj->limits->velocity;
      }
      if (movable) {
        j.type = uj->type == urdf::Joint::PRISMATIC ? 2 : 1;
        const auto fixed = options.fixed_joint_positions.find(uj->name);
        j.fixed_value = fixed == options.fixed_joint_positions.end() ? 0.0 : fixed->second;
        if (j.controlled < 0) m->fixed_used_[uj->name] = j.fixed_value;
        if (j.type == 2) {
          offset += j.controlled >= 0 ? std::max(std::fabs(m->lower_[j.controlled]), std::fabs(m->upper_[j.controlled]))
                                      : std::fabs(j.fixed_value);
        }
      }
    }
    m->link_parent_.push_back(parent);
    m->link_joint_.push_back(j);
    joint_offset.push_back(offset);
    const bool is_static = parent < 0 || (m->link_static_[parent] && j.controlled < 0);
    m->link_static_.push_back(is_static);
    m->link_driving_joint_.push_back(j.controlled >= 0 ? j.controlled
                                                       : (parent < 0 ? -1 : m->link_driving_joint_[parent]));
    for (const auto& child : link->child_links) queue.push_back(child);
  }
  for (std::size_t i = 0; i < dof; ++i) {
    if (!found[i]) {
      *error = "configured joint '" + options.joint_names[i] + "' is not in the URDF";
      return nullptr;
    }
  }

  // Chain offset bounds: distance from controlled joint i's frame to any link frame it moves.
  const std::size_t n_links = m->link_names_.size();
  m->offset_bound_.assign(dof, std::vector<double>(n_links, -1.0));
  for (std::size_t i = 0; i < dof; ++i) {
    const int root = m->joint_child_link_[i];
    m->offset_bound_[i][root] = 0.0;             // the joint frame is the child link frame
    for (std::size_t l = 0; l < n_links; ++l) {  // parents come first
      const int p = m->link_parent_[l];
      if (static_cast<int>(l) != root && p >= 0 && m->offset_bound_[i][p] >= 0.0) {
        m->offset_bound_[i][l] = m->offset_bound_[i][p] + joint_offset[l];
      }
    }
  }

  // Collision shapes.
  m->shapes_.resize(n_links);
  for (std::size_t l = 0; l < n_links; ++l) {
    urdf::LinkConstSharedPtr link = urdf_model->getLink(m->link_names_[l]);
    std::vector<urdf::CollisionSharedPtr> collisions = link->collision_array;
    if (collisions.empty() && link->collision) collisions.push_back(link->collision);
    for (const auto& c : collisions) {
      if (!c || !c->geometry) continue;
      CollisionShapeSpec s;
      s.origin = toEigen(c->origin);
      switch (c->geometry->type) {
        case urdf::Geometry::BOX: {
          const auto* b = static_cast<const urdf::Box*>(c->geometry.get());
          s.type = ShapeType::kBox;
          s.dims = Eigen::Vector3d(b->dim.x, b->dim.y, b->dim.z);
          break;
        }
        case urdf::Geometry::SPHERE:
          s.type = ShapeType::kSphere;
          s.dims.x() = static_cast<const urdf::Sphere*>(c->geometry.get())->radius;
          break;
        case urdf::Geometry::CYLINDER: {
          const auto* cy = static_cast<const urdf::Cylinder*>(c->geometry.get());
          s.type = ShapeType::kCylinder;
          s.dims = Eigen::Vector3d(cy->radius, cy->length, 0.0);
          break;
        }
        case urdf::Geometry::MESH: {
          const auto* me = static_cast<const urdf::Mesh*>(c->geometry.get());
          s.type = ShapeType::kMesh;
          s.scale = Eigen::Vector3d(me->scale.x, me->scale.y, me->scale.z);
          s.mesh_path = resolveMesh(me->filename, options, error);
          if (s.mesh_path.empty()) {
            *error = "link '" + m->link_names_[l] + "': " + *error;
            return nullptr;
          }
          break;
        }
        default:
          continue;
      }
      m->shapes_[l].push_back(s);
    }
  }

  // Base and end-effector links.
  m->base_link_ = options.base_link.empty() ? m->link_names_.front() : options.base_link;
  m->base_index_ = m->linkIndex(m->base_link_);
  if (m->base_index_ < 0) {
    *error = "base_link '" + m->base_link_ + "' is not in the URDF";
    return nullptr;
  }
  if (!m->link_static_[m->base_index_]) {
    *error = "base_link '" + m->base_link_ + "' is moved by a controlled joint";
    return nullptr;
  }
  m->ee_link_ = options.ee_link.empty() ? m->link_names_[m->joint_child_link_.back()] : options.ee_link;
  if (m->linkIndex(m->ee_link_) < 0) {
    *error = "ee_link '" + m->ee_link_ + "' is not in the URDF";
    return nullptr;
  }
  {
    // The base is static: its pose does not depend on q. Compute it once with q = 0 (clamped to limits).
    std::vector<double> q(dof);
    for (std::size_t i = 0; i < dof; ++i) q[i] = std::min(std::max(0.0, m->lower_[i]), m->upper_[i]);
    std::vector<Eigen::Isometry3d> poses;
    m->computeLinkTransforms(q.data(), &poses);  // root_to_base_inv_ is still identity here
    m->root_to_base_inv_ = poses[m->base_index_].inverse();
  }

  // Independent KDL tree (used to cross-check FK).
  m->kdl_tree_ = std::make_unique<KDL::Tree>();
  if (!kdl_parser::treeFromUrdfModel(*urdf_model, *m->kdl_tree_)) {
    *error = "kdl_parser could not build a KDL tree from the URDF";
    return nullptr;
  }
  for (const auto& seg : m->kdl_tree_->getSegments()) {
    const KDL::Joint& kj = GetTreeElementSegment(seg.second).getJoint();
    if (kj.getType() != KDL::Joint::None) m->kdl_joint_index_[kj.getName()] = GetTreeElementQNr(seg.second);
  }
  return m;
}

void RobotModel::computeLinkTransforms(const double* q, std::vector<Eigen::Isometry3d>* out) const {
  const std::size_t n = link_names_.size();
  if (out->size() != n) out->resize(n);
  std::vector<Eigen::Isometry3d>& poses = *out;
  for (std::size_t l = 0; l < n; ++l) {
    const Joint& j = link_joint_[l];
    const int p = link_parent_[l];
    if (p < 0) {
      poses[l] = root_to_base_inv_;
      continue;
    }
    if (j.type == 0) {
      poses[l] = poses[p] * j.origin;
      continue;
    }
    const double v = j.controlled >= 0 ? q[j.controlled] : j.fixed_value;
    if (j.type == 1) {
      poses[l] = poses[p] * j.origin * Eigen::AngleAxisd(v, j.axis);
    } else {
      poses[l] = poses[p] * j.origin * Eigen::Translation3d(v * j.axis);
    }
  }
}

bool RobotModel::linkPoseKdl(const std::vector<double>& q, const std::string& link, Eigen::Isometry3d* pose) const {
  if (q.size() != dof() || linkIndex(link) < 0) return false;
  KDL::JntArray jq(kdl_tree_->getNrOfJoints());
  for (const auto& kv : kdl_joint_index_) {
    double v = 0.0;
    const auto fixed = fixed_used_.find(kv.first);
    if (fixed != fixed_used_.end()) v = fixed->second;
    for (std::size_t i = 0; i < dof(); ++i) {
      if (joint_names_[i] == kv.first) v = q[i];
    }
    jq(kv.second) = v;
  }
  KDL::TreeFkSolverPos_recursive solver(*kdl_tree_);
  KDL::Frame f_link, f_base;
  if (solver.JntToCart(jq, f_link, link) < 0 || solver.JntToCart(jq, f_base, base_link_) < 0) return false;
  const KDL::Frame f = f_base.Inverse() * f_link;
  Eigen::Isometry3d t = Eigen::Isometry3d::Identity();
  for (int r = 0; r < 3; ++r) {
    t.translation()(r) = f.p(r);
    for (int c = 0; c < 3; ++c) t.linear()(r, c) = f.M(r, c);
  }
  *pose = t;
  return true;
}

}  // namespace moverl_planning_scene
