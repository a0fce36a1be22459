#include "moverl_planning_scene/fcl_collision_checker.h"

#include <assimp/postprocess.h>
#include <assimp/scene.h>

#include <assimp/Importer.hpp>
#include <chrono>
#include <cmath>
#include <limits>
#include <map>
#include <array>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <random>
#include <sstream>
#include <unistd.h>

#include <fcl/geometry/bvh/BVH_model.h>
#include <fcl/geometry/shape/box.h>
#include <fcl/geometry/shape/capsule.h>
#include <fcl/geometry/shape/cone.h>
#include <fcl/geometry/shape/convex.h>
#include <fcl/geometry/shape/cylinder.h>
#include <fcl/geometry/shape/sphere.h>
#include <fcl/math/bv/OBBRSS.h>
#include <fcl/geometry/octree/octree.h>
#include <fcl/narrowphase/collision.h>
#include <octomap/OcTree.h>

namespace moverl_planning_scene {
namespace {

constexpr std::uint64_t kFnvOffset = 1469598103934665603ULL;
constexpr std::uint64_t kFnvPrime = 1099511628211ULL;
constexpr std::size_t kMaxInteriorStates = 1000000;  // guard against absurd segments
constexpr int kAcmFileVersion = 1;

void fnv(std::uint64_t* h, const void* data, std::size_t n) {
  const auto* p = static_cast<const unsigned char*>(data);
  for (std::size_t i = 0; i < n; ++i) {
    *h ^= p[i];
    *h *= kFnvPrime;
  }
}
void fnvString(std::uint64_t* h, const std::string& s) {
  fnv(h, s.data(), s.size());
  const char sep = '\0';
  fnv(h, &sep, 1);
}
template <typename T>
void fnvValue(std::uint64_t* h, T v) {
  fnv(h, &v, sizeof(v));
}

struct MeshData {
  std::vector<fcl::Vector3d> vertices;
  std::vector<fcl::Triangle> triangles;
};

bool loadMesh(const std::string& path, const Eigen::Vector3d& scale, MeshData* out, std::string* error) {
  Assimp::Importer importer;
  const aiScene* scene = importer.ReadFile(
      path, aiProcess_Triangulate | aiProcess_JoinIdenticalVertices | aiProcess_PreTransformVertices);
  if (scene == nullptr || scene->mNumMeshes == 0) {
    *error = "assimp cannot load mesh '" + path + "': " + importer.GetErrorString();
    return false;
  }
  for (unsigned m = 0; m < scene->mNumMeshes; ++m) {
    const aiMesh* mesh = scene->mMeshes[m];
    const std::size_t base = out->vertices.size();
    for (unsigned v = 0; v < mesh->mNumVertices; ++v) {
      const aiVector3D& p = mesh->mVertices[v];
      out->vertices.emplace_back(p.x * scale.x(), p.y * scale.y(), p.z * scale.z());
    }
    for (unsigned f = 0; f < mesh->mNumFaces; ++f) {
      const aiFace& face = mesh->mFaces[f];
      if (face.mNumIndices != 3) continue;  // points/lines
      out->triangles.emplace_back(base + face.mIndices[0], base + face.mIndices[1], base + face.mIndices[2]);
    }
  }
  if (out->vertices.empty()) {
    *error = "mesh '" + path + "' has no vertices";
    return false;
  }
  return true;
}

/// Vertices whose convex hull contains every point within `padding` of the mesh's convex hull.
///
/// Each hull vertex v moves along m_v / k_v * padding, where m_v is the unit mean of the outward normals n_f of
/// the supporting triangles around v (triangles whose plane has the whole mesh on one side: the hull's faces)
/// and k_v = min_f m_v . n_f. Every direction u in v's normal cone is a non-negative combination of those n_f,
/// so u . m_v / k_v >= |u| and the support function grows by at least padding in every direction: the new hull
/// contains the Minkowski sum of the old one with a ball of radius padding. Vertices on no supporting triangle
/// lie inside the hull and stay where they are.
std::vector<fcl::Vector3d> inflateMesh(const MeshData& mesh, double padding, bool hull_only) {
  if (padding <= 0.0 && !hull_only) return mesh.vertices;
  const std::size_t nv = mesh.vertices.size();
  // Weld duplicated vertices (OBJ exports often repeat them per face) so that normals gather per position.
  std::map<std::array<long long, 3>, std::size_t> ids;
  std::vector<std::size_t> weld(nv);
  constexpr double kWeld = 1e-7;
  for (std::size_t i = 0; i < nv; ++i) {
    const auto& v = mesh.vertices[i];
    const std::array<long long, 3> key{std::llround(v.x() / kWeld), std::llround(v.y() / kWeld),
                                       std::llround(v.z() / kWeld)};
    weld[i] = ids.emplace(key, ids.size()).first->second;
  }
  std::vector<std::vector<fcl::Vector3d>> normals(ids.size());
  for (const auto& t : mesh.triangles) {
    const fcl::Vector3d& a = mesh.vertices[t[0]];
    const fcl::Vector3d n = (mesh.vertices[t[1]] - a).cross(mesh.vertices[t[2]] - a);
    const double norm = n.norm();
    if (norm < 1e-12) continue;  // degenerate triangle
    fcl::Vector3d u = n / norm;
    double lo = 0.0, hi = 0.0;
    for (const auto& v : mesh.vertices) {
      const double side = u.dot(v - a);
      lo = std::min(lo, side);
      hi = std::max(hi, side);
    }
    constexpr double kTolerance = 1e-6;
    if (lo < -kTolerance && hi > kTolerance) continue;  // not a supporting plane: inside the hull
    if (hi > kTolerance) u = -u;                       // outward: the mesh lies on the negative side
    for (int k = 0; k < 3; ++k) normals[weld[t[k]]].push_back(u);
  }
  constexpr double kMaxStretch = 10.0;  // very sharp vertices: cap the offset at 10 * padding
  std::vector<fcl::Vector3d> offset(ids.size(), fcl::Vector3d::Zero());
  for (std::size_t w = 0; w < normals.size(); ++w) {
    if (normals[w].empty()) continue;
    fcl::Vector3d m = fcl::Vector3d::Zero();
    for (const auto& n : normals[w]) m += n;
    if (m.norm() < 1e-9) continue;
    m.normalize();
    double k = 1.0;
    for (const auto& n : normals[w]) k = std::min(k, m.dot(n));
    offset[w] = m * padding * std::min(1.0 / std::max(k, 1e-9), kMaxStretch);
  }
  if (hull_only) {
    // One point per welded vertex that lies on a supporting triangle: the convex hull is unchanged and GJK's
    // exhaustive support search visits 2-3x fewer points (OBJ files repeat vertices per face).
    std::vector<fcl::Vector3d> out;
    std::vector<bool> taken(ids.size(), false);
    for (std::size_t i = 0; i < nv; ++i) {
      const std::size_t w = weld[i];
      if (taken[w] || normals[w].empty()) continue;
      taken[w] = true;
      out.push_back(mesh.vertices[i] + offset[w]);
    }
    if (out.size() >= 4) return out;  // else: degenerate mesh, keep every vertex
  }
  std::vector<fcl::Vector3d> out(mesh.vertices);
  for (std::size_t i = 0; i < nv; ++i) out[i] += offset[weld[i]];
  return out;
}

std::shared_ptr<fcl::CollisionGeometry<double>> meshGeometry(const std::vector<fcl::Vector3d>& vertices,
                                                             const std::vector<fcl::Triangle>& triangles,
                                                             MeshMode mode) {
  if (mode == MeshMode::kConvexHull) {
    // No faces on purpose: FCL then uses an exhaustive support function over all vertices, which is exactly
    // the support function of the convex hull of the mesh (correct even if the mesh is not convex).
    auto verts = std::make_shared<const std::vector<fcl::Vector3d>>(vertices);
    auto faces = std::make_shared<const std::vector<int>>();
    return std::make_shared<fcl::Convexd>(verts, 0, faces);
  }
  auto bvh = std::make_shared<fcl::BVHModel<fcl::OBBRSSd>>();
  bvh->beginModel(static_cast<int>(triangles.size()), static_cast<int>(vertices.size()));
  bvh->addSubModel(vertices, triangles);
  bvh->endModel();
  return bvh;
}

}  // namespace

struct FclCollisionChecker::Geom {
  int link = -1;
  std::shared_ptr<fcl::CollisionGeometry<double>> geom;
  Eigen::Isometry3d origin = Eigen::Isometry3d::Identity();  // shape in link frame
  Eigen::Vector3d center_local = Eigen::Vector3d::Zero();     // bounding sphere centre, link frame
  double radius = 0.0;                                        // bounding sphere radius
  Eigen::Isometry3d world_tf = Eigen::Isometry3d::Identity();
  Eigen::Vector3d world_center = Eigen::Vector3d::Zero();
  // The same shape inflated by >= self_padding, for self-collision checks (== geom when self_padding is 0).
  std::shared_ptr<fcl::CollisionGeometry<double>> padded;
  double padded_radius = 0.0;
  // The same shape inflated by >= padding, checked against the sensed octree (whose cells cannot be inflated).
  std::shared_ptr<fcl::CollisionGeometry<double>> octo;
};

struct FclCollisionChecker::Obstacle {
  std::string id;
  std::shared_ptr<fcl::CollisionGeometry<double>> geom;
  Eigen::Isometry3d pose = Eigen::Isometry3d::Identity();
  double radius = 0.0;  // bounding sphere about pose.translation()
  WorldObject source;   // moving obstacles: the object as given (pose at t = 0, unpadded dimensions, motion)
};

namespace {

/// Geometry of object o padded by p and translated along its motion axis by every s in [lo, hi] from its pose at
/// t = 0: a superset of the swept volume (exact for spheres -> capsules, boxes translating along a box axis and
/// cylinders translating along their own axis; otherwise the shape's local bounding box stretched along the motion).
/// With lo = hi = 0 it is the padded object itself. Returns false for a bad shape (message in *why).
bool sweptGeometry(const WorldObject& o, double p, double lo, double hi,
                   std::shared_ptr<fcl::CollisionGeometry<double>>* geom, Eigen::Isometry3d* pose, double* radius,
                   std::string* why) {
  const std::vector<double>& d = o.dimensions;
  const double h = 0.5 * (hi - lo);                  // half the travel
  const Eigen::Vector3d a = o.motion.axis;           // unit
  *pose = o.pose;
  pose->translation() += a * (0.5 * (lo + hi));      // centre of the travel
  const Eigen::Matrix3d R = o.pose.linear();
  const Eigen::Vector3d u = R.transpose() * a;       // motion axis in the object's frame
  constexpr double kAligned = 1.0 - 1e-9;
  auto box = [&](double x, double y, double z) {
    // A box of these (padded) dims in the frame *pose, swept along u by +/- h: |x_i + s u_i| <= d_i/2 + h |u_i|.
    const Eigen::Vector3d dims(x + 2 * h * std::fabs(u[0]), y + 2 * h * std::fabs(u[1]), z + 2 * h * std::fabs(u[2]));
    *geom = std::make_shared<fcl::Boxd>(dims[0], dims[1], dims[2]);
    *radius = 0.5 * dims.norm();
  };
  switch (o.type) {
    case ShapeType::kBox:
      if (d.size() != 3) return (*why = "BOX needs 3 dimensions [x, y, z]", false);
      box(d[0] + 2 * p, d[1] + 2 * p, d[2] + 2 * p);
      return true;
    case ShapeType::kSphere:
      if (d.size() != 1) return (*why = "SPHERE needs 1 dimension [radius]", false);
      if (h <= 0.0) {
        *geom = std::make_shared<fcl::Sphered>(d[0] + p);
      } else {  // a capsule along the motion axis (fcl capsules lie along local z)
        *geom = std::make_shared<fcl::Capsuled>(d[0] + p, 2 * h);
        pose->linear() = Eigen::Quaterniond::FromTwoVectors(Eigen::Vector3d::UnitZ(), a).toRotationMatrix();
      }
      *radius = d[0] + p + h;
      return true;
    case ShapeType::kCylinder:
    case ShapeType::kCone: {
      if (d.size() != 2) return (*why = "CYLINDER/CONE needs 2 dimensions [height, radius]", false);
      const double r = d[1] + p, len = d[0] + 2 * p;
      if (h <= 0.0 || std::fabs(u[2]) >= kAligned) {  // static, or moving along its own axis: longer cylinder
        if (o.type == ShapeType::kCylinder) {
          *geom = std::make_shared<fcl::Cylinderd>(r, len + 2 * h);
        } else if (h <= 0.0) {
          *geom = std::make_shared<fcl::Coned>(r, len);
        } else {
          *geom = std::make_shared<fcl::Cylinderd>(r, len + 2 * h);  // cone within its cylinder
        }
        *radius = std::hypot(r, 0.5 * len + h);
        return true;
      }
      // Rotate the (symmetric) local frame about z so that the in-plane part of u lies along x; bound the
      // cylinder by its box (2r, 2r, len) and sweep that.
      const double angle = std::atan2(u[1], u[0]);
      pose->linear() = R * Eigen::AngleAxisd(angle, Eigen::Vector3d::UnitZ()).toRotationMatrix();
      const Eigen::Vector3d u2(std::hypot(u[0], u[1]), 0.0, u[2]);
      const Eigen::Vector3d dims(2 * r + 2 * h * u2[0], 2 * r, len + 2 * h * std::fabs(u2[2]));
      *geom = std::make_shared<fcl::Boxd>(dims[0], dims[1], dims[2]);
      *radius = 0.5 * dims.norm();
      return true;
    }
    default:
      return (*why = "unsupported shape type", false);
  }
}

}  // namespace

FclCollisionChecker::FclCollisionChecker(const RobotModel& model) : model_(model) {}
FclCollisionChecker::~FclCollisionChecker() = default;

std::unique_ptr<FclCollisionChecker> FclCollisionChecker::create(const RobotModel& model,
                                                                 const FclCheckerOptions& options,
                                                                 std::string* error) {
  std::string dummy;
  if (error == nullptr) error = &dummy;
  if (!(options.padding >= 0.0) || !std::isfinite(options.padding)) {
    *error = "padding must be >= 0";
    return nullptr;
  }
  if (!(options.path_resolution > 0.0) || !std::isfinite(options.path_resolution)) {
    *error = "path_resolution must be > 0";
    return nullptr;
  }
  if (!(options.self_padding >= 0.0) || !std::isfinite(options.self_padding)) {
    *error = "self_padding must be >= 0";
    return nullptr;
  }
  if (options.acm_samples < 0) {
    *error = "acm_samples must be >= 0";
    return nullptr;
  }
  std::unique_ptr<FclCollisionChecker> c(new FclCollisionChecker(model));
  c->options_ = options;
  if (!c->loadGeometry(error)) return nullptr;
  c->computeAcm();
  return c;
}

bool FclCollisionChecker::loadGeometry(std::string* error) {
  const std::size_t n_links = model_.linkNames().size();
  link_geoms_.assign(n_links, {});
  for (std::size_t l = 0; l < n_links; ++l) {
    for (const CollisionShapeSpec& s : model_.collisionShapes(static_cast<int>(l))) {
      Geom g;
      g.link = static_cast<int>(l);
      g.origin = s.origin;
      Eigen::Vector3d center_shape = Eigen::Vector3d::Zero();
      const double sp = options_.self_padding, wp = options_.padding;
      g.padded_radius = -1.0;  // primitives: radius + 2 * sp (set below); meshes compute it exactly
      switch (s.type) {
        case ShapeType::kBox:
          g.geom = std::make_shared<fcl::Boxd>(s.dims.x(), s.dims.y(), s.dims.z());
          g.radius = 0.5 * s.dims.norm();
          g.padded = std::make_shared<fcl::Boxd>(s.dims.x() + 2 * sp, s.dims.y() + 2 * sp, s.dims.z() + 2 * sp);
          g.octo = std::make_shared<fcl::Boxd>(s.dims.x() + 2 * wp, s.dims.y() + 2 * wp, s.dims.z() + 2 * wp);
          break;
        case ShapeType::kSphere:
          g.geom = std::make_shared<fcl::Sphered>(s.dims.x());
          g.radius = s.dims.x();
          g.padded = std::make_shared<fcl::Sphered>(s.dims.x() + sp);
          g.octo = std::make_shared<fcl::Sphered>(s.dims.x() + wp);
          break;
        case ShapeType::kCylinder:
          g.geom = std::make_shared<fcl::Cylinderd>(s.dims.x(), s.dims.y());
          g.radius = std::hypot(s.dims.x(), 0.5 * s.dims.y());
          g.padded = std::make_shared<fcl::Cylinderd>(s.dims.x() + sp, s.dims.y() + 2 * sp);
          g.octo = std::make_shared<fcl::Cylinderd>(s.dims.x() + wp, s.dims.y() + 2 * wp);
          break;
        case ShapeType::kCone:
          g.geom = std::make_shared<fcl::Coned>(s.dims.x(), s.dims.y());
          g.radius = std::hypot(s.dims.x(), 0.5 * s.dims.y());
          g.padded = std::make_shared<fcl::Coned>(s.dims.x() + sp, s.dims.y() + 2 * sp);
          g.octo = std::make_shared<fcl::Coned>(s.dims.x() + wp, s.dims.y() + 2 * wp);
          break;
        case ShapeType::kMesh: {
          MeshData mesh;
          if (!loadMesh(s.mesh_path, s.scale, &mesh, error)) return false;
          Eigen::Vector3d lo = mesh.vertices.front(), hi = lo;
          for (const auto& v : mesh.vertices) {
            lo = lo.cwiseMin(v);
            hi = hi.cwiseMax(v);
          }
          center_shape = 0.5 * (lo + hi);
          for (const auto& v : mesh.vertices) g.radius = std::max(g.radius, (v - center_shape).norm());
          const bool hull = options_.mesh_mode == MeshMode::kConvexHull;
          const std::vector<Eigen::Vector3d> inflated = inflateMesh(mesh, sp, hull);
          g.padded_radius = 0.0;
          for (const auto& v : inflated) g.padded_radius = std::max(g.padded_radius, (v - center_shape).norm());
          g.geom = meshGeometry(hull ? inflateMesh(mesh, 0.0, true) : mesh.vertices, mesh.triangles,
                                options_.mesh_mode);
          g.padded = sp > 0.0 ? meshGeometry(inflated, mesh.triangles, options_.mesh_mode) : g.geom;
          g.octo = wp > 0.0 ? meshGeometry(inflateMesh(mesh, wp, hull), mesh.triangles, options_.mesh_mode) : g.geom;
          break;
        }
      }
      g.geom->computeLocalAABB();
      if (sp <= 0.0) g.padded = g.geom;
      if (wp <= 0.0) g.octo = g.geom;
      g.padded->computeLocalAABB();
      g.octo->computeLocalAABB();
      if (g.padded_radius < 0.0) g.padded_radius = g.radius + 2.0 * sp;
      g.center_local = s.origin * center_shape;
      link_geoms_[l].push_back(static_cast<int>(geoms_.size()));
      geoms_.push_back(std::move(g));
    }
  }
  const std::size_t dof = model_.dof();
  // Reach: bound on the distance of any collision-geometry point from the base origin, in every configuration.
  {
    std::vector<Eigen::Isometry3d> poses;
    const std::vector<double> q0(dof, 0.0);
    model_.computeLinkTransforms(q0.data(), &poses);
    double d0 = 0.0;  // distance of joint 0's origin (= the origin of its child link) from the base origin
    for (std::size_t l = 0; l < n_links; ++l) {
      if (dof > 0 && model_.chainOffsetBound(0, static_cast<int>(l)) == 0.0) {
        d0 = std::max(d0, poses[l].translation().norm());
      }
    }
    reach_radius_ = 0.0;
    for (const Geom& g : geoms_) {
      const double c = dof > 0 ? model_.chainOffsetBound(0, g.link) : -1.0;
      const double r = c < 0.0 ? (poses[g.link] * g.center_local).norm() + g.radius
                               : d0 + c + g.center_local.norm() + g.radius;
      reach_radius_ = std::max(reach_radius_, r);
    }
  }
  // r_i: bound on the distance of any geometry point moved by joint i from the joint axis.
  joint_radius_.assign(dof, 0.0);
  for (std::size_t i = 0; i < dof; ++i) {
    if (model_.isPrismatic(i)) {
      joint_radius_[i] = 1.0;  // every moved point travels exactly |dq_i|
      continue;
    }
    for (const Geom& g : geoms_) {
      const double chain = model_.chainOffsetBound(i, g.link);
      if (chain < 0.0) continue;
      joint_radius_[i] = std::max(joint_radius_[i], chain + g.center_local.norm() + g.radius);
    }
  }
  link_poses_.resize(n_links);
  q_scratch_.resize(dof);
  return true;
}

void FclCollisionChecker::updateTransforms(const double* q) {
  model_.computeLinkTransforms(q, &link_poses_);
  for (Geom& g : geoms_) {
    const Eigen::Isometry3d& p = link_poses_[g.link];
    g.world_tf = p * g.origin;
    g.world_center = p * g.center_local;
  }
}

bool FclCollisionChecker::geomPairCollides(const Geom& a, const Geom& b, bool compute_depth, double* depth,
                                           bool padded) const {
  const double r = padded ? a.padded_radius + b.padded_radius : a.radius + b.radius;
  if ((a.world_center - b.world_center).squaredNorm() > r * r) return false;
  fcl::CollisionRequestd req(1, compute_depth);
  fcl::CollisionResultd res;
  fcl::collide(padded ? a.padded.get() : a.geom.get(), a.world_tf, padded ? b.padded.get() : b.geom.get(), b.world_tf,
               req, res);
  if (!res.isCollision()) return false;
  if (compute_depth && depth != nullptr && res.numContacts() > 0) {
    *depth = std::max(*depth, res.getContact(0).penetration_depth);
  }
  return true;
}

bool FclCollisionChecker::linkPairCollides(int la, int lb, bool padded) {
  for (int ga : link_geoms_[la]) {
    for (int gb : link_geoms_[lb]) {
      if (geomPairCollides(geoms_[ga], geoms_[gb], false, nullptr, padded)) return true;
    }
  }
  return false;
}

std::uint64_t FclCollisionChecker::acmKey() const {
  std::uint64_t h = kFnvOffset;
  fnvValue(&h, kAcmFileVersion);
  fnvString(&h, model_.urdfText());
  for (const auto& j : model_.jointNames()) fnvString(&h, j);
  fnvString(&h, "|fixed|");
  for (const auto& kv : model_.fixedPositions()) {
    fnvString(&h, kv.first);
    fnvValue(&h, kv.second);
  }
  fnvValue(&h, options_.acm_samples);
  fnvValue(&h, options_.acm_seed);
  fnvValue(&h, options_.self_padding);
  fnvValue(&h, static_cast<int>(options_.mesh_mode));
  // Geometry content (mesh files may change while the URDF text does not).
  for (const Geom& g : geoms_) {
    fnvValue(&h, g.radius);
    fnvValue(&h, g.center_local.x());
    fnvValue(&h, g.center_local.y());
    fnvValue(&h, g.center_local.z());
  }
  return h;
}

bool FclCollisionChecker::loadAcm(const std::string& file) {
  std::ifstream in(file);
  if (!in) return false;
  const std::size_t n = model_.linkNames().size();
  std::vector<AcmReason> acm(n * n, AcmReason::kNoGeometry);
  std::string a, b;
  int reason = 0;
  std::size_t count = 0;
  while (in >> a >> b >> reason) {
    const int ia = model_.linkIndex(a), ib = model_.linkIndex(b);
    if (ia < 0 || ib < 0 || reason < 0 || reason > static_cast<int>(AcmReason::kNoGeometry)) return false;
    acm[ia * n + ib] = acm[ib * n + ia] = static_cast<AcmReason>(reason);
    ++count;
  }
  if (count == 0) return false;
  acm_ = acm;
  return true;
}

void FclCollisionChecker::saveAcm(const std::string& file) const {
  std::error_code ec;
  std::filesystem::create_directories(std::filesystem::path(file).parent_path(), ec);
  const std::string tmp = file + ".tmp" + std::to_string(::getpid());
  {
    std::ofstream out(tmp);
    if (!out) return;
    const auto& names = model_.linkNames();
    const std::size_t n = names.size();
    for (std::size_t a = 0; a < n; ++a) {
      for (std::size_t b = a + 1; b < n; ++b) {
        if (acm_[a * n + b] == AcmReason::kNoGeometry) continue;
        out << names[a] << ' ' << names[b] << ' ' << static_cast<int>(acm_[a * n + b]) << '\n';
      }
    }
  }
  std::filesystem::rename(tmp, file, ec);
  if (ec) std::filesystem::remove(tmp, ec);
}

void FclCollisionChecker::computeAcm() {
  const auto t0 = std::chrono::steady_clock::now();
  const std::size_t n = model_.linkNames().size();
  acm_stats_ = AcmStats();
  if (!options_.acm_cache_dir.empty()) {
    char name[64];
    std::snprintf(name, sizeof(name), "acm_%016llx.txt", static_cast<unsigned long long>(acmKey()));
    acm_stats_.cache_file = (std::filesystem::path(options_.acm_cache_dir) / name).string();
    if (loadAcm(acm_stats_.cache_file)) acm_stats_.from_cache = true;
  }
  if (!acm_stats_.from_cache) {
    acm_.assign(n * n, AcmReason::kNoGeometry);
    // Nearest ancestor with collision geometry ("looking through" geometry-less links and fixed joints).
    auto geometry_parent = [&](int l) {
      int p = model_.parentLink(l);
      while (p >= 0 && link_geoms_[p].empty()) p = model_.parentLink(p);
      return p;
    };
    std::vector<std::pair<int, int>> candidates;
    for (std::size_t a = 0; a < n; ++a) {
      if (link_geoms_[a].empty()) continue;
      for (std::size_t b = a + 1; b < n; ++b) {
        if (link_geoms_[b].empty()) continue;
        const int ia = static_cast<int>(a), ib = static_cast<int>(b);
        AcmReason r = AcmReason::kEnabled;
        if (model_.isStatic(ia) && model_.isStatic(ib)) {
          r = AcmReason::kStatic;
        } else if (geometry_parent(ib) == ia || geometry_parent(ia) == ib) {
          r = AcmReason::kAdjacent;
        } else if (model_.drivingJoint(ia) == model_.drivingJoint(ib)) {
          r = AcmReason::kRigid;  // no controlled joint between them
        } else {
          candidates.emplace_back(ia, ib);
        }
        acm_[a * n + b] = acm_[b * n + a] = r;
      }
    }
    if (options_.acm_samples > 0 && !candidates.empty()) {
      // "always": the real shapes touch in every sample; "never": even the padded shapes never touch.
      std::vector<int> hits(candidates.size(), 0), padded_hits(candidates.size(), 0);
      std::mt19937_64 rng(options_.acm_seed);
      const std::size_t dof = model_.dof();
      std::vector<double> q(dof);
      for (int s = 0; s < options_.acm_samples; ++s) {
        for (std::size_t i = 0; i < dof; ++i) {
          std::uniform_real_distribution<double> d(model_.lowerLimits()[i], model_.upperLimits()[i]);
          q[i] = d(rng);
        }
        updateTransforms(q.data());
        for (std::size_t c = 0; c < candidates.size(); ++c) {
          if (linkPairCollides(candidates[c].first, candidates[c].second, true)) {
            ++padded_hits[c];
            if (linkPairCollides(candidates[c].first, candidates[c].second, false)) ++hits[c];
          }
        }
      }
      for (std::size_t c = 0; c < candidates.size(); ++c) {
        AcmReason r = AcmReason::kEnabled;
        if (padded_hits[c] == 0) r = AcmReason::kNever;
        if (hits[c] == options_.acm_samples) r = AcmReason::kAlways;
        const int a = candidates[c].first, b = candidates[c].second;
        acm_[a * n + b] = acm_[b * n + a] = r;
      }
    }
    if (!acm_stats_.cache_file.empty()) saveAcm(acm_stats_.cache_file);
  }
  rebuildPairLists();
  acm_stats_.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

void FclCollisionChecker::rebuildPairLists() {
  const std::size_t n = model_.linkNames().size();
  self_pairs_.clear();
  for (std::size_t a = 0; a < n; ++a) {
    for (std::size_t b = a + 1; b < n; ++b) {
      switch (acm_[a * n + b]) {
        case AcmReason::kEnabled:
          ++acm_stats_.enabled;
          self_pairs_.emplace_back(static_cast<int>(a), static_cast<int>(b));
          break;
        case AcmReason::kAdjacent:
          ++acm_stats_.adjacent;
          break;
        case AcmReason::kRigid:
          ++acm_stats_.rigid;
          break;
        case AcmReason::kAlways:
          ++acm_stats_.always;
          break;
        case AcmReason::kNever:
          ++acm_stats_.never;
          break;
        default:
          break;
      }
    }
  }
  world_geoms_.clear();
  for (std::size_t g = 0; g < geoms_.size(); ++g) {
    if (!model_.isStatic(geoms_[g].link)) world_geoms_.push_back(static_cast<int>(g));
  }
}

std::size_t FclCollisionChecker::worldSize() const { return world_.size(); }

AcmReason FclCollisionChecker::acmReason(const std::string& link_a, const std::string& link_b) const {
  const int a = model_.linkIndex(link_a), b = model_.linkIndex(link_b);
  if (a < 0 || b < 0 || a == b) return AcmReason::kNoGeometry;
  return acm_[a * model_.linkNames().size() + b];
}

bool FclCollisionChecker::setWorld(const std::vector<WorldObject>& objects, std::string* error) {
  std::string dummy;
  if (error == nullptr) error = &dummy;
  std::vector<Obstacle> world;
  world.reserve(objects.size());
  std::vector<std::size_t> moving;
  const double p = options_.padding;
  for (const WorldObject& o : objects) {
    const std::vector<double>& d = o.dimensions;
    auto bad = [&](const std::string& why) {
      *error = "world object '" + o.id + "': " + why;
      return false;
    };
    for (double v : d) {
      if (!std::isfinite(v) || v <= 0.0) return bad("dimensions must be finite and > 0");
    }
    if (!o.pose.matrix().allFinite()) return bad("pose is not finite");
    const ObstacleMotion& m = o.motion;
    if (m.type != ObstacleMotion::Type::kNone) {
      if (m.type != ObstacleMotion::Type::kOscillate) return bad("unknown motion type");
      if (!m.axis.allFinite() || std::fabs(m.axis.norm() - 1.0) > 1e-6) return bad("motion axis must be a unit vector");
      if (!std::isfinite(m.amplitude) || m.amplitude < 0.0) return bad("motion amplitude must be finite and >= 0");
      if (!std::isfinite(m.period) || m.period <= 0.0) return bad("motion period must be finite and > 0");
      if (!std::isfinite(m.phase)) return bad("motion phase must be finite");
    }
    Obstacle ob;
    ob.id = o.id;
    std::string why;
    double lo = 0.0, hi = 0.0;
    if (m.moving()) m.range(0.0, std::numeric_limits<double>::infinity(), &lo, &hi);  // whole envelope
    if (!sweptGeometry(o, p, lo, hi, &ob.geom, &ob.pose, &ob.radius, &why)) return bad(why);
    ob.geom->computeLocalAABB();
    if (m.moving()) {
      moving.push_back(world.size());
      ob.source = o;
    }
    world.push_back(std::move(ob));
  }
  moving_.swap(moving);
  window_t0_ = 0.0;
  window_t1_ = std::numeric_limits<double>::infinity();
  world_.swap(world);
  return true;
}

void FclCollisionChecker::setMotionWindow(double t0, double t1) {
  if (moving_.empty()) return;
  const bool envelope = !(t1 < std::numeric_limits<double>::infinity());
  const bool current_envelope = !(window_t1_ < std::numeric_limits<double>::infinity());
  if (envelope ? current_envelope : (t0 == window_t0_ && t1 == window_t1_)) return;  // unchanged
  window_t0_ = t0;
  window_t1_ = envelope ? std::numeric_limits<double>::infinity() : t1;
  for (std::size_t i : moving_) {
    Obstacle& ob = world_[i];
    double lo, hi;
    ob.source.motion.range(t0, window_t1_, &lo, &hi);
    std::string why;
    sweptGeometry(ob.source, options_.padding, lo, hi, &ob.geom, &ob.pose, &ob.radius, &why);  // validated before
    ob.geom->computeLocalAABB();
  }
}

double FclCollisionChecker::obstacleRadius(std::size_t i) const { return world_.at(i).radius; }
Eigen::Vector3d FclCollisionChecker::obstacleCenter(std::size_t i) const { return world_.at(i).pose.translation(); }

bool FclCollisionChecker::obstacleContains(std::size_t i, const Eigen::Vector3d& point) const {
  const Obstacle& ob = world_.at(i);
  auto probe = std::make_shared<fcl::Sphered>(1e-6);
  Eigen::Isometry3d tf = Eigen::Isometry3d::Identity();
  tf.translation() = point;
  fcl::CollisionRequestd req(1, false);
  fcl::CollisionResultd res;
  fcl::collide(probe.get(), tf, ob.geom.get(), ob.pose, req, res);
  return res.isCollision();
}

void FclCollisionChecker::checkState(const double* q, const CollisionRequest& request, CollisionResult* result) {
  result->clear();
  updateTransforms(q);
  const auto& names = model_.linkNames();
  if (request.check_self) {
    for (const auto& lp : self_pairs_) {
      double depth = 0.0;
      bool hit = false;
      for (int ga : link_geoms_[lp.first]) {
        for (int gb : link_geoms_[lp.second]) {
          if (geomPairCollides(geoms_[ga], geoms_[gb], request.compute_depth, &depth, /*padded=*/true)) {
            hit = true;
            if (!request.compute_depth) break;
          }
        }
        if (hit && !request.compute_depth) break;
      }
      if (!hit) continue;
      result->status = CollisionStatus::kSelf;
      if (request.max_pairs == 0) return;
      result->pairs.push_back(ContactPair{names[lp.first], names[lp.second], depth});
      if (result->pairs.size() >= request.max_pairs) return;
    }
    if (result->collision()) return;
  }
  if (!request.check_world) return;
  for (const Obstacle& ob : world_) {
    const Eigen::Vector3d oc = ob.pose.translation();
    int last_link = -1;
    for (int gi : world_geoms_) {
      const Geom& g = geoms_[gi];
      if (g.link == last_link) continue;  // this link already reported with this obstacle
      const double r = g.radius + ob.radius;
      if ((g.world_center - oc).squaredNorm() > r * r) continue;
      fcl::CollisionRequestd req(1, request.compute_depth);
      fcl::CollisionResultd res;
      fcl::collide(g.geom.get(), g.world_tf, ob.geom.get(), ob.pose, req, res);
      if (!res.isCollision()) continue;
      result->status = CollisionStatus::kWorld;
      if (request.max_pairs == 0) return;
      const double depth = request.compute_depth && res.numContacts() > 0 ? res.getContact(0).penetration_depth : 0.0;
      result->pairs.push_back(ContactPair{names[g.link], ob.id, depth});
      last_link = g.link;
      if (result->pairs.size() >= request.max_pairs) return;
    }
  }
  if (!octree_) return;
  int last_link = -1;
  for (int gi : world_geoms_) {
    const Geom& g = geoms_[gi];
    if (g.link == last_link) continue;
    fcl::CollisionRequestd req(1, false);
    fcl::CollisionResultd res;
    fcl::collide(g.octo.get(), g.world_tf, octree_.get(), Eigen::Isometry3d::Identity(), req, res);
    if (!res.isCollision()) continue;
    result->status = CollisionStatus::kWorld;
    if (request.max_pairs == 0) return;
    result->pairs.push_back(ContactPair{names[g.link], kOctomapId, 0.0});
    last_link = g.link;
    if (result->pairs.size() >= request.max_pairs) return;
  }
}

void FclCollisionChecker::setOctree(std::shared_ptr<const octomap::OcTree> tree) {
  if (!tree) {
    octree_.reset();
    return;
  }
  auto o = std::make_shared<fcl::OcTree<double>>(tree);
  o->computeLocalAABB();
  octree_ = o;
}

void FclCollisionChecker::robotPointMask(const double* q, const std::vector<Eigen::Vector3d>& points, double padding,
                                         std::vector<std::uint8_t>* mask) const {
  mask->assign(points.size(), 0);
  std::vector<Eigen::Isometry3d> poses;
  model_.computeLinkTransforms(q, &poses);
  const double pad = std::max(padding, 1e-6);
  auto probe = std::make_shared<fcl::Sphered>(pad);
  fcl::CollisionRequestd req(1, false);
  for (const Geom& g : geoms_) {
    const Eigen::Isometry3d tf = poses[g.link] * g.origin;
    const Eigen::Vector3d center = poses[g.link] * g.center_local;
    const double r = g.radius + pad, r2 = r * r;
    Eigen::Isometry3d at = Eigen::Isometry3d::Identity();
    for (std::size_t k = 0; k < points.size(); ++k) {
      if ((*mask)[k] != 0 || !((points[k] - center).squaredNorm() <= r2)) continue;
      at.translation() = points[k];
      fcl::CollisionResultd res;
      fcl::collide(probe.get(), at, g.geom.get(), tf, req, res);
      if (res.isCollision()) (*mask)[k] = 1;
    }
  }
}

std::size_t FclCollisionChecker::interiorStateCount(const double* q0, const double* q1) const {
  double motion = 0.0;
  for (std::size_t i = 0; i < joint_radius_.size(); ++i) motion += joint_radius_[i] * std::fabs(q1[i] - q0[i]);
  const double n = std::ceil(motion / options_.path_resolution);
  if (!(n >= 0.0)) return 0;  // NaN guard (inputs are validated by callers)
  return n > static_cast<double>(kMaxInteriorStates) ? kMaxInteriorStates : static_cast<std::size_t>(n);
}

void FclCollisionChecker::checkPath(const double* q0, const double* q1, const PathCheckRequest& request,
                                    PathCheckResult* result) {
  result->clear();
  const std::size_t dof = model_.dof();
  const std::size_t n = interiorStateCount(q0, q1);
  const double denom = static_cast<double>(n + 1);
  double last_valid = 0.0;
  // Checks the state at t; returns true when it collides (and fills the result).
  auto check_at = [&](double t) {
    for (std::size_t i = 0; i < dof; ++i) q_scratch_[i] = q0[i] + t * (q1[i] - q0[i]);
    if (t == 1.0) std::memcpy(q_scratch_.data(), q1, dof * sizeof(double));
    ++result->checked_states;
    checkState(q_scratch_.data(), request.state, &state_scratch_);
    if (!state_scratch_.collision()) return false;
    result->status = state_scratch_.status;
    result->pairs.swap(state_scratch_.pairs);
    result->collision_fraction = t;
    result->last_valid_fraction = last_valid;
    return true;
  };
  if (request.find_first) {
    if (request.check_start && check_at(0.0)) return;
    for (std::size_t k = 1; k <= n; ++k) {
      const double t = static_cast<double>(k) / denom;
      if (check_at(t)) return;
      last_valid = t;
    }
    if (request.check_goal && check_at(1.0)) return;
    result->last_valid_fraction = 1.0;
    return;
  }
  // Rejection-first order: goal, start, then interior indices by bisection (coarse to fine).
  last_valid = 0.0;
  if (request.check_goal && check_at(1.0)) return;
  if (request.check_start && check_at(0.0)) return;
  if (n > 0) {
    // Coarse-to-fine bisection: at level `step`, the odd multiples of step (even ones were done at coarser levels).
    std::size_t step = 1;
    while (step < n + 1) step <<= 1;
    for (; step >= 1; step >>= 1) {
      for (std::size_t k = step; k <= n; k += 2 * step) {
        if (check_at(static_cast<double>(k) / denom)) {
          result->last_valid_fraction = 0.0;  // unknown in this order: be conservative
          return;
        }
      }
    }
  }
  result->last_valid_fraction = 1.0;
}

}  // namespace moverl_planning_scene
