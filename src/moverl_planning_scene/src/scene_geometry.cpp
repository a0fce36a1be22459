/**
 * \file scene_geometry.cpp
 * \brief ROS-free command-line view of the planning scene's robot collision geometry, for tests and the parity tool
 *        (which compare it with PyBullet's in Python).
 *
 *   scene_geometry --urdf robot.urdf --joints j1,j2,... [--base-link L] [--fixed j=v,...] [--mesh-dir DIR]
 *                  [--mesh-mode convex_hull|triangles] [--scene-config planning_scene.yaml]
 *
 * The checker's tunables come from --scene-config (default: the repo's config/planning_scene.yaml); --mesh-mode
 * overrides its mesh_mode. No allowed-collision matrix is computed (geometry only).
 *
 * Then one command per line on stdin, one answer line per command on stdout:
 *   q v1 ... vn          set the configuration (controlled joints, in --joints order)      -> "ok"
 *   in LINK TOL x y z    is the point (base frame) within TOL metres of LINK's collision shapes in the current
 *                        configuration (FCL, the shapes the checker uses)?                  -> "1" or "0"
 *   pose LINK            the link frame in the base frame                  -> 12 numbers (R row-major, then t)
 *   geometry             every link's collision geometry, as one JSON line (link frame; see LinkGeometry)
 * Errors: "error <message>" (the program goes on). Exit code 2 when the robot cannot be loaded.
 */
#include <algorithm>
#include <fstream>
#include <iomanip>
#include <iostream>
#include <sstream>
#include <string>
#include <vector>

#include "moverl_planning_scene/fcl_collision_checker.h"
#include "moverl_planning_scene/robot_model.h"
#include "moverl_planning_scene/tunables.h"

namespace mps = moverl_planning_scene;

namespace {

std::vector<std::string> split(const std::string& s, char sep) {
  std::vector<std::string> out;
  std::stringstream ss(s);
  std::string item;
  while (std::getline(ss, item, sep)) {
    if (!item.empty()) out.push_back(item);
  }
  return out;
}

const char* typeName(mps::ShapeType t) {
  switch (t) {
    case mps::ShapeType::kBox:
      return "box";
    case mps::ShapeType::kSphere:
      return "sphere";
    case mps::ShapeType::kCylinder:
      return "cylinder";
    case mps::ShapeType::kCone:
      return "cone";
    case mps::ShapeType::kMesh:
      return "mesh";
  }
  return "?";
}

std::string jsonString(const std::string& s) {
  std::string out = "\"";
  for (char c : s) {
    if (c == '"' || c == '\\') out += '\\';
    out += c;
  }
  return out + "\"";
}

void printGeometry(const mps::RobotModel& model, const mps::FclCollisionChecker& checker) {
  std::ostringstream o;
  o << std::setprecision(17) << "{";
  bool first_link = true;
  for (std::size_t l = 0; l < model.linkNames().size(); ++l) {
    const auto geoms = checker.linkGeometry(static_cast<int>(l));
    if (geoms.empty()) continue;
    o << (first_link ? "" : ",") << jsonString(model.linkNames()[l]) << ":[";
    first_link = false;
    for (std::size_t k = 0; k < geoms.size(); ++k) {
      const mps::LinkGeometry& g = geoms[k];
      o << (k ? "," : "") << "{\"type\":\"" << typeName(g.type) << "\",\"piece\":" << jsonString(g.piece)
        << ",\"origin\":[";
      for (int r = 0; r < 3; ++r) {
        for (int c = 0; c < 4; ++c) o << (r || c ? "," : "") << g.origin.matrix()(r, c);
      }
      o << "],\"dims\":[" << g.dims.x() << "," << g.dims.y() << "," << g.dims.z() << "],\"vertices\":[";
      for (std::size_t v = 0; v < g.vertices.size(); ++v) {
        const auto& p = g.vertices[v];
        o << (v ? "," : "") << "[" << p.x() << "," << p.y() << "," << p.z() << "]";
      }
      o << "]}";
    }
    o << "]";
  }
  o << "}";
  std::cout << o.str() << "\n";
}

}  // namespace

int main(int argc, char** argv) {
  std::string urdf_path, mesh_mode, scene_config = MOVERL_CONFIG_DIR "/planning_scene.yaml";
  mps::RobotModelOptions options;
  for (int i = 1; i + 1 < argc; i += 2) {
    const std::string key = argv[i], value = argv[i + 1];
    if (key == "--urdf") {
      urdf_path = value;
    } else if (key == "--joints") {
      options.joint_names = split(value, ',');
    } else if (key == "--base-link") {
      options.base_link = value;
    } else if (key == "--fixed") {
      for (const auto& kv : split(value, ',')) {
        const auto eq = kv.find('=');
        if (eq == std::string::npos) {
          std::cerr << "--fixed wants joint=value pairs, got '" << kv << "'\n";
          return 2;
        }
        try {
          options.fixed_joint_positions[kv.substr(0, eq)] = std::stod(kv.substr(eq + 1));
        } catch (const std::exception&) {
          std::cerr << "--fixed: '" << kv << "' is not joint=number\n";
          return 2;
        }
      }
    } else if (key == "--mesh-dir") {
      options.mesh_base_dir = value;
    } else if (key == "--mesh-mode") {
      mesh_mode = value;
    } else if (key == "--scene-config") {
      scene_config = value;
    } else {
      std::cerr << "unknown option " << key << "\n";
      return 2;
    }
  }
  std::ifstream in(urdf_path);
  if (urdf_path.empty() || !in) {
    std::cerr << "usage: scene_geometry --urdf robot.urdf --joints j1,j2,... (cannot read '" << urdf_path << "')\n";
    return 2;
  }
  std::stringstream text;
  text << in.rdbuf();
  if (options.mesh_base_dir.empty()) {
    const auto slash = urdf_path.rfind('/');
    options.mesh_base_dir = slash == std::string::npos ? "." : urdf_path.substr(0, slash);
  }
  std::string error;
  auto model = mps::RobotModel::fromUrdf(text.str(), options, &error);
  if (!model) {
    std::cerr << "cannot load the robot: " << error << "\n";
    return 2;
  }
  mps::PlanningSceneOptions scene_options;
  const auto tunables = mps::YamlTunables::fromFile(scene_config, &error);
  if (!tunables) {
    std::cerr << "cannot read the scene's tunables: " << error << "\n";
    return 2;
  }
  try {
    mps::readSceneTunables(*tunables, &scene_options);
  } catch (const std::exception& e) {
    std::cerr << e.what() << "\n";
    return 2;
  }
  mps::FclCheckerOptions checker_options = scene_options.checker;
  checker_options.acm_samples = 0;  // geometry only
  if (mesh_mode == "triangles") {
    checker_options.mesh_mode = mps::MeshMode::kTriangles;
  } else if (mesh_mode == "convex_hull") {
    checker_options.mesh_mode = mps::MeshMode::kConvexHull;
  } else if (!mesh_mode.empty()) {
    std::cerr << "--mesh-mode must be convex_hull or triangles, not '" << mesh_mode << "'\n";
    return 2;
  }
  auto checker = mps::FclCollisionChecker::create(*model, checker_options, &error);
  if (!checker) {
    std::cerr << "cannot load the collision geometry: " << error << "\n";
    return 2;
  }
  std::vector<double> q(model->dof());
  for (std::size_t i = 0; i < q.size(); ++i) {
    q[i] = std::min(std::max(0.0, model->lowerLimits()[i]), model->upperLimits()[i]);
  }
  std::cout << std::setprecision(17);
  std::string line;
  while (std::getline(std::cin, line)) {
    std::istringstream cmd(line);
    std::string op;
    if (!(cmd >> op)) continue;
    if (op == "q") {
      std::vector<double> v;
      double x;
      while (cmd >> x) v.push_back(x);
      if (v.size() != q.size()) {
        std::cout << "error expected " << q.size() << " joint values, got " << v.size() << "\n";
        continue;
      }
      q = v;
      std::cout << "ok\n";
    } else if (op == "in") {
      std::string link;
      double tol;
      Eigen::Vector3d p;
      if (!(cmd >> link >> tol >> p.x() >> p.y() >> p.z())) {
        std::cout << "error usage: in LINK TOL x y z\n";
        continue;
      }
      const int index = model->linkIndex(link);
      if (index < 0) {
        std::cout << "error unknown link " << link << "\n";
        continue;
      }
      std::vector<std::uint8_t> mask;
      checker->linkPointMask(q.data(), index, {p}, tol, &mask);
      std::cout << int(mask[0]) << "\n";
    } else if (op == "pose") {
      std::string link;
      cmd >> link;
      const int index = model->linkIndex(link);
      if (index < 0) {
        std::cout << "error unknown link " << link << "\n";
        continue;
      }
      std::vector<Eigen::Isometry3d> poses;
      model->computeLinkTransforms(q.data(), &poses);
      const Eigen::Matrix4d m = poses[index].matrix();
      for (int r = 0; r < 3; ++r) {
        for (int c = 0; c < 3; ++c) std::cout << m(r, c) << " ";
      }
      std::cout << m(0, 3) << " " << m(1, 3) << " " << m(2, 3) << "\n";
    } else if (op == "geometry") {
      printGeometry(*model, *checker);
    } else {
      std::cout << "error unknown command " << op << "\n";
    }
    std::cout.flush();
  }
  return 0;
}
