/**
 * \file mesh_loader.h
 * \brief Collision meshes read as the physics engine (PyBullet's URDF importer) reads them (ROS-free).
 *
 * PyBullet makes one convex hull per *piece* of a collision mesh: a Wavefront OBJ file gives one piece per `o` or `g`
 * block that has faces (V-HACD decompositions are stored this way), an STL or COLLADA file gives one piece of all its
 * vertices. The scene must not split finer than that (the hulls of finer pieces miss the space between them), and
 * splitting coarser only costs false alarms, so OBJ files are read here with the same grouping rules; STL, COLLADA and
 * every other format go through assimp as one piece. COLLADA: the `<unit>` scale and node transforms are applied,
 * the `<up_axis>` is ignored (PyBullet and rviz ignore it too).
 */
#pragma once

#include <Eigen/Core>
#include <array>
#include <string>
#include <vector>

namespace moverl_planning_scene {

/// \brief One piece of a mesh: its vertices (scaled) and triangles (indices into them).
struct MeshPiece {
  std::string name;  ///< OBJ object/group name ("" otherwise)
  std::vector<Eigen::Vector3d> vertices;
  std::vector<std::array<int, 3>> triangles;
};

/// \brief Reads a mesh file (OBJ by its own reader, anything else by assimp), every vertex multiplied by `scale`.
///        OBJ pieces: one per `o`/`g` block with faces, each with only the vertices its faces use; merged into one
///        piece when `split_pieces` is false. Returns false with *error naming the file and the problem.
bool loadMeshPieces(const std::string& path, const Eigen::Vector3d& scale, bool split_pieces,
                    std::vector<MeshPiece>* pieces, std::string* error);

/// \brief Parses Wavefront OBJ text as loadMeshPieces does for .obj files (`source` names it in errors).
bool parseObj(const std::string& text, const Eigen::Vector3d& scale, std::vector<MeshPiece>* pieces, std::string* error,
              const std::string& source = "OBJ text");

}  // namespace moverl_planning_scene
