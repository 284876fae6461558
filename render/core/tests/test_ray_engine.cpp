// Ray engine against analytic answers: a unit box and a triangulated sphere.
#include <cmath>
#include <vector>

#include "check.hpp"
#include "ptpb/ray_engine.hpp"

using ptpb::Vec3d;
using ptpb::Vec3f;

namespace {

// Unit cube [0,1]^3 wound outward (right-hand normals point out).
void add_unit_box(ptpb::RayScene& scene, std::uint32_t id) {
  const float v[] = {0, 0, 0, 1, 0, 0, 0, 1, 0, 1, 1, 0, 0, 0, 1, 1, 0, 1, 0, 1, 1, 1, 1, 1};
  const std::uint32_t f[] = {0, 2, 3, 0, 3, 1, 4, 5, 7, 4, 7, 6, 0, 1, 5, 0, 5, 4,
                             2, 6, 7, 2, 7, 3, 0, 4, 6, 0, 6, 2, 1, 3, 7, 1, 7, 5};
  scene.add_mesh(v, 8, f, 12, id);
}

}  // namespace

TEST_CASE("box hit distances and outward normals") {
  ptpb::RayScene scene;
  add_unit_box(scene, 7);
  scene.commit();
  const ptpb::Hit h = scene.intersect(Vec3f(0.25f, 0.5f, 3.0f), Vec3f(0, 0, -1));
  CHECK(h.valid());
  CHECK_CLOSE(h.t, 2.0, 1e-6);
  CHECK(h.mesh_id == 7);
  CHECK_NEAR(h.normal.z, 1.0, 1e-6);
  const ptpb::Hit side = scene.intersect(Vec3f(-2.0f, 0.3f, 0.6f), Vec3f(1, 0, 0));
  CHECK_CLOSE(side.t, 2.0, 1e-6);
  CHECK_NEAR(side.normal.x, -1.0, 1e-6);
  // From inside, the exit face's normal still points outward.
  const ptpb::Hit inside = scene.intersect(Vec3f(0.5f, 0.5f, 0.5f), Vec3f(0, 1, 0));
  CHECK_CLOSE(inside.t, 0.5, 1e-6);
  CHECK_NEAR(inside.normal.y, 1.0, 1e-6);
  CHECK(!scene.intersect(Vec3f(2, 2, 2), Vec3f(0, 0, 1)).valid());
  CHECK(scene.occluded(Vec3f(0.5f, 0.5f, 3.0f), Vec3f(0, 0, -1)));
  CHECK(!scene.occluded(Vec3f(0.5f, 0.5f, 3.0f), Vec3f(0, 0, -1), 0.0f, 1.5f));
}

TEST_CASE("batched queries agree with single queries at any thread count") {
  ptpb::RayScene scene;
  add_unit_box(scene, 1);
  scene.commit();
  const std::size_t n = 10000;
  std::vector<float> o(3 * n), d(3 * n);
  for (std::size_t i = 0; i < n; ++i) {
    const float a = 6.283185f * float(i) / float(n);
    o[3 * i] = 0.5f + 3.0f * std::cos(a);
    o[3 * i + 1] = 0.5f + 3.0f * std::sin(a);
    o[3 * i + 2] = 0.5f;
    d[3 * i] = -std::cos(a);
    d[3 * i + 1] = -std::sin(a);
    d[3 * i + 2] = 0.0f;
  }
  std::vector<float> t1(n), t2(n), n1(3 * n), n2(3 * n);
  std::vector<std::uint32_t> p1(n), p2(n), m1(n), m2(n);
  scene.intersect_batch(o.data(), d.data(), n, 0.0f, nullptr, t1.data(), p1.data(), m1.data(), n1.data(), 1);
  scene.intersect_batch(o.data(), d.data(), n, 0.0f, nullptr, t2.data(), p2.data(), m2.data(), n2.data(), 4);
  bool same = true;
  for (std::size_t i = 0; i < n; ++i) same = same && t1[i] == t2[i] && p1[i] == p2[i];
  CHECK(same);
  // Distance to the box from a circle of radius 3 around its centre, along the inward ray.
  const float a = 6.283185f * 17.0f / float(n);
  const double expected = 3.0 - 0.5 / std::max(std::fabs(std::cos(a)), std::fabs(std::sin(a)));
  CHECK_CLOSE(t1[17], expected, 1e-5);
}

TEST_CASE("closest distance to the box from inside, outside, near faces, edges and corners") {
  ptpb::RayScene scene;
  add_unit_box(scene, 3);
  scene.commit();
  using ptpb::Vec3d;
  CHECK_CLOSE(scene.closest_distance(Vec3d(0.5, 0.5, 0.5), 10.0), 0.5, 1e-12);
  CHECK_CLOSE(scene.closest_distance(Vec3d(0.3, 0.6, 0.9), 10.0), 0.1, 1e-9);
  CHECK_CLOSE(scene.closest_distance(Vec3d(0.5, 0.5, 1e-7), 10.0), 1e-7, 1e-9);
  CHECK_CLOSE(scene.closest_distance(Vec3d(2.0, 0.5, 0.5), 10.0), 1.0, 1e-12);             // face
  CHECK_CLOSE(scene.closest_distance(Vec3d(2.0, 2.0, 0.5), 10.0), std::sqrt(2.0), 1e-12);  // edge
  CHECK_CLOSE(scene.closest_distance(Vec3d(2.0, 2.0, 2.0), 10.0), std::sqrt(3.0), 1e-12);  // corner
  // Bounded: nothing within the radius returns the radius.
  CHECK_CLOSE(scene.closest_distance(Vec3d(0.5, 0.5, 0.5), 0.25), 0.25, 0.0);
  CHECK_CLOSE(scene.closest_distance(Vec3d(5.0, 5.0, 5.0), 1.0), 1.0, 0.0);
}

TEST_CASE("instanced copies answer like copies placed by hand: hits, occlusion, closest distance") {
  // The unit box at 3 x 3 offsets 1.5 m apart, once as instances of one mesh, once as nine meshes.
  const float v[] = {0, 0, 0, 1, 0, 0, 0, 1, 0, 1, 1, 0, 0, 0, 1, 1, 0, 1, 0, 1, 1, 1, 1, 1};
  const std::uint32_t f[] = {0, 2, 3, 0, 3, 1, 4, 5, 7, 4, 7, 6, 0, 1, 5, 0, 5, 4,
                             2, 6, 7, 2, 7, 3, 0, 4, 6, 0, 6, 2, 1, 3, 7, 1, 7, 5};
  std::vector<double> offsets;
  for (int i = -1; i <= 1; ++i)
    for (int j = -1; j <= 1; ++j) offsets.insert(offsets.end(), {1.5 * i, 1.5 * j, 0.25 * (i + j)});
  ptpb::RayScene instanced, copies;
  instanced.add_instanced_mesh(v, 8, f, 12, offsets.data(), 9, 5);
  for (int k = 0; k < 9; ++k) {
    float moved[24];
    for (int q = 0; q < 24; ++q) moved[q] = v[q] + static_cast<float>(offsets[3 * k + q % 3]);
    copies.add_mesh(moved, 8, f, 12, 5);
  }
  instanced.commit();
  copies.commit();
  CHECK(instanced.triangle_count() == 12 && instanced.placed_triangle_count() == 108);
  CHECK(copies.triangle_count() == 108);
  CHECK_CLOSE(double(instanced.bounds().lower.x), -1.5, 1e-7);
  CHECK_CLOSE(double(instanced.bounds().upper.z), 1.5, 1e-7);
  int hits = 0;
  for (int n = 0; n < 2000; ++n) {
    // A deterministic spread of rays through and around the block of boxes.
    const double a = 0.61803398875 * n, b = 0.7548776662 * n, c = 0.5698402910 * n;
    const Vec3f o(float(4.0 * (a - std::floor(a)) - 2.0), float(4.0 * (b - std::floor(b)) - 2.0),
                  float(3.0 * (c - std::floor(c)) - 1.0));
    const Vec3f d(float(std::cos(7.1 * n)), float(std::sin(3.3 * n)), float(std::cos(5.7 * n + 1.0)));
    const ptpb::Hit hi = instanced.intersect(o, d), hc = copies.intersect(o, d);
    CHECK(hi.valid() == hc.valid());
    if (hi.valid() && hc.valid()) {
      ++hits;
      CHECK_NEAR(double(hi.t), double(hc.t), 1e-5);
      CHECK(hi.mesh_id == 5 && hi.prim_id == hc.prim_id);
      CHECK_NEAR(double(hi.normal.x), double(hc.normal.x), 1e-6);
      CHECK_NEAR(double(hi.normal.z), double(hc.normal.z), 1e-6);
    }
    CHECK(instanced.occluded(o, d, 0.0f, 0.8f) == copies.occluded(o, d, 0.0f, 0.8f));
    const Vec3d p(o.x, o.y, o.z);
    CHECK_NEAR(instanced.closest_distance(p, 2.0), copies.closest_distance(p, 2.0), 1e-6);
  }
  CHECK(hits > 500);
  // The centre of the middle box is 0.5 from its faces; the point between two boxes 0.25 from each.
  CHECK_CLOSE(instanced.closest_distance(Vec3d(0.5, 0.5, 0.5), 10.0), 0.5, 1e-6);
  CHECK_CLOSE(instanced.closest_distance(Vec3d(1.25, 0.5, 0.5), 10.0), 0.25, 1e-6);
  ptpb::RayScene refused;
  CHECK_THROWS(refused.add_instanced_mesh(v, 8, f, 12, offsets.data(), 0, 0));
  const double bad[] = {0.0, NAN, 0.0};
  CHECK_THROWS(refused.add_instanced_mesh(v, 8, f, 12, bad, 1, 0));
}

TEST_CASE("invalid meshes are refused with a reason") {
  ptpb::RayScene scene;
  const float bad[] = {0, 0, 0, 1, 0, 0, 0, NAN, 0};
  const std::uint32_t f[] = {0, 1, 2};
  CHECK_THROWS(scene.add_mesh(bad, 3, f, 1, 0));
  const float ok[] = {0, 0, 0, 1, 0, 0, 0, 1, 0};
  const std::uint32_t out_of_range[] = {0, 1, 3};
  CHECK_THROWS(scene.add_mesh(ok, 3, out_of_range, 1, 0));
  CHECK_THROWS(scene.add_mesh(ok, 3, f, 0, 0));
}

PTPB_TEST_MAIN()
