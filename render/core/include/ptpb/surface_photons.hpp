// Surface photons and their density estimate on diffuse surfaces (DESIGN.md §7): the record a
// light path leaves at each diffuse hit, a uniform hash grid rebuilt every iteration with the
// iteration's radius r_i, and the per-photon acceptance and kernel weight of the gather.
#pragma once
#include <cstdint>
#include <vector>

#include "ptpb/kernels.hpp"
#include "ptpb/vec.hpp"

namespace ptpb {

struct SurfacePhoton {
  Vec3d position{};   // x_p on the surface
  Vec3d direction{};  // unit incident direction, along the light's travel
  Vec3d normal{};     // unit surface normal on the side the light arrived from
  Vec3d power{};      // Phi_p: path throughput on arrival, before the albedo, W
  double tau = 0.0;   // arrival OPL tau_p, m (from the light's time origin)
  std::uint32_t shape = 0;
  int light_depth = 0;    // non-null interactions before the hit
  bool timeless = false;  // from an emitter without a time origin: steady image only
  std::uint32_t path = 0;
};

// Uniform hash grid of cubic cells of size r (the photons lie on 2-D surfaces embedded in 3-D, so
// the cells are cubes and a query visits the 3x3x3 block around x). Buckets are filled in photon
// index order and a query returns indices sorted ascending, so the sum over a query does not
// depend on the build or on hash collisions (§9).
class SurfacePhotonGrid {
 public:
  // radius: r_i, both the cell size and the query radius; throws std::invalid_argument if not > 0.
  // Keeps a pointer to `photons`, which must stay alive and unchanged while the grid is queried.
  void build(const std::vector<SurfacePhoton>& photons, double radius);
  // Replaces `out` with the indices of the photons strictly within r of x, ascending.
  void query(const Vec3d& x, std::vector<std::uint32_t>& out) const;
  double radius() const { return radius_; }
  std::size_t size() const { return photons_ ? photons_->size() : 0; }

 private:
  std::uint64_t bucket(std::int64_t ix, std::int64_t iy, std::int64_t iz) const;
  const std::vector<SurfacePhoton>* photons_ = nullptr;
  double radius_ = 0.0, inv_cell_ = 0.0;
  std::uint64_t mask_ = 0;
  std::vector<std::uint32_t> start_;    // CSR offsets, one more than the bucket count
  std::vector<std::uint32_t> indices_;  // photon indices grouped by bucket, ascending within each
};

// Kernel weight k_r(|x - x_p|) of photon p for a gather at x with unit normal `normal` facing
// the viewer, or 0 when the photon is rejected: beyond r, on the other side of the surface, or
// on a surface whose normal differs from x's by more than acos(min_normal_cos).
inline double surface_photon_weight(const SurfacePhoton& p, const Vec3d& x, const Vec3d& normal, double radius,
                                    SpatialKernel kernel, double min_normal_cos) {
  // Both normals face their own incoming side, so the two sides of one surface have opposite
  // normals: this one test rejects the far side of a thin shell as well as creases and edges.
  if (!(dot(p.normal, normal) >= min_normal_cos)) return 0.0;
  return spatial_kernel_2d(kernel, length(x - p.position), radius);
}

}  // namespace ptpb
