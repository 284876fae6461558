// Triangle ray engine on Embree 3: batched closest-hit and occlusion queries.
#pragma once
#include <cstddef>
#include <cstdint>
#include <limits>
#include <memory>
#include <vector>

#include "ptpb/vec.hpp"

namespace ptpb {

constexpr std::uint32_t kInvalidId = std::numeric_limits<std::uint32_t>::max();

struct Hit {
  float t = std::numeric_limits<float>::infinity();  // distance along the (unit) direction, m
  std::uint32_t prim_id = kInvalidId;                // triangle index within its mesh
  std::uint32_t mesh_id = kInvalidId;                // caller's id of the mesh
  Vec3f normal{};                                    // geometric normal, unit, from the winding
  bool valid() const { return mesh_id != kInvalidId; }
};

struct Bounds3f {
  Vec3f lower{std::numeric_limits<float>::infinity(), std::numeric_limits<float>::infinity(),
              std::numeric_limits<float>::infinity()};
  Vec3f upper{-std::numeric_limits<float>::infinity(), -std::numeric_limits<float>::infinity(),
              -std::numeric_limits<float>::infinity()};
  bool empty() const { return !(lower.x <= upper.x); }
};

// A set of triangle meshes. Add meshes, call commit(), then query from any number of threads.
class RayScene {
 public:
  RayScene();
  ~RayScene();
  RayScene(const RayScene&) = delete;
  RayScene& operator=(const RayScene&) = delete;

  // vertices: nv x 3 floats (m); faces: nf x 3 vertex indices. Throws std::invalid_argument on
  // empty meshes, non-finite vertices or out-of-range indices. Returns the mesh's slot.
  void add_mesh(const float* vertices, std::size_t vertex_count, const std::uint32_t* faces, std::size_t face_count,
                std::uint32_t mesh_id);
  // The same mesh placed at each of `offset_count` translations (offsets: offset_count x 3, m) as Embree
  // instances of one copy: memory stays that of one mesh however many are placed (DESIGN.md §13). Every
  // copy answers with `mesh_id`. Throws std::invalid_argument on a non-finite offset or none at all.
  void add_instanced_mesh(const float* vertices, std::size_t vertex_count, const std::uint32_t* faces,
                          std::size_t face_count, const double* offsets, std::size_t offset_count,
                          std::uint32_t mesh_id);
  void commit();
  bool committed() const { return committed_; }

  std::size_t mesh_count() const { return mesh_ids_.size(); }
  // Triangles stored (an instanced mesh counts once) and triangles placed (once per copy).
  std::size_t triangle_count() const { return triangle_count_; }
  std::size_t placed_triangle_count() const { return placed_triangle_count_; }
  Bounds3f bounds() const { return bounds_; }

  // Single queries; directions need not be unit (t is then in units of |d|).
  Hit intersect(const Vec3f& origin, const Vec3f& direction, float tnear = 0.0f,
                float tfar = std::numeric_limits<float>::infinity()) const;
  bool occluded(const Vec3f& origin, const Vec3f& direction, float tnear = 0.0f,
                float tfar = std::numeric_limits<float>::infinity()) const;
  // Distance from `point` to the nearest triangle of any mesh, or `radius` when none lies closer
  // (an Embree point query bounded by `radius`, exact in double on the float vertices).
  double closest_distance(const Vec3d& point, double radius) const;

  // Batched queries over n rays stored as n x 3 arrays; `threads` = 0 uses all hardware threads.
  void intersect_batch(const float* origins, const float* directions, std::size_t n, float tnear, const float* tfar,
                       float* t_out, std::uint32_t* prim_out, std::uint32_t* mesh_out, float* normal_out,
                       int threads) const;
  void occluded_batch(const float* origins, const float* directions, std::size_t n, float tnear, const float* tfar,
                      bool* occluded_out, int threads) const;

 private:
  void require_committed() const;
  struct Impl;
  std::unique_ptr<Impl> impl_;
  void check_mesh(const float* vertices, std::size_t vertex_count, const std::uint32_t* faces, std::size_t face_count,
                  std::uint32_t mesh_id) const;
  void store_mesh(const float* vertices, std::size_t vertex_count, const std::uint32_t* faces, std::size_t face_count,
                  std::uint32_t mesh_id);
  // Adds the box of a mesh whose own box is `local`, moved by `offset`, to bounds_.
  void grow_bounds(const Bounds3f& local, const Vec3d& offset);
  std::vector<std::uint32_t> mesh_ids_;  // mesh slot -> caller's mesh id
  std::size_t triangle_count_ = 0;
  std::size_t placed_triangle_count_ = 0;
  Bounds3f bounds_{};
  bool committed_ = false;
};

}  // namespace ptpb
