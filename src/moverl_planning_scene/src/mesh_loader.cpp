#include "moverl_planning_scene/mesh_loader.h"

#include <assimp/config.h>
#include <assimp/postprocess.h>
#include <assimp/scene.h>

#include <algorithm>
#include <assimp/Importer.hpp>
#include <cctype>
#include <cstdlib>
#include <fstream>
#include <sstream>
#include <unordered_map>

namespace moverl_planning_scene {
namespace {

bool isBlank(char c) { return c == ' ' || c == '\t'; }

std::string lowerExtension(const std::string& path) {
  const std::size_t dot = path.rfind('.');
  if (dot == std::string::npos || path.find('/', dot) != std::string::npos) return "";
  std::string ext = path.substr(dot);
  std::transform(ext.begin(), ext.end(), ext.begin(), [](unsigned char c) { return std::tolower(c); });
  return ext;
}

/// Faces of one OBJ block (vertex indices, 0-based, into the file's vertex list).
struct ObjBlock {
  std::string name;
  std::vector<std::vector<int>> faces;
};

/// Keeps the vertices the faces use, renumbered, and fans each face into triangles.
MeshPiece blockToPiece(const ObjBlock& block, const std::vector<Eigen::Vector3d>& vertices) {
  MeshPiece piece;
  piece.name = block.name;
  std::unordered_map<int, int> used;
  auto local = [&](int v) {
    const auto it = used.emplace(v, static_cast<int>(piece.vertices.size()));
    if (it.second) piece.vertices.push_back(vertices[v]);
    return it.first->second;
  };
  for (const auto& f : block.faces) {
    const int a = local(f[0]);
    for (std::size_t k = 1; k + 1 < f.size(); ++k) piece.triangles.push_back({a, local(f[k]), local(f[k + 1])});
  }
  return piece;
}

bool loadWithAssimp(const std::string& path, const Eigen::Vector3d& scale, std::vector<MeshPiece>* pieces,
                    std::string* error) {
  Assimp::Importer importer;
  // PyBullet's COLLADA reader applies <unit> and node transforms but not <up_axis> (nor does rviz); assimp would
  // rotate a Z_UP file into its Y-up convention.
  importer.SetPropertyBool(AI_CONFIG_IMPORT_COLLADA_IGNORE_UP_DIRECTION, true);
  const aiScene* scene =
      importer.ReadFile(path, aiProcess_Triangulate | aiProcess_JoinIdenticalVertices | aiProcess_PreTransformVertices);
  if (scene == nullptr || scene->mNumMeshes == 0) {
    *error = "assimp cannot load mesh '" + path + "': " + importer.GetErrorString();
    return false;
  }
  MeshPiece piece;
  for (unsigned m = 0; m < scene->mNumMeshes; ++m) {
    const aiMesh* mesh = scene->mMeshes[m];
    const int base = static_cast<int>(piece.vertices.size());
    for (unsigned v = 0; v < mesh->mNumVertices; ++v) {
      const aiVector3D& p = mesh->mVertices[v];
      piece.vertices.emplace_back(p.x * scale.x(), p.y * scale.y(), p.z * scale.z());
    }
    for (unsigned f = 0; f < mesh->mNumFaces; ++f) {
      const aiFace& face = mesh->mFaces[f];
      if (face.mNumIndices != 3) continue;  // points/lines
      piece.triangles.push_back({base + static_cast<int>(face.mIndices[0]), base + static_cast<int>(face.mIndices[1]),
                                 base + static_cast<int>(face.mIndices[2])});
    }
  }
  if (piece.vertices.empty()) {
    *error = "mesh '" + path + "' has no vertices";
    return false;
  }
  pieces->push_back(std::move(piece));
  return true;
}

}  // namespace

bool parseObj(const std::string& text, const Eigen::Vector3d& scale, std::vector<MeshPiece>* pieces, std::string* error,
              const std::string& source) {
  std::vector<Eigen::Vector3d> vertices;
  std::vector<ObjBlock> blocks(1);
  std::istringstream in(text);
  std::string line;
  int line_no = 0;
  auto fail = [&](const std::string& why) {
    *error = source + ":" + std::to_string(line_no) + ": " + why;
    return false;
  };
  while (std::getline(in, line)) {
    ++line_no;
    const char* t = line.c_str();
    while (isBlank(*t)) ++t;
    // Keywords are followed by a space or tab, as PyBullet's reader requires (a bare "g" starts no new block there).
    if (t[0] == 'v' && isBlank(t[1])) {
      double xyz[3];
      char* end = const_cast<char*>(t + 2);
      for (double& c : xyz) {
        const char* start = end;
        c = std::strtod(start, &end);
        if (end == start) return fail("a vertex needs 3 coordinates");
      }
      // PyBullet stores OBJ coordinates as float: use the same values.
      vertices.emplace_back(static_cast<float>(xyz[0]) * scale.x(), static_cast<float>(xyz[1]) * scale.y(),
                            static_cast<float>(xyz[2]) * scale.z());
    } else if (t[0] == 'f' && isBlank(t[1])) {
      std::vector<int> face;
      std::istringstream tokens(t + 2);
      std::string tok;
      while (tokens >> tok) {
        const int idx = std::atoi(tok.c_str());  // "v", "v/vt", "v//vn" or "v/vt/vn": the vertex comes first
        const int n = static_cast<int>(vertices.size());
        const int v = idx > 0 ? idx - 1 : n + idx;
        if (idx == 0 || v < 0 || v >= n) return fail("face index '" + tok + "' is not one of the vertices so far");
        face.push_back(v);
      }
      if (face.size() >= 3) blocks.back().faces.push_back(std::move(face));  // points and edges are skipped
    } else if ((t[0] == 'g' || t[0] == 'o') && isBlank(t[1])) {
      std::istringstream tokens(t + 2);
      ObjBlock b;
      tokens >> b.name;
      if (blocks.back().faces.empty()) {
        blocks.back().name = b.name;  // an empty block is no piece: PyBullet only flushes blocks with faces
      } else {
        blocks.push_back(std::move(b));
      }
    }
  }
  for (const ObjBlock& b : blocks) {
    if (!b.faces.empty()) pieces->push_back(blockToPiece(b, vertices));
  }
  if (pieces->empty()) {
    *error = source + ": no faces";
    return false;
  }
  return true;
}

bool loadMeshPieces(const std::string& path, const Eigen::Vector3d& scale, bool split_pieces,
                    std::vector<MeshPiece>* pieces, std::string* error) {
  std::vector<MeshPiece> out;
  if (lowerExtension(path) == ".obj") {
    std::ifstream file(path, std::ios::binary);
    if (!file) {
      *error = "cannot read mesh '" + path + "'";
      return false;
    }
    std::stringstream ss;
    ss << file.rdbuf();
    if (!parseObj(ss.str(), scale, &out, error, path)) return false;
  } else if (!loadWithAssimp(path, scale, &out, error)) {
    return false;
  }
  if (!split_pieces && out.size() > 1) {
    MeshPiece all;
    for (const MeshPiece& p : out) {
      const int base = static_cast<int>(all.vertices.size());
      all.vertices.insert(all.vertices.end(), p.vertices.begin(), p.vertices.end());
      for (const auto& t : p.triangles) all.triangles.push_back({base + t[0], base + t[1], base + t[2]});
    }
    out.assign(1, std::move(all));
  }
  pieces->insert(pieces->end(), std::make_move_iterator(out.begin()), std::make_move_iterator(out.end()));
  return true;
}

}  // namespace moverl_planning_scene
