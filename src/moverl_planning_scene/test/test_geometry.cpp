/**
 * \file test_geometry.cpp
 * \brief Convex hulls, their inflation, mesh reading (OBJ pieces, COLLADA units/up axis) and the regression of issue
 *        #15: every vertex of the KUKA iiwa's binary STL collision meshes lies inside the scene's link shapes. No
 *        roscore. The iiwa test is skipped when pybullet_data was not found at configure time.
 */
#include <gtest/gtest.h>

#include <unistd.h>
#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <random>
#include <set>
#include <sstream>
#include <utility>

#include <fcl/geometry/shape/box.h>
#include <fcl/geometry/shape/capsule.h>
#include <fcl/geometry/shape/cone.h>
#include <fcl/geometry/shape/cylinder.h>
#include <fcl/geometry/shape/halfspace.h>
#include <fcl/geometry/shape/sphere.h>
#include <fcl/narrowphase/collision.h>
#include "moverl_planning_scene/convex_hull.h"
#include "moverl_planning_scene/fcl_collision_checker.h"
#include "moverl_planning_scene/fcl_convex.h"
#include "moverl_planning_scene/mesh_loader.h"
#include "moverl_planning_scene/robot_model.h"
#include "moverl_planning_scene/worker_pool.h"
#include "panda_support.h"

namespace mps = moverl_planning_scene;
using Eigen::Vector3d;

namespace {

const std::string kPandaUrdf = MOVERL_PANDA_URDF;

/// pybullet_data's folder, from the Panda URDF found at configure time ("" when not found).
std::string pybulletData() {
  if (kPandaUrdf.empty()) return "";
  const std::string dir = kPandaUrdf.substr(0, kPandaUrdf.rfind('/'));  // .../franka_panda
  return dir.substr(0, dir.rfind('/'));
}

/// The Panda's model as config/robots/panda.yaml gives it (pybullet_data's URDF); nullptr with *error.
std::unique_ptr<mps::RobotModel> pandaModel(std::string* error) {
  return mps::RobotModel::fromUrdf(mps::panda::readFile(kPandaUrdf), mps::panda::options(kPandaUrdf).robot, error);
}

/// The Panda's model and its scene options as the repo ships them: a fatal failure when either is missing (callers
/// wrap it in ASSERT_NO_FATAL_FAILURE).
void loadPandaModel(std::unique_ptr<mps::RobotModel>* model, mps::PlanningSceneOptions* options) {
  ASSERT_FALSE(kPandaUrdf.empty()) << "pybullet_data's Panda URDF not found at configure time";
  *options = mps::panda::options(kPandaUrdf);
  std::string error;
  *model = pandaModel(&error);
  ASSERT_NE(*model, nullptr) << error;
}

/// The Panda's planning scene as the repo ships it (a fatal failure when it cannot be built).
void loadPandaScene(std::unique_ptr<mps::PlanningScene>* scene) {
  ASSERT_FALSE(kPandaUrdf.empty()) << "pybullet_data's Panda URDF not found at configure time";
  std::string error;
  *scene = mps::PlanningScene::create(mps::panda::readFile(kPandaUrdf), mps::panda::options(kPandaUrdf), &error);
  ASSERT_NE(*scene, nullptr) << error;
}

/// pybullet_data's KUKA iiwa, its seven joints controlled, its meshes next to its URDF; nullptr with *error.
std::unique_ptr<mps::RobotModel> iiwaModel(std::string* error) {
  const std::string data = pybulletData();
  mps::RobotModelOptions o;
  for (int i = 1; i <= 7; ++i) o.joint_names.push_back("lbr_iiwa_joint_" + std::to_string(i));
  o.mesh_base_dir = data + "/kuka_iiwa";
  return mps::RobotModel::fromUrdf(mps::panda::readFile(data + "/kuka_iiwa/model.urdf"), o, error);
}

double support(const std::vector<Vector3d>& pts, const Vector3d& u) {
  double best = -1e300;
  for (const auto& p : pts) best = std::max(best, u.dot(p));
  return best;
}

Vector3d randomUnit(std::mt19937* rng) {
  std::normal_distribution<double> n(0.0, 1.0);
  Vector3d u(n(*rng), n(*rng), n(*rng));
  return u.normalized();
}

/// Checks the hull's invariants against its input; returns the largest distance above a face of an input point
/// that is not one of the hull's points (loose points are kept in `vertices`, so their hull contains them).
double checkHull(const mps::ConvexHull& h, const std::vector<Vector3d>& input) {
  EXPECT_FALSE(h.degenerate);
  EXPECT_EQ(h.faces.size(), h.normals.size());
  // Every hull point is an input point.
  for (const auto& v : h.vertices) {
    bool found = false;
    for (const auto& p : input) found |= (p - v).norm() == 0.0;
    EXPECT_TRUE(found);
  }
  // Closed triangulated sphere: every directed edge once, its reverse once; Euler V - E + F = 2.
  std::set<std::pair<int, int>> edges;
  for (const auto& f : h.faces) {
    for (int e = 0; e < 3; ++e) EXPECT_TRUE(edges.insert({f[e], f[(e + 1) % 3]}).second);
  }
  for (const auto& e : edges) EXPECT_TRUE(edges.count({e.second, e.first}));
  const long nv = static_cast<long>(h.face_vertices), ne = static_cast<long>(edges.size() / 2);
  EXPECT_EQ(nv - ne + static_cast<long>(h.faces.size()), 2);
  // Convex, and every other input point inside every face plane.
  std::set<std::array<double, 3>> kept;
  for (const auto& v : h.vertices) kept.insert({v.x(), v.y(), v.z()});
  double worst = -1e300;
  for (std::size_t f = 0; f < h.faces.size(); ++f) {
    const Vector3d& a = h.vertices[h.faces[f][0]];
    for (std::size_t k = 0; k < h.face_vertices; ++k) EXPECT_LE(h.normals[f].dot(h.vertices[k] - a), 1e-9);
    for (const auto& p : input) {
      if (!kept.count({p.x(), p.y(), p.z()})) worst = std::max(worst, h.normals[f].dot(p - a));
    }
  }
  return worst;
}

void writeFile(const std::string& path, const std::string& text) {
  std::ofstream out(path, std::ios::binary);
  out << text;
}

std::string tempPath(const std::string& name) {
  const char* tmp = std::getenv("TMPDIR");
  return std::string(tmp ? tmp : "/tmp") + "/moverl_test_geometry_" + std::to_string(::getpid()) + "_" + name;
}

}  // namespace

TEST(ConvexHull, RandomCloudIsExact) {
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> u(-0.2, 0.2);
  for (int trial = 0; trial < 20; ++trial) {
    std::vector<Vector3d> pts;
    for (int i = 0; i < 500; ++i) pts.emplace_back(u(rng), u(rng), u(rng) * 0.3);
    const mps::ConvexHull h = mps::computeConvexHull(pts);
    EXPECT_LE(checkHull(h, pts), 1e-12);
    // Same support function as the whole cloud in every direction: no extreme point was lost.
    for (int k = 0; k < 200; ++k) {
      const Vector3d d = randomUnit(&rng);
      EXPECT_NEAR(support(h.vertices, d), support(pts, d), 1e-15);
    }
  }
}

TEST(ConvexHull, TessellatedCylinderWithFloatNoise) {
  // The kind of mesh that broke the old vertex selection (issue #15): a finely tessellated round link whose many
  // cap vertices are coplanar and whose coordinates went through float.
  std::mt19937 rng(5);
  std::uniform_real_distribution<double> jitter(-1e-7, 1e-7);
  std::vector<Vector3d> pts;
  for (int i = 0; i < 256; ++i) {
    const double a = 2 * M_PI * i / 256;
    for (double z : {-0.1, -0.05, 0.0, 0.05, 0.1}) {
      const Vector3d p(0.068 * std::cos(a) + jitter(rng), 0.068 * std::sin(a), z);
      pts.emplace_back(static_cast<float>(p.x()), static_cast<float>(p.y()), static_cast<float>(p.z()));
    }
    for (double r : {0.02, 0.04}) {
      pts.emplace_back(static_cast<float>(r * std::cos(a)), static_cast<float>(r * std::sin(a)), 0.1f);
    }
  }
  const mps::ConvexHull h = mps::computeConvexHull(pts);
  EXPECT_LE(checkHull(h, pts), 1e-12);
  EXPECT_LE(h.vertices.size() - h.face_vertices, h.face_vertices / 20) << "too many loose points";
  for (int k = 0; k < 2000; ++k) {
    const Vector3d d = randomUnit(&rng);
    EXPECT_GE(support(h.vertices, d), support(pts, d) - 1e-15);
  }
}

TEST(ConvexHull, DegenerateInputsKeepEveryPoint) {
  std::vector<Vector3d> flat;  // a square grid in the plane z = 0.1
  for (int i = 0; i < 5; ++i) {
    for (int j = 0; j < 5; ++j) flat.emplace_back(0.01 * i, 0.01 * j, 0.1);
  }
  mps::ConvexHull h = mps::computeConvexHull(flat);
  EXPECT_TRUE(h.degenerate);
  EXPECT_EQ(h.vertices.size(), 25u);
  h = mps::computeConvexHull({Vector3d(0, 0, 0), Vector3d(1, 1, 1), Vector3d(2, 2, 2), Vector3d(3, 3, 3)});
  EXPECT_TRUE(h.degenerate);  // collinear
  h = mps::computeConvexHull({Vector3d(0, 0, 0), Vector3d(1, 0, 0), Vector3d(1, 0, 0), Vector3d(0, 1, 0)});
  EXPECT_TRUE(h.degenerate);
  EXPECT_EQ(h.vertices.size(), 3u);  // duplicates merged
  // A box given with duplicated corners and interior points: 8 vertices.
  std::vector<Vector3d> box;
  for (int k = 0; k < 3; ++k) {
    for (double x : {-1.0, 1.0}) {
      for (double y : {-2.0, 2.0}) {
        for (double z : {-0.5, 0.5}) box.emplace_back(x, y, z);
      }
    }
    box.emplace_back(0.1 * k, 0.0, 0.0);
    box.emplace_back(1.0, 0.0, 0.0);  // on a face
  }
  h = mps::computeConvexHull(box);
  EXPECT_LE(checkHull(h, box), 1e-12);
  EXPECT_EQ(h.vertices.size(), 8u);
}

TEST(ConvexHull, InflationOfABoxIsTight) {
  // Box corners have a normal cone of an octant: one point would overshoot by sqrt(3); the sub-cones keep it <= 25 %.
  std::vector<Vector3d> box;
  for (double x : {-0.1, 0.1}) {
    for (double y : {-0.05, 0.05}) {
      for (double z : {-0.02, 0.02}) box.emplace_back(x, y, z);
    }
  }
  const mps::ConvexHull h = mps::computeConvexHull(box);
  ASSERT_FALSE(h.degenerate);
  const double r = 0.01;
  const std::vector<Vector3d> inflated = mps::inflateHull(h, r);
  std::mt19937 rng(2);
  double worst = 0.0;
  for (int k = 0; k < 20000; ++k) {
    const Vector3d d = randomUnit(&rng);
    const double grow = support(inflated, d) - support(h.vertices, d);
    EXPECT_GE(grow, r * (1 - 1e-12));
    worst = std::max(worst, grow / r);
  }
  EXPECT_LE(worst, 1.25 + 1e-9);
  EXPECT_LE(inflated.size(), 8u * 20u);
}

TEST(ConvexHull, InflationContainsTheMinkowskiSum) {
  std::mt19937 rng(11);
  std::uniform_real_distribution<double> u(-0.1, 0.1);
  std::vector<Vector3d> pts;
  for (int i = 0; i < 300; ++i) pts.emplace_back(u(rng), 0.2 * u(rng), 3 * u(rng));  // a long, thin, sharp cloud
  const mps::ConvexHull h = mps::computeConvexHull(pts);
  const double r = 0.004;
  const std::vector<Vector3d> inflated = mps::inflateHull(h, r);
  for (int k = 0; k < 5000; ++k) {
    const Vector3d d = randomUnit(&rng);
    const double grow = support(inflated, d) - support(h.vertices, d);
    EXPECT_GE(grow, r * (1 - 1e-12)) << "direction " << d.transpose();
    EXPECT_LE(grow, 1.2585 * r);  // at most the icosahedron's 26 % more than needed
  }
  // Degenerate hulls (a flat square): icosahedra around every point, still a superset.
  std::vector<Vector3d> flat = {Vector3d(0, 0, 0), Vector3d(1, 0, 0), Vector3d(0, 1, 0), Vector3d(1, 1, 0)};
  const mps::ConvexHull fh = mps::computeConvexHull(flat);
  ASSERT_TRUE(fh.degenerate);
  const std::vector<Vector3d> finf = mps::inflateHull(fh, r);
  EXPECT_EQ(finf.size(), 48u);
  for (int k = 0; k < 2000; ++k) {
    const Vector3d d = randomUnit(&rng);
    EXPECT_GE(support(finf, d) - support(flat, d), r * (1 - 1e-12));
    EXPECT_LE(support(finf, d) - support(flat, d), 1.2585 * r);
  }
}

TEST(MeshLoader, ObjPiecesFollowObjectsAndGroups) {
  const std::string obj =
      "# two objects, the second split by a group; a bare 'g' (no space) starts nothing, as in PyBullet\n"
      "mtllib x.mtl\n"
      "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\n"
      "v 5 0 0\nv 6 0 0\nv 5 1 0\nv 5 0 1\n"
      "v 9 9 9\n"  // used by no face: not part of any piece
      "o first\nusemtl a\nf 1 2 3\nusemtl b\nf 1/1 2/2 4/4\n"
      "o second\ng\nf 5//1 6//1 7//1\ng part\nf -5 -4 -3 -2\nl 1 2\n";
  std::vector<mps::MeshPiece> pieces;
  std::string error;
  ASSERT_TRUE(mps::parseObj(obj, Vector3d(2, 1, 1), &pieces, &error)) << error;
  ASSERT_EQ(pieces.size(), 3u);
  EXPECT_EQ(pieces[0].name, "first");
  EXPECT_EQ(pieces[0].vertices.size(), 4u);
  EXPECT_EQ(pieces[0].triangles.size(), 2u);  // usemtl does not split
  EXPECT_EQ(pieces[1].name, "second");
  EXPECT_EQ(pieces[1].vertices.size(), 3u);
  EXPECT_EQ(pieces[2].name, "part");
  EXPECT_EQ(pieces[2].vertices.size(), 4u);              // the quad, relative indices
  EXPECT_EQ(pieces[2].triangles.size(), 2u);             // fanned
  EXPECT_EQ(pieces[1].vertices[1], Vector3d(12, 0, 0));  // scaled
  for (const auto& p : pieces) {
    for (const auto& v : p.vertices) EXPECT_NE(v, Vector3d(18, 9, 9));
  }
  pieces.clear();
  EXPECT_FALSE(mps::parseObj("v 0 0 0\nf 1 2 3\n", Vector3d::Ones(), &pieces, &error));
  EXPECT_NE(error.find(":2:"), std::string::npos) << error;
  EXPECT_FALSE(mps::parseObj("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 0 1 2\n", Vector3d::Ones(), &pieces, &error));
  EXPECT_FALSE(mps::parseObj("v 0 0\n", Vector3d::Ones(), &pieces, &error));
  EXPECT_FALSE(mps::parseObj("v 0 0 0\n", Vector3d::Ones(), &pieces, &error));  // no faces
}

TEST(MeshLoader, ColladaUnitAndNodeTransformApplyUpAxisDoesNot) {
  // A unit triangle-pair in millimetres, Z_UP, under a node translated by (10, 20, 30) mm.
  const std::string dae = R"(<?xml version="1.0" encoding="utf-8"?>
<COLLADA xmlns="http://www.collada.org/2005/11/COLLADASchema" version="1.4.1">
  <asset><unit name="millimeter" meter="0.001"/><up_axis>Z_UP</up_axis></asset>
  <library_geometries>
    <geometry id="g" name="g"><mesh>
      <source id="g-pos"><float_array id="g-pos-array" count="12">0 0 0 100 0 0 0 100 0 0 0 100</float_array>
        <technique_common><accessor source="#g-pos-array" count="4" stride="3">
          <param name="X" type="float"/><param name="Y" type="float"/><param name="Z" type="float"/>
        </accessor></technique_common></source>
      <vertices id="g-vtx"><input semantic="POSITION" source="#g-pos"/></vertices>
      <triangles count="2"><input semantic="VERTEX" source="#g-vtx" offset="0"/><p>0 1 2 0 1 3</p></triangles>
    </mesh></geometry>
  </library_geometries>
  <library_visual_scenes><visual_scene id="s" name="s">
    <node id="n" name="n"><matrix>1 0 0 10 0 1 0 20 0 0 1 30 0 0 0 1</matrix>
      <instance_geometry url="#g"/></node>
  </visual_scene></library_visual_scenes>
  <scene><instance_visual_scene url="#s"/></scene>
</COLLADA>
)";
  const std::string path = tempPath("mesh.dae");
  writeFile(path, dae);
  std::vector<mps::MeshPiece> pieces;
  std::string error;
  ASSERT_TRUE(mps::loadMeshPieces(path, Vector3d::Ones(), true, &pieces, &error)) << error;
  std::remove(path.c_str());
  ASSERT_EQ(pieces.size(), 1u);
  std::vector<Vector3d> expected = {Vector3d(0.01, 0.02, 0.03), Vector3d(0.11, 0.02, 0.03), Vector3d(0.01, 0.12, 0.03),
                                    Vector3d(0.01, 0.02, 0.13)};
  ASSERT_EQ(pieces[0].vertices.size(), 4u);
  for (const auto& e : expected) {
    double best = 1e9;
    for (const auto& v : pieces[0].vertices) best = std::min(best, (v - e).norm());
    EXPECT_LT(best, 1e-6) << "missing vertex " << e.transpose();
  }
}

// Issue #15: the scene must contain PyBullet's shape of every iiwa link. PyBullet's shape of a binary STL is the
// convex hull of all its triangle vertices (read here independently of the scene).
TEST(IiwaMeshes, EveryStlVertexIsInsideTheSceneShape) {
  const std::string data = pybulletData();
  ASSERT_FALSE(data.empty()) << "pybullet_data not found at configure time";
  std::string error;
  auto model = iiwaModel(&error);
  ASSERT_NE(model, nullptr) << error;
  mps::FclCheckerOptions co = mps::panda::options(kPandaUrdf).checker;
  co.acm_samples = 0;
  auto checker = mps::FclCollisionChecker::create(*model, co, &error);
  ASSERT_NE(checker, nullptr) << error;
  EXPECT_EQ(checker->degenerateHulls(), 0u);
  std::mt19937 rng(1);
  std::vector<double> q(7);
  for (int i = 0; i < 7; ++i) {
    std::uniform_real_distribution<double> d(model->lowerLimits()[i], model->upperLimits()[i]);
    q[i] = d(rng);
  }
  std::vector<Eigen::Isometry3d> poses;
  model->computeLinkTransforms(q.data(), &poses);
  for (int k = 0; k <= 7; ++k) {
    const std::string link = "lbr_iiwa_link_" + std::to_string(k);
    std::ifstream in(data + "/kuka_iiwa/meshes/link_" + std::to_string(k) + ".stl", std::ios::binary);
    std::string bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    ASSERT_GT(bytes.size(), 84u);
    std::uint32_t n = 0;
    std::memcpy(&n, bytes.data() + 80, 4);
    ASSERT_EQ(bytes.size(), 84u + 50u * n) << link << ": not a binary STL";
    const int l = model->linkIndex(link);
    ASSERT_GE(l, 0);
    const auto& shapes = model->collisionShapes(l);
    ASSERT_EQ(shapes.size(), 1u);
    std::vector<Vector3d> points;
    for (std::uint32_t t = 0; t < n; ++t) {
      for (int v = 0; v < 3; ++v) {
        float xyz[3];
        std::memcpy(xyz, bytes.data() + 84 + 50 * t + 12 + 12 * v, 12);
        points.push_back(poses[l] * shapes[0].origin * Vector3d(xyz[0], xyz[1], xyz[2]));
      }
    }
    std::vector<std::uint8_t> mask;
    checker->linkPointMask(q.data(), l, points, 1e-7, &mask);
    std::size_t outside = 0;
    for (auto m : mask) outside += m == 0;
    EXPECT_EQ(outside, 0u) << link << ": " << outside << " of " << points.size() << " STL vertices outside";
  }
}

// The FCL shapes of hulls walk the hull's edges for their support function: it must give exactly the support of the
// point set, for every Panda collision mesh, its hull and both inflations the checker uses, in every direction.
TEST(FclConvex, SupportEqualsThePointSetsOnEveryPandaMesh) {
  ASSERT_FALSE(kPandaUrdf.empty()) << "pybullet_data (franka_panda/panda.urdf) not found at configure time";
  const std::string meshes = kPandaUrdf.substr(0, kPandaUrdf.rfind('/')) + "/meshes/collision/";
  std::mt19937 rng(7);
  int walked = 0;
  for (const char* name : {"link0", "link1", "link2", "link3", "link4", "link5", "link6", "link7", "hand", "finger"}) {
    std::vector<mps::MeshPiece> pieces;
    std::string error;
    ASSERT_TRUE(mps::loadMeshPieces(meshes + name + ".obj", Vector3d::Ones(), true, &pieces, &error)) << error;
    for (const auto& piece : pieces) {
      const mps::ConvexHull hull = mps::computeConvexHull(piece.vertices);
      for (const std::vector<Vector3d>& pts :
           {piece.vertices, hull.vertices, mps::inflateHull(hull, 0.004), mps::inflateHull(hull, 0.01)}) {
        const auto convex = mps::makeFclConvex(pts);
        walked += pts.size() > 32 && convex->getFaceCount() > 0;  // FCL walks edges above 32 vertices
        for (int k = 0; k < 2000; ++k) {
          const Vector3d u = randomUnit(&rng);
          EXPECT_NEAR(u.dot(convex->findExtremeVertex(u)), support(pts, u), 1e-12) << name;
        }
      }
    }
  }
  EXPECT_GT(walked, 20) << "the hull shapes should use FCL's edge walk";
}

// The self filter answers convex hulls from their faces (robotPointMask's fast path); FCL's sphere test is its oracle.
// Over random Panda configurations and points around the arm, both say the same, except for points within 1e-6 m of
// the padding's boundary (where the two numerical methods may round either way).
TEST(SelfFilter, HullFacesAgreeWithFclOnThePanda) {
  std::unique_ptr<mps::PlanningScene> scene;
  ASSERT_NO_FATAL_FAILURE(loadPandaScene(&scene));
  const mps::FclCollisionChecker& checker = scene->checker();
  const auto& model = scene->model();
  std::mt19937 rng(7);
  std::size_t inside = 0, total = 0;
  for (int trial = 0; trial < 6; ++trial) {
    std::vector<double> q(model.dof());
    for (std::size_t i = 0; i < q.size(); ++i) {
      std::uniform_real_distribution<double> d(model.lowerLimits()[i], model.upperLimits()[i]);
      q[i] = d(rng);
    }
    std::vector<Eigen::AlignedBox3d> boxes;
    checker.robotBoundingBoxes(q.data(), 0.05, &boxes);
    std::vector<Vector3d> points;
    for (const auto& b : boxes) {  // points in and around every shape
      std::uniform_real_distribution<double> x(b.min().x(), b.max().x()), y(b.min().y(), b.max().y()),
          z(b.min().z(), b.max().z());
      for (int k = 0; k < 1500; ++k) points.emplace_back(x(rng), y(rng), z(rng));
    }
    for (double pad : {0.001, 0.01, 0.03, 0.05}) {
      std::vector<std::uint8_t> fast, oracle, below, above;
      checker.robotPointMask(q.data(), points, pad, &fast);
      checker.linkPointMaskFcl(q.data(), -1, points, pad, &oracle);
      checker.linkPointMaskFcl(q.data(), -1, points, pad - 1e-6, &below);
      checker.linkPointMaskFcl(q.data(), -1, points, pad + 1e-6, &above);
      std::size_t unexplained = 0;
      for (std::size_t k = 0; k < points.size(); ++k) {
        inside += fast[k];
        if (fast[k] != oracle[k] && !(below[k] == 0 && above[k] == 1)) ++unexplained;
      }
      total += points.size();
      EXPECT_EQ(unexplained, 0u) << "configuration " << trial << ", padding " << pad;
    }
  }
  EXPECT_GT(inside, total / 20);  // the points do reach into the shapes
}

// A dense cloud (a camera's neighbouring points lie millimetres apart): the self filter answers a point from its
// neighbour's answer where the neighbour's distance to the hull settles it. Lines of points 1 mm apart through every
// shape and its padding: the same answers as FCL's sphere test, except within 1e-6 m of the padding's boundary.
TEST(SelfFilter, DenseCloudsAnswerAsFcl) {
  std::unique_ptr<mps::PlanningScene> scene;
  ASSERT_NO_FATAL_FAILURE(loadPandaScene(&scene));
  const mps::FclCollisionChecker& checker = scene->checker();
  const std::vector<double> q = {0.2, -0.5, 0.1, -2.0, 0.3, 1.8, 0.6};
  ASSERT_EQ(q.size(), scene->model().dof());
  std::vector<Eigen::AlignedBox3d> boxes;
  checker.robotBoundingBoxes(q.data(), 0.02, &boxes);
  std::mt19937 rng(11);
  std::vector<Vector3d> points;
  for (const auto& b : boxes) {
    std::uniform_real_distribution<double> y(b.min().y(), b.max().y()), z(b.min().z(), b.max().z());
    for (int line = 0; line < 12; ++line) {  // along x, as an image row
      const double yy = y(rng), zz = z(rng);
      for (double x = b.min().x(); x <= b.max().x(); x += 0.001) points.emplace_back(x, yy, zz);
    }
  }
  mps::WorkerPool pool(3);
  for (double pad : {0.004, 0.01}) {
    std::vector<std::uint8_t> fast, on_pool, below, above;
    checker.robotPointMask(q.data(), points, pad, &fast);
    checker.robotPointMask(q.data(), points, pad, &on_pool, nullptr, &pool);  // in parts: each part's own answers
    EXPECT_EQ(on_pool, fast) << "padding " << pad;
    checker.linkPointMaskFcl(q.data(), -1, points, pad - 1e-6, &below);
    checker.linkPointMaskFcl(q.data(), -1, points, pad + 1e-6, &above);
    std::size_t inside = 0, outside = 0, wrong = 0;
    for (std::size_t k = 0; k < points.size(); ++k) {
      inside += below[k];
      outside += above[k] == 0;
      if ((fast[k] == 0 && below[k] == 1) || (fast[k] == 1 && above[k] == 0)) ++wrong;
    }
    EXPECT_EQ(wrong, 0u) << "padding " << pad;
    EXPECT_GT(inside, points.size() / 10) << "padding " << pad;  // both answers are common along the lines
    EXPECT_GT(outside, points.size() / 10) << "padding " << pad;
  }
}

// A skip mask leaves its points out (mask 0) and answers the others as without it: the self filter of several
// configurations ORs each one's mask over the points the ones before left.
TEST(SelfFilter, SkippedPointsAreLeftOutAndTheOthersAnsweredAsBefore) {
  std::unique_ptr<mps::PlanningScene> scene;
  ASSERT_NO_FATAL_FAILURE(loadPandaScene(&scene));
  const mps::FclCollisionChecker& checker = scene->checker();
  const std::vector<double> q(scene->model().dof(), 0.3);
  std::vector<Eigen::AlignedBox3d> boxes;
  checker.robotBoundingBoxes(q.data(), 0.05, &boxes);
  std::mt19937 rng(3);
  std::vector<Vector3d> points;
  for (const auto& b : boxes) {
    std::uniform_real_distribution<double> x(b.min().x(), b.max().x()), y(b.min().y(), b.max().y()),
        z(b.min().z(), b.max().z());
    for (int k = 0; k < 300; ++k) points.emplace_back(x(rng), y(rng), z(rng));
  }
  std::vector<std::uint8_t> all, skip(points.size()), some, on_pool, some_on_pool;
  for (std::size_t k = 0; k < skip.size(); ++k) skip[k] = k % 3 == 0;
  checker.robotPointMask(q.data(), points, 0.01, &all);
  checker.robotPointMask(q.data(), points, 0.01, &some, &skip);
  // The points in parts on a pool's threads: the same masks.
  mps::WorkerPool pool(3);
  checker.robotPointMask(q.data(), points, 0.01, &on_pool, nullptr, &pool);
  checker.robotPointMask(q.data(), points, 0.01, &some_on_pool, &skip, &pool);
  EXPECT_EQ(on_pool, all);
  EXPECT_EQ(some_on_pool, some);
  std::size_t hits = 0;
  for (std::size_t k = 0; k < points.size(); ++k) {
    EXPECT_EQ(some[k], skip[k] ? 0 : all[k]) << k;
    hits += all[k] != 0 && skip[k] == 0;
  }
  EXPECT_GT(hits, points.size() / 20);
}

/// A world object of `type` and `dims` at `at`, turned by `turn` rad about (1, 1, 0).
mps::WorldObject turnedShape(const std::string& id, mps::ShapeType type, std::vector<double> dims, const Vector3d& at,
                             double turn) {
  mps::WorldObject o;
  o.id = id;
  o.type = type;
  o.dimensions = std::move(dims);
  o.pose.translation() = at;
  o.pose.linear() = Eigen::AngleAxisd(turn, Vector3d(1, 1, 0).normalized()).toRotationMatrix();
  return o;
}

// The static filter marks the points within its padding of each static world object (a box as its box grown by the
// padding along its axes, a cone as its bounding cylinder), never of a moving one; in parts on a pool's threads the
// mask is the same.
TEST(StaticFilter, MarksPointsNearTheStaticObjectsAndTheSameOnAPool) {
  std::unique_ptr<mps::PlanningScene> scene;
  ASSERT_NO_FATAL_FAILURE(loadPandaScene(&scene));
  std::string error;
  auto checker = mps::FclCollisionChecker::create(scene->model(), scene->checker().options(), &error);
  ASSERT_NE(checker, nullptr) << error;
  std::vector<mps::WorldObject> world = {
      turnedShape("box", mps::ShapeType::kBox, {0.4, 0.2, 0.1}, Vector3d(0.5, 0.0, 0.1), 0.5),
      turnedShape("ball", mps::ShapeType::kSphere, {0.08}, Vector3d(0.5, 0.4, 0.3), 0.0),
      turnedShape("post", mps::ShapeType::kCylinder, {0.3, 0.05}, Vector3d(0.4, -0.4, 0.2), 0.6),
      turnedShape("cone", mps::ShapeType::kCone, {0.3, 0.1}, Vector3d(0.2, 0.4, 0.25), -0.9),
      turnedShape("swinging", mps::ShapeType::kSphere, {0.1}, Vector3d(0.0, 0.0, 0.6), 0.0),
  };
  world.back().motion.type = mps::ObstacleMotion::Type::kOscillate;
  world.back().motion.axis = Vector3d::UnitY();
  world.back().motion.amplitude = 0.3;
  world.back().motion.period = 4.0;
  ASSERT_TRUE(checker->setWorld(world, &error)) << error;
  const double pad = 0.01;
  // Each static object's centre, a point just within its padding and one just beyond (along its local x: the box's
  // face, the ball's surface, the post's and the cone's side), the moving ball's centre; then many random points.
  std::vector<Vector3d> points;
  std::vector<int> expected;
  const double reach_x[4] = {0.2, 0.08, 0.05, 0.1};
  for (int i = 0; i < 4; ++i) {
    const Eigen::Isometry3d& pose = world[i].pose;
    for (const auto& [x, in] : {std::make_pair(0.0, 1), std::make_pair(reach_x[i] + pad - 1e-4, 1),
                                std::make_pair(reach_x[i] + pad + 1e-4, 0)}) {
      points.push_back(pose * Vector3d(x, 0.0, 0.0));
      expected.push_back(in);
    }
  }
  points.push_back(world.back().pose.translation());
  expected.push_back(0);
  const std::size_t known = points.size();
  std::mt19937 rng(5);
  std::uniform_real_distribution<double> x(-0.1, 0.9), y(-0.6, 0.6), z(-0.1, 0.7);
  for (int k = 0; k < 100000; ++k) points.emplace_back(x(rng), y(rng), z(rng));
  std::vector<std::uint8_t> alone, on_pool;
  checker->staticObjectPointMask(points, pad, &alone);
  mps::WorkerPool pool(3);
  checker->staticObjectPointMask(points, pad, &on_pool, &pool);
  for (std::size_t k = 0; k < known; ++k) EXPECT_EQ(alone[k], expected[k]) << "point " << k;
  EXPECT_EQ(on_pool, alone);
  const auto marked = std::count(alone.begin() + known, alone.end(), 1);
  EXPECT_GT(marked, 1000);  // the random points do meet the objects
  EXPECT_LT(marked, 50000);
}

// checkPath leaves out, for a whole segment, the shape pairs a plane at its midpoint separates by more than they can
// move over half of it (FclCheckerOptions::cull_path_pairs), and so do state checks of a prepared segment's ends. They
// must answer exactly as checking every pair at every state: over random segments short and long that meet the world
// (every obstacle shape, turned, and a moving one checked over a window of its motion), the robot itself, or nothing,
// with every kind of request.
void expectSamePairs(const std::vector<mps::ContactPair>& a, const std::vector<mps::ContactPair>& b, int trial) {
  ASSERT_EQ(a.size(), b.size()) << "trial " << trial;
  for (std::size_t k = 0; k < a.size(); ++k) {
    EXPECT_EQ(a[k].a, b[k].a) << "trial " << trial;
    EXPECT_EQ(a[k].b, b[k].b) << "trial " << trial;
    EXPECT_EQ(a[k].depth, b[k].depth) << "trial " << trial;
  }
}

void expectCullingChangesNoAnswer(const mps::RobotModel& model, mps::FclCheckerOptions options,
                                  const std::vector<double>& home, unsigned seed) {
  std::string error;
  options.cull_path_pairs = true;
  auto culled = mps::FclCollisionChecker::create(model, options, &error);
  ASSERT_NE(culled, nullptr) << error;
  options.cull_path_pairs = false;
  auto every = mps::FclCollisionChecker::create(model, options, &error);
  ASSERT_NE(every, nullptr) << error;
  std::vector<mps::WorldObject> world = {
      mps::panda::box("table", 1.5, 0.8, 0.03, 0.35, 0.0, -0.015),
      mps::panda::box("wall", 0.4, 0.005, 0.5, 0.45, 0.0, 0.45),
      turnedShape("ball", mps::ShapeType::kSphere, {0.08}, Vector3d(0.5, 0.25, 0.35), 0.0),
      turnedShape("post", mps::ShapeType::kCylinder, {0.3, 0.05}, Vector3d(0.4, -0.3, 0.2), 0.6),
      turnedShape("cone", mps::ShapeType::kCone, {0.3, 0.1}, Vector3d(0.25, 0.4, 0.25), -0.9),
      turnedShape("swinging", mps::ShapeType::kSphere, {0.06}, Vector3d(0.3, 0.0, 0.6), 0.0),
  };
  world.back().motion.type = mps::ObstacleMotion::Type::kOscillate;
  world.back().motion.axis = Vector3d::UnitY();
  world.back().motion.amplitude = 0.3;
  world.back().motion.period = 4.0;
  ASSERT_TRUE(culled->setWorld(world, &error)) << error;
  ASSERT_TRUE(every->setWorld(world, &error)) << error;
  culled->setMotionWindow(0.0, 0.5);
  every->setMotionWindow(0.0, 0.5);
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> unit(-1.0, 1.0);
  const std::size_t dof = model.dof();
  std::size_t counts[3] = {0, 0, 0}, ends[3] = {0, 0, 0}, states = 0;
  for (int trial = 0; trial < 3000; ++trial) {
    std::vector<double> q0(dof), q1(dof);
    const double reach = std::array<double, 4>{0.02, 0.06, 0.13, 0.6}[trial % 4];  // rad per joint, at most
    for (std::size_t i = 0; i < dof; ++i) {
      const double lo = model.lowerLimits()[i], hi = model.upperLimits()[i];
      const double from = trial % 3 == 0 ? lo + 0.5 * (unit(rng) + 1.0) * (hi - lo) : home[i] + 0.8 * unit(rng);
      q0[i] = std::min(std::max(from, lo), hi);
      q1[i] = std::min(std::max(q0[i] + reach * unit(rng), lo), hi);
    }
    mps::PathCheckRequest request;
    request.find_first = trial % 2 == 0;
    request.check_start = trial % 5 != 0;
    request.check_goal = trial % 7 != 0;
    request.state.max_pairs = std::array<std::size_t, 4>{0, 1, 2, 100}[trial % 3 + (trial % 8 == 0)];  // 100: all
    request.state.compute_depth = trial % 4 == 1;
    request.state.check_self = trial % 11 != 3;
    request.state.check_world = trial % 13 != 4;
    // As validateMotion: the segment prepared, then its ends checked; now and then the moving obstacle's window
    // changes in between (the culling must not outlive the world it was made for).
    const bool moved_window = trial % 9 == 5;
    culled->prepareSegment(q0.data(), q1.data());
    if (moved_window) {
      culled->setMotionWindow(1.0, 3.0);
      every->setMotionWindow(1.0, 3.0);
    }
    for (const std::vector<double>* q : {&q1, &q0}) {
      mps::CollisionResult sa, sb;
      culled->checkState(q->data(), request.state, &sa);
      every->checkState(q->data(), request.state, &sb);
      ASSERT_EQ(sa.status, sb.status) << "trial " << trial;
      expectSamePairs(sa.pairs, sb.pairs, trial);
      ends[static_cast<int>(sa.status)] += 1;
    }
    mps::PathCheckResult a, b;
    culled->checkPath(q0.data(), q1.data(), request, &a);
    every->checkPath(q0.data(), q1.data(), request, &b);
    if (moved_window) {
      culled->setMotionWindow(0.0, 0.5);
      every->setMotionWindow(0.0, 0.5);
    }
    ASSERT_EQ(a.status, b.status) << "trial " << trial;
    ASSERT_EQ(a.checked_states, b.checked_states) << "trial " << trial;
    ASSERT_EQ(a.collision_fraction, b.collision_fraction) << "trial " << trial;
    ASSERT_EQ(a.last_valid_fraction, b.last_valid_fraction) << "trial " << trial;
    expectSamePairs(a.pairs, b.pairs, trial);
    ++counts[static_cast<int>(a.status)];
    states += a.checked_states;
  }
  // Every kind of answer was asked for, and the segments were long enough to cull on.
  EXPECT_GT(counts[0], 300u) << "free";
  EXPECT_GT(counts[1], 100u) << "self";
  EXPECT_GT(counts[2], 300u) << "world";
  EXPECT_GT(states, 3000u * 8);
  EXPECT_GT(ends[0], 1000u) << "free ends";
  EXPECT_GT(ends[1] + ends[2], 500u) << "colliding ends";
}

TEST(PathCulling, ThePandaGetsTheSameAnswersAsFromEveryPairAtEveryState) {
  std::unique_ptr<mps::RobotModel> model;
  mps::PlanningSceneOptions o;
  ASSERT_NO_FATAL_FAILURE(loadPandaModel(&model, &o));
  expectCullingChangesNoAnswer(*model, o.checker, {0.0, -0.785, 0.0, -2.356, 0.0, 1.571, 0.785}, 7);
}

TEST(PathCulling, TheIiwaGetsTheSameAnswersAsFromEveryPairAtEveryState) {
  ASSERT_FALSE(pybulletData().empty()) << "pybullet_data not found at configure time";
  std::string error;
  auto model = iiwaModel(&error);
  ASSERT_NE(model, nullptr) << error;
  expectCullingChangesNoAnswer(*model, mps::panda::options(kPandaUrdf).checker, {0.0, 0.5, 0.0, -1.5, 0.0, 1.0, 0.0},
                               11);
}

// The support values the culling's separating planes are certified with, against FCL's GJK: every shape meets a slab
// beyond the plane n . x = support - 1e-6 and not one beyond n . x = support + 1e-6, for every primitive the world
// has and convex hulls, turned and moved, in random directions. (Slabs, not fcl::Halfspace: FCL 0.7's cone/half-space
// test answers wrongly in some directions, where dense sampling of the cone's apex and base circle agrees with
// shapeSupport.)
TEST(PathCulling, ShapeSupportIsWhereGjkSaysTheShapeEnds) {
  std::mt19937 rng(13);
  std::uniform_real_distribution<double> unit(-1.0, 1.0);
  std::vector<Vector3d> cloud;
  for (int k = 0; k < 200; ++k) cloud.emplace_back(0.1 * unit(rng), 0.05 * unit(rng), 0.2 * unit(rng));
  const std::vector<std::shared_ptr<fcl::CollisionGeometryd>> shapes = {
      std::make_shared<fcl::Boxd>(0.3, 0.2, 0.1),
      std::make_shared<fcl::Sphered>(0.1),
      std::make_shared<fcl::Capsuled>(0.05, 0.3),
      std::make_shared<fcl::Cylinderd>(0.1, 0.4),
      std::make_shared<fcl::Coned>(0.1, 0.3),
      mps::makeFclConvex(cloud),
      mps::makeFclConvex(mps::inflateHull(mps::computeConvexHull(cloud), 0.01))};
  constexpr double kGap = 1e-6;
  const fcl::Boxd slab(20.0, 20.0, 2.0);  // its face towards the shape at z = -1, in its frame
  for (std::size_t s = 0; s < shapes.size(); ++s) {
    for (int k = 0; k < 300; ++k) {
      Eigen::Isometry3d tf = Eigen::Isometry3d::Identity();
      tf.linear() = Eigen::AngleAxisd(3.0 * unit(rng), randomUnit(&rng)).toRotationMatrix();
      tf.translation() = Vector3d(unit(rng), unit(rng), unit(rng));
      const Vector3d n = randomUnit(&rng);
      const double support = mps::shapeSupport(*shapes[s], tf, n);
      ASSERT_TRUE(std::isfinite(support)) << "shape " << s;
      ASSERT_TRUE(mps::hasShapeSupport(*shapes[s])) << "shape " << s;
      // The slab {x : d <= n . x <= d + 2} (20 m wide): the shape meets it when it reaches past n . x = d.
      auto reaches = [&](double d) {
        fcl::Transform3d at = fcl::Transform3d::Identity();
        at.linear() = Eigen::Quaterniond::FromTwoVectors(Vector3d::UnitZ(), n).toRotationMatrix();
        at.translation() = (d + 1.0) * n;
        fcl::CollisionRequestd request;
        fcl::CollisionResultd result;
        fcl::collide(shapes[s].get(), fcl::Transform3d(tf.matrix()), &slab, at, request, result);
        return result.isCollision();
      };
      EXPECT_TRUE(reaches(support - kGap)) << "shape " << s << ": support too large, direction " << n.transpose();
      EXPECT_FALSE(reaches(support + kGap)) << "shape " << s << ": support too small, direction " << n.transpose();
    }
  }
  fcl::Halfspaced plane(Vector3d::UnitZ(), 0.0);
  EXPECT_TRUE(std::isinf(mps::shapeSupport(plane, Eigen::Isometry3d::Identity(), Vector3d::UnitX())));
  EXPECT_FALSE(mps::hasShapeSupport(plane));  // the two lists of fcl_convex.cpp agree
}

// The motion bound counts a prismatic joint's travel within its limits: a segment with one beyond them (a measured
// state past a limit) is not culled. A slider held 0.5 m out on a 0.1 m rail swings into a box at the segment's end; a
// bound from the rail's limits would have left the pair out at every state.
TEST(PathCulling, APrismaticJointBeyondItsLimitsIsNotCulled) {
  const std::string urdf = R"(<robot name="swing">
  <link name="base"/>
  <link name="arm"/>
  <link name="slider"><collision><geometry><box size="0.04 0.04 0.04"/></geometry></collision></link>
  <joint name="turn" type="revolute"><parent link="base"/><child link="arm"/><axis xyz="0 0 1"/>
    <limit lower="-3" upper="3" effort="1" velocity="1"/></joint>
  <joint name="slide" type="prismatic"><parent link="arm"/><child link="slider"/><origin xyz="0.05 0 0"/>
    <axis xyz="1 0 0"/><limit lower="0" upper="0.1" effort="1" velocity="1"/></joint>
</robot>)";
  mps::RobotModelOptions ro;
  ro.joint_names = {"turn", "slide"};
  std::string error;
  auto model = mps::RobotModel::fromUrdf(urdf, ro, &error);
  ASSERT_NE(model, nullptr) << error;
  mps::FclCheckerOptions co = mps::panda::options(kPandaUrdf).checker;
  co.acm_samples = 0;
  auto culled = mps::FclCollisionChecker::create(*model, co, &error);
  ASSERT_NE(culled, nullptr) << error;
  co.cull_path_pairs = false;
  auto every = mps::FclCollisionChecker::create(*model, co, &error);
  ASSERT_NE(every, nullptr) << error;
  const double out = 0.5;  // m along the rail, beyond its 0.1 m
  const Vector3d end(0.05 + out, 0.0, 0.0);
  const Vector3d at_goal = Eigen::AngleAxisd(0.5, Vector3d::UnitZ()) * end;
  const std::vector<mps::WorldObject> world = {
      mps::panda::box("box", 0.05, 0.05, 0.05, at_goal.x(), at_goal.y(), at_goal.z())};
  ASSERT_TRUE(culled->setWorld(world, &error)) << error;
  ASSERT_TRUE(every->setWorld(world, &error)) << error;
  const std::vector<double> q0 = {-0.5, out}, q1 = {0.5, out};
  // The bound within the rail's limits is far below how far the slider swings from the midpoint to the box.
  const std::vector<double> mid = {0.0, out};
  ASSERT_LT(culled->segmentMotionBound(mid.data(), q1.data(), -1, model->linkIndex("slider")),
            0.5 * ((Eigen::AngleAxisd(0.5, Vector3d::UnitZ()) * end) - end).norm());
  mps::PathCheckRequest request;
  mps::PathCheckResult a, b;
  culled->checkPath(q0.data(), q1.data(), request, &a);
  every->checkPath(q0.data(), q1.data(), request, &b);
  EXPECT_EQ(b.status, mps::CollisionStatus::kWorld);
  EXPECT_EQ(a.status, b.status);
  EXPECT_EQ(a.collision_fraction, b.collision_fraction);
}

// A world object's pose must be a rigid transform: the culling's support values and FCL's shapes read its rotation.
TEST(PathCulling, AnObstacleWhosePoseIsNotRigidIsRefused) {
  std::unique_ptr<mps::RobotModel> model;
  mps::PlanningSceneOptions o;
  ASSERT_NO_FATAL_FAILURE(loadPandaModel(&model, &o));
  mps::FclCheckerOptions co = o.checker;
  co.acm_samples = 0;
  std::string error;
  auto checker = mps::FclCollisionChecker::create(*model, co, &error);
  ASSERT_NE(checker, nullptr) << error;
  mps::WorldObject skewed = mps::panda::box("skewed", 0.1, 0.1, 0.1, 0.5, 0.0, 0.3);
  skewed.pose.linear() = Eigen::Vector3d(1.0, 2.0, 1.0).asDiagonal();
  EXPECT_FALSE(checker->setWorld({skewed}, &error));
  EXPECT_NE(error.find("not a rotation"), std::string::npos) << error;
  mps::WorldObject mirrored = mps::panda::box("mirrored", 0.1, 0.1, 0.1, 0.5, 0.0, 0.3);
  mirrored.pose.linear() = Eigen::Vector3d(1.0, 1.0, -1.0).asDiagonal();
  EXPECT_FALSE(checker->setWorld({mirrored}, &error));
  mps::WorldObject turned = mps::panda::box("turned", 0.1, 0.1, 0.1, 0.5, 0.0, 0.3);
  turned.pose.linear() = Eigen::AngleAxisd(0.7, Vector3d(1, 2, 3).normalized()).toRotationMatrix();
  EXPECT_TRUE(checker->setWorld({turned}, &error)) << error;
}

// The bound the culling rests on: the distance between a point of one link's (padded) shapes and a point of another's
// (or a point fixed in the base frame, where world obstacles are) changes by no more than segmentMotionBound says
// between any two states of a segment, over random segments of the Panda and the iiwa and every pair of links.
void expectMotionBoundHolds(const mps::RobotModel& model, const mps::FclCheckerOptions& options, unsigned seed) {
  std::string error;
  mps::FclCheckerOptions o = options;
  o.acm_samples = 0;
  auto checker = mps::FclCollisionChecker::create(model, o, &error);
  ASSERT_NE(checker, nullptr) << error;
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> unit(0.0, 1.0);
  const std::size_t dof = model.dof();
  const int n_links = static_cast<int>(model.linkNames().size());
  std::vector<std::vector<Vector3d>> points(n_links);  // per link, points of its shapes pushed out by the padding
  for (int l = 0; l < n_links; ++l) {
    for (const auto& g : checker->linkGeometry(l)) {
      for (std::size_t k = 0; k < g.vertices.size(); k += 1 + g.vertices.size() / 12) {
        points[l].push_back(g.origin * g.vertices[k] + options.self_padding * randomUnit(&rng));
      }
    }
  }
  std::vector<Vector3d> fixed;  // base-frame points around the robot
  for (int k = 0; k < 12; ++k) fixed.push_back(Vector3d(2.0 * unit(rng) - 1.0, 2.0 * unit(rng) - 1.0, 1.5 * unit(rng)));
  std::size_t compared = 0;
  double tightest = 0.0;  // the largest change / bound seen
  for (int trial = 0; trial < 100; ++trial) {
    std::vector<double> q0(dof), q1(dof), qa(dof), qb(dof);
    for (std::size_t i = 0; i < dof; ++i) {
      const double lo = model.lowerLimits()[i], hi = model.upperLimits()[i];
      q0[i] = lo + unit(rng) * (hi - lo);
      q1[i] = std::min(std::max(q0[i] + 1.2 * (unit(rng) - 0.5), lo), hi);
    }
    const double ta = unit(rng), tb = unit(rng);
    for (std::size_t i = 0; i < dof; ++i) {
      qa[i] = q0[i] + ta * (q1[i] - q0[i]);
      qb[i] = q0[i] + tb * (q1[i] - q0[i]);
    }
    std::vector<Eigen::Isometry3d> pa, pb;
    model.computeLinkTransforms(qa.data(), &pa);
    model.computeLinkTransforms(qb.data(), &pb);
    for (int a = -1; a < n_links; ++a) {
      for (int b = 0; b < n_links; ++b) {
        if (a == b || points[b].empty()) continue;
        const double bound = checker->segmentMotionBound(qa.data(), qb.data(), a, b);
        for (const Vector3d& x : points[b]) {
          const Vector3d xa = pa[b] * x, xb = pb[b] * x;
          // The other end: a point of link a's shapes, or of the base frame around the robot.
          for (const Vector3d& y : a < 0 ? fixed : points[a]) {
            const double ya_gap = (xa - (a < 0 ? y : Vector3d(pa[a] * y))).norm();
            const double yb_gap = (xb - (a < 0 ? y : Vector3d(pb[a] * y))).norm();
            const double change = std::fabs(ya_gap - yb_gap);
            ASSERT_LE(change, bound + 1e-12) << model.linkNames()[b] << " and "
                                             << (a < 0 ? "the base" : model.linkNames()[a]) << ", trial " << trial;
            if (bound > 0.0) tightest = std::max(tightest, change / bound);
            ++compared;
          }
        }
      }
    }
  }
  EXPECT_GT(compared, 100000u);
  EXPECT_GT(tightest, 0.2);  // the bound is not vacuous
}

TEST(PathCulling, ThePandasPointsMoveNoFartherThanTheBound) {
  std::unique_ptr<mps::RobotModel> model;
  mps::PlanningSceneOptions o;
  ASSERT_NO_FATAL_FAILURE(loadPandaModel(&model, &o));
  expectMotionBoundHolds(*model, o.checker, 3);
}

TEST(PathCulling, TheIiwasPointsMoveNoFartherThanTheBound) {
  ASSERT_FALSE(pybulletData().empty()) << "pybullet_data not found at configure time";
  std::string error;
  auto model = iiwaModel(&error);
  ASSERT_NE(model, nullptr) << error;
  expectMotionBoundHolds(*model, mps::panda::options(kPandaUrdf).checker, 5);
}

int main(int argc, char** argv) {
  ::testing::InitGoogleTest(&argc, argv);
  return RUN_ALL_TESTS();
}
