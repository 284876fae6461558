// The gather (DESIGN.md §4, §5, §7): the estimates a camera path collects, from photon beams along a
// medium segment and from surface photons at a diffuse hit, and the acceptance test of a ray–beam
// pair that the beam structures mirror.
#pragma once
#include <cstdint>
#include <vector>

#include "ptpb/beam_geometry.hpp"
#include "ptpb/camera.hpp"
#include "ptpb/film.hpp"

namespace ptpb {

enum class PairTest { Parallel, Outside, Inside };

// The gather's test of a ray–beam pair (§4): near-parallel pairs (sin^2 below the guard) are
// rejected, and the others count when the closest approach lies on the query segment [0, t_max], on
// the beam [0, length] and within the kernel radius.
inline PairTest test_beam_pair(const ClosestApproach& ca, double t_max, double beam_length, double radius,
                               double parallel_guard_sin2) {
  if (ca.sin2 < parallel_guard_sin2) return PairTest::Parallel;
  if (!(ca.t >= 0 && ca.t <= t_max && ca.s >= 0 && ca.s <= beam_length && ca.u < radius)) return PairTest::Outside;
  return PairTest::Inside;
}

// Beam×beam estimate along the query segment [0, t_q] of one camera segment (§4, §5), over the beams
// of `layer` with its radius. Returns the number of pairs it accepted.
std::uint64_t gather(const CameraPass& p, const BeamLayer& layer, const PixelSplat& splat, const Vec3d& pos,
                     const Vec3d& dir, double t_q, int medium, const Vec3d& weight, double tau_c, int depth_c,
                     std::vector<std::uint32_t>& cand, TileStats& ts);

// Surface photon estimate at a diffuse camera hit x (§7); `normal` faces the camera side, `weight`
// is the camera throughput up to x and tau_c the camera OPL to x.
void gather_surface(const CameraPass& p, const PixelSplat& splat, const Vec3d& x, const Vec3d& normal,
                    const Vec3d& albedo, const Vec3d& weight, double tau_c, int depth_c,
                    std::vector<std::uint32_t>& cand, TileStats& ts);

}  // namespace ptpb
