// gtests of the depth cameras' rasterizer (include/moverl_sim/depth_raster.h), against the geometry it draws.
#include "moverl_sim/depth_raster.h"

#include <gtest/gtest.h>

#include <cmath>
#include <vector>

namespace {
constexpr int kW = 64, kH = 48;
constexpr double kF = 40.0, kCx = 32.0, kCy = 23.0, kNear = 0.1, kFar = 5.0;

struct Mesh {
  std::vector<float> vertices;
  std::vector<int32_t> part;
  std::vector<int32_t> triangles;
  int add(double x, double y, double z, int32_t p) {
    vertices.insert(vertices.end(), {float(x), float(y), float(z)});
    part.push_back(p);
    return int(part.size()) - 1;
  }
  void tri(int a, int b, int c) { triangles.insert(triangles.end(), {a, b, c}); }
};

struct Result {
  int status;
  std::vector<float> depth;
  std::vector<int32_t> part;
};

/// Renders with every part at the identity unless poses are given.
Result render(const Mesh& m, int n_parts, std::vector<double> poses = {}, const uint8_t* closed = nullptr) {
  if (poses.empty())
    for (int i = 0; i < n_parts; ++i) poses.insert(poses.end(), {1, 0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0});
  Result r{0, std::vector<float>(kW * kH, -1.f), std::vector<int32_t>(kW * kH, 7)};
  r.status = moverl_depth_raster(kW, kH, kF, kCx, kCy, kNear, kFar, n_parts, poses.data(), closed, int(m.part.size()),
                                 m.vertices.data(), m.part.data(), int(m.triangles.size() / 3), m.triangles.data(),
                                 r.depth.data(), r.part.data());
  return r;
}

/// A square of half side s at depth z, facing the camera, as two triangles (wound as given by flip).
void square(Mesh& m, double s, double z, int32_t p, bool flip = false) {
  const int a = m.add(-s, -s, z, p), b = m.add(s, -s, z, p), c = m.add(s, s, z, p), d = m.add(-s, s, z, p);
  if (flip) {
    m.tri(a, c, b);
    m.tri(a, d, c);
  } else {
    m.tri(a, b, c);
    m.tri(a, c, d);
  }
}
}  // namespace

TEST(DepthRaster, ASquareCoversExactlyThePixelsWhoseSamplePointsItContains) {
  for (bool flip : {false, true}) {
    Mesh m;
    square(m, 0.3, 2.0, 0, flip);
    const Result r = render(m, 1);
    ASSERT_EQ(r.status, MOVERL_DEPTH_RASTER_OK);
    int covered = 0;
    for (int v = 0; v < kH; ++v)
      for (int u = 0; u < kW; ++u) {
        const double x = (u - kCx) / kF * 2.0, y = (v - kCy) / kF * 2.0;  // the sample ray at z = 2
        const bool inside = std::fabs(x) <= 0.3 && std::fabs(y) <= 0.3;
        const float d = r.depth[v * kW + u];
        if (inside) {
          ++covered;
          EXPECT_FLOAT_EQ(d, 2.0f) << u << "," << v;
          EXPECT_EQ(r.part[v * kW + u], 0);
        } else {
          EXPECT_EQ(d, float(kFar)) << u << "," << v;
          EXPECT_EQ(r.part[v * kW + u], -1);
        }
      }
    EXPECT_EQ(covered, 13 * 13);  // |u - 32| <= 6, |v - 23| <= 6
  }
}

TEST(DepthRaster, ATiltedTriangleHasTheDepthOfItsPlaneAlongEachRay) {
  // The plane z = 1.5 + 0.5 x (in front of the camera over the whole image), as one big triangle.
  Mesh m;
  const auto plane_z = [](double x) { return 1.5 + 0.5 * x; };
  const int a = m.add(-2, -2, plane_z(-2), 0), b = m.add(2, -2, plane_z(2), 0), c = m.add(0, 3, plane_z(0), 0);
  m.tri(a, b, c);
  const Result r = render(m, 1);
  int checked = 0;
  for (int v = 0; v < kH; ++v)
    for (int u = 0; u < kW; ++u) {
      const float d = r.depth[v * kW + u];
      if (d == float(kFar)) continue;
      // Along the ray (rx, ry, 1): z = 1.5 + 0.5 rx z  =>  z = 1.5 / (1 - 0.5 rx)
      const double rx = (u - kCx) / kF;
      EXPECT_NEAR(d, 1.5 / (1.0 - 0.5 * rx), 1e-5) << u << "," << v;
      ++checked;
    }
  EXPECT_GT(checked, kW * kH / 2);
}

TEST(DepthRaster, TheNearestSurfaceWinsWhateverTheOrder) {
  for (bool near_first : {false, true}) {
    Mesh m;
    square(m, near_first ? 0.2 : 1.0, near_first ? 1.0 : 3.0, near_first ? 0 : 1);
    square(m, near_first ? 1.0 : 0.2, near_first ? 3.0 : 1.0, near_first ? 1 : 0);
    const Result r = render(m, 2);
    const int centre = 23 * kW + 32;
    EXPECT_FLOAT_EQ(r.depth[centre], 1.0f);
    EXPECT_EQ(r.part[centre], 0);
    const int beside = 23 * kW + 32 + 12;  // x = 0.3 z: outside the small square at z = 1, inside the big one
    EXPECT_FLOAT_EQ(r.depth[beside], 3.0f);
    EXPECT_EQ(r.part[beside], 1);
  }
}

TEST(DepthRaster, PartsArePlacedByTheirPoses) {
  Mesh m;
  square(m, 0.3, 0.0, 0);  // in its part's frame at z = 0; the part 2 m in front of the camera, shifted right
  const Result r = render(m, 1, {1, 0, 0, 0, 1, 0, 0, 0, 1, 0.5, 0, 2.0});
  // Covered: x in [0.2, 0.8] at z = 2, i.e. u - 32 in [4, 16]
  EXPECT_EQ(r.depth[23 * kW + 32], float(kFar));
  EXPECT_FLOAT_EQ(r.depth[23 * kW + 42], 2.0f);
}

TEST(DepthRaster, WhatLiesNearerThanTheNearPlaneIsClippedAway) {
  // A floor-like triangle from z = 0.02 (in front of near) to z = 3: pixels see it only where it is beyond near.
  Mesh m;
  const int a = m.add(-1, 0.05, 0.02, 0), b = m.add(1, 0.05, 0.02, 0), c = m.add(0, 0.05, 3.0, 0);
  m.tri(a, b, c);
  const Result r = render(m, 1);
  int seen = 0;
  for (int i = 0; i < kW * kH; ++i)
    if (r.depth[i] != float(kFar)) {
      ++seen;
      EXPECT_GE(r.depth[i], float(kNear));
      EXPECT_LT(r.depth[i], 3.0f + 1e-4f);
    }
  EXPECT_GT(seen, 0);
  // The row through y = 0.05 at z = near (v = 23 + 40 * 0.5 = 43) sees the plane at about z = 0.1.
  const float d = r.depth[43 * kW + 32];
  EXPECT_NEAR(d, 0.1f, 0.01f);
  // A triangle wholly nearer than near, or beyond far, is not seen.
  Mesh hidden;
  square(hidden, 0.01, 0.05, 0);
  square(hidden, 10.0, 6.0, 0);
  const Result h = render(hidden, 1);
  for (int i = 0; i < kW * kH; ++i) EXPECT_EQ(h.depth[i], float(kFar));
}

TEST(DepthRaster, AFanOfThinTrianglesLeavesNoCrack) {
  // A disk of 360 slivers around one centre, at z = 1, before a backdrop at z = 4: a pixel inside the disk that saw
  // the backdrop would be a crack along a shared edge.
  Mesh m;
  const int centre = m.add(0.01, -0.02, 1.0, 0);
  const int n = 360;
  std::vector<int> rim;
  for (int k = 0; k < n; ++k)
    rim.push_back(m.add(0.01 + 0.4 * std::cos(2 * M_PI * k / n), -0.02 + 0.4 * std::sin(2 * M_PI * k / n), 1.0, 0));
  for (int k = 0; k < n; ++k) m.tri(centre, rim[k], rim[(k + 1) % n]);
  square(m, 4.0, 4.0, 1);
  const Result r = render(m, 2);
  int inside = 0;
  for (int v = 0; v < kH; ++v)
    for (int u = 0; u < kW; ++u) {
      const double x = (u - kCx) / kF - 0.01, y = (v - kCy) / kF + 0.02;
      if (std::hypot(x, y) < 0.399) {
        ++inside;
        EXPECT_FLOAT_EQ(r.depth[v * kW + u], 1.0f) << u << "," << v;
      }
    }
  EXPECT_GT(inside, 700);
}

TEST(DepthRaster, BackFacesAreSkippedOnlyInClosedParts) {
  // Flipped, the square's normals (b - a) x (c - a) point at the camera (counter-clockwise seen from it, a right-handed
  // frame): a front face; not flipped they point away: a back face. A part not marked closed draws both.
  const int centre = 23 * kW + 32;
  for (bool flip : {false, true})
    for (uint8_t closed : {0, 1}) {
      Mesh m;
      square(m, 0.3, 2.0, 0, flip);
      const Result r = render(m, 1, {}, &closed);
      const bool drawn = r.depth[centre] == 2.0f;
      EXPECT_EQ(drawn, !closed || flip) << "flip " << flip << " closed " << int(closed);
    }
}

TEST(DepthRaster, AClosedPartTheNearPlaneCutsOrThatHoldsTheCameraKeepsItsBackFaces) {
  // A closed box (outward winding) from z -0.05 to 0.35 (the near plane at 0.1 cuts it), and one around the camera:
  // with back faces culled neither would be drawn, and the camera would see the backdrop at 3 through them.
  for (double z0 : {-0.05, -0.5}) {
    Mesh m;
    const double s = z0 < -0.1 ? 1.0 : 0.2, z1 = z0 < -0.1 ? 0.5 : 0.35;
    int v[8];
    for (int k = 0; k < 8; ++k) v[k] = m.add(k & 1 ? s : -s, k & 2 ? s : -s, k & 4 ? z1 : z0, 0);
    // Outward normals (b - a) x (c - a): -z, +z, -y, +y, -x, +x faces.
    const int quads[6][4] = {{0, 2, 3, 1}, {4, 5, 7, 6}, {0, 1, 5, 4}, {2, 6, 7, 3}, {0, 4, 6, 2}, {1, 3, 7, 5}};
    for (const auto& q : quads) {
      m.tri(v[q[0]], v[q[1]], v[q[2]]);
      m.tri(v[q[0]], v[q[2]], v[q[3]]);
    }
    square(m, 4.0, 3.0, 1);  // the backdrop
    const uint8_t closed[2] = {1, 0};
    const Result r = render(m, 2, {}, closed);
    EXPECT_FLOAT_EQ(r.depth[23 * kW + 32], float(z1)) << "box from z " << z0;
    EXPECT_EQ(r.part[23 * kW + 32], 0);
  }
}

TEST(DepthRaster, BadInputIsRefusedAndLeavesTheImageAlone) {
  Mesh m;
  square(m, 0.3, 2.0, 0);
  std::vector<double> pose{1, 0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0};
  std::vector<float> depth(kW * kH, -1.f);
  const auto call = [&](int w, double f, double near, double far, int n_parts, const Mesh& mesh) {
    return moverl_depth_raster(w, kH, f, kCx, kCy, near, far, n_parts, pose.data(), nullptr, int(mesh.part.size()),
                               mesh.vertices.data(), mesh.part.data(), int(mesh.triangles.size() / 3),
                               mesh.triangles.data(), depth.data(), nullptr);
  };
  EXPECT_EQ(call(0, kF, kNear, kFar, 1, m), MOVERL_DEPTH_RASTER_BAD_IMAGE);
  EXPECT_EQ(call(kW, 0.0, kNear, kFar, 1, m), MOVERL_DEPTH_RASTER_BAD_IMAGE);
  EXPECT_EQ(call(kW, kF, 0.0, kFar, 1, m), MOVERL_DEPTH_RASTER_BAD_IMAGE);
  EXPECT_EQ(call(kW, kF, kNear, kNear, 1, m), MOVERL_DEPTH_RASTER_BAD_IMAGE);
  EXPECT_EQ(call(kW, kF, kNear, kFar, -1, m), MOVERL_DEPTH_RASTER_BAD_COUNT);
  EXPECT_EQ(call(kW, kF, kNear, kFar, 0, m), MOVERL_DEPTH_RASTER_BAD_INDEX);  // vertices of a missing part
  Mesh bad = m;
  bad.triangles[4] = int32_t(bad.part.size());  // a missing vertex
  EXPECT_EQ(call(kW, kF, kNear, kFar, 1, bad), MOVERL_DEPTH_RASTER_BAD_INDEX);
  for (float d : depth) ASSERT_EQ(d, -1.f);
  EXPECT_EQ(call(kW, kF, kNear, kFar, 1, m), MOVERL_DEPTH_RASTER_OK);
}

int main(int argc, char** argv) {
  testing::InitGoogleTest(&argc, argv);
  return RUN_ALL_TESTS();
}
