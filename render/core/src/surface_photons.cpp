// The surface photon hash grid: counting sort of photon indices into hashed cubic cells.
#include "ptpb/surface_photons.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>

#include "ptpb/rng.hpp"

namespace ptpb {
namespace {

std::int64_t cell_coord(double v, double inv_cell) {
  // Clamped so that photons far from the origin at a tiny radius cannot overflow the cast; such
  // cells merely share buckets, which the exact distance test resolves.
  const double c = std::floor(v * inv_cell);
  constexpr double lim = 4.0e18;
  return static_cast<std::int64_t>(std::clamp(c, -lim, lim));
}

}  // namespace

std::uint64_t SurfacePhotonGrid::bucket(std::int64_t ix, std::int64_t iy, std::int64_t iz) const {
  const std::uint64_t h = mix64(static_cast<std::uint64_t>(ix) ^
                                mix64(static_cast<std::uint64_t>(iy) ^ mix64(static_cast<std::uint64_t>(iz))));
  return h & mask_;
}

void SurfacePhotonGrid::build(const std::vector<SurfacePhoton>& photons, double radius) {
  if (!(std::isfinite(radius) && radius > 0.0))
    throw std::invalid_argument("surface photon radius must be finite and > 0 (m)");
  if (photons.size() >= std::numeric_limits<std::uint32_t>::max())
    throw std::invalid_argument("too many surface photons in one iteration (reduce light_paths_per_iteration)");
  photons_ = &photons;
  radius_ = radius;
  inv_cell_ = 1.0 / radius;
  // About two buckets per photon keeps collisions rare without a large empty table.
  std::uint64_t buckets = 1;
  while (buckets < 2 * photons.size()) buckets <<= 1;
  mask_ = buckets - 1;
  start_.assign(buckets + 1, 0);
  indices_.resize(photons.size());
  std::vector<std::uint32_t> home(photons.size());
  for (std::size_t i = 0; i < photons.size(); ++i) {
    const Vec3d& x = photons[i].position;
    home[i] = static_cast<std::uint32_t>(
        bucket(cell_coord(x.x, inv_cell_), cell_coord(x.y, inv_cell_), cell_coord(x.z, inv_cell_)));
    ++start_[home[i] + 1];
  }
  for (std::uint64_t b = 0; b < buckets; ++b) start_[b + 1] += start_[b];
  std::vector<std::uint32_t> fill(start_.begin(), start_.end() - 1);
  // Ascending photon order inside each bucket: the fill runs over photons in index order.
  for (std::size_t i = 0; i < photons.size(); ++i) indices_[fill[home[i]]++] = static_cast<std::uint32_t>(i);
}

void SurfacePhotonGrid::query(const Vec3d& x, std::vector<std::uint32_t>& out) const {
  out.clear();
  if (!photons_ || photons_->empty()) return;
  const std::int64_t cx = cell_coord(x.x, inv_cell_), cy = cell_coord(x.y, inv_cell_), cz = cell_coord(x.z, inv_cell_);
  // Cells are r wide, so the ball of radius r around x lies inside the 3x3x3 block. Distinct
  // cells can share a bucket; visiting each bucket once keeps every photon listed once.
  std::uint64_t seen[27];
  int count = 0;
  for (int dz = -1; dz <= 1; ++dz)
    for (int dy = -1; dy <= 1; ++dy)
      for (int dx = -1; dx <= 1; ++dx) seen[count++] = bucket(cx + dx, cy + dy, cz + dz);
  std::sort(seen, seen + count);
  count = static_cast<int>(std::unique(seen, seen + count) - seen);
  const double r2 = radius_ * radius_;
  const std::vector<SurfacePhoton>& photons = *photons_;
  for (int k = 0; k < count; ++k) {
    for (std::uint32_t j = start_[seen[k]]; j < start_[seen[k] + 1]; ++j) {
      const std::uint32_t i = indices_[j];
      const Vec3d d = photons[i].position - x;
      if (dot(d, d) < r2) out.push_back(i);
    }
  }
  std::sort(out.begin(), out.end());
}

}  // namespace ptpb
