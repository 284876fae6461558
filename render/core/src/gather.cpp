// The gather (DESIGN.md §4, §5, §7): beam estimates along a camera segment, surface photon estimates
// at a diffuse camera hit, each splatted into the pixel's tile.
#include "ptpb/gather.hpp"

#include <algorithm>
#include <cmath>

#include "ptpb/free_flight.hpp"
#include "ptpb/kernels.hpp"
#include "ptpb/sampling.hpp"

namespace ptpb {

// Beam×beam estimate along the query segment [0, t_q] of one camera segment (§4, §5).
std::uint64_t gather(const CameraPass& p, const BeamLayer& layer, const PixelSplat& splat, const Vec3d& pos,
                     const Vec3d& dir, double t_q, int medium, const Vec3d& weight, double tau_c, int depth_c,
                     std::vector<std::uint32_t>& cand, TileStats& ts) {
  const Scene& scene = p.cs->scene();
  const RenderSettings& st = *p.st;
  const Medium& m = scene.media[medium];
  const Vec3d sigma_t = m.sigma_t();
  const double n = m.ior;
  cand.clear();
  layer.accel->query(pos, dir, t_q, cand);
  ++ts.queries;
  // Canonical order makes the sum independent of traversal and thread count (§9): the structures
  // hand their candidates over sorted (BeamAccel::query), and only near-parallel ones can repeat.
  cand.erase(std::unique(cand.begin(), cand.end()), cand.end());
  ts.candidates += cand.size();
  const std::vector<Beam>& beams = *layer.beams;
  std::uint64_t accepted = 0;
  const double radius = layer.radius_in(medium);
  const bool short_query = st.query_beam_kind == BeamKind::Short;
  const Vec3d query_weight = weight * m.sigma_s * p.inv_paths;
  for (std::uint32_t bi : cand) {
    const Beam& b = beams[bi];
    if (b.medium != medium) {
      ++ts.false_positives;
      continue;
    }
    if (st.max_depth >= 0 && b.light_depth + depth_c + 2 > st.max_depth) continue;
    const ClosestApproach ca = closest_approach(pos, dir, b.origin, b.direction);
    const PairTest verdict = test_beam_pair(ca, t_q, b.length, radius, st.parallel_guard_sin2);
    if (verdict == PairTest::Parallel) {
      ++ts.parallel;
      continue;
    }
    if (verdict == PairTest::Outside) {
      ++ts.false_positives;
      continue;
    }
    const double k_r = spatial_kernel_1d(st.spatial_kernel, ca.u, radius);
    const double phase = hg_eval(dot(b.direction, -dir), m.g);
    // Tr(t_c) Tr(s_b) in one exponential per channel; short beams divide by their survival.
    const Vec3d tr = transmittance(sigma_t, ca.t + ca.s);
    double survival = 1.0;
    if (short_query) survival = survival_mixture(sigma_t, ca.t);
    if (b.kind == BeamKind::Short) survival *= survival_mixture(sigma_t, ca.s);
    const double scalar = k_r * phase / (std::sqrt(ca.sin2) * survival);
    const Vec3d value = query_weight * tr * b.power * scalar;
    const double tau = b.tau0 + n * ca.s + (st.camera_unwarp ? 0.0 : n * ca.t + tau_c);
    splat.add(tau, value, b.timeless, p.time_half_width);
    ++accepted;
  }
  return accepted;
}

// Surface photon estimate at a diffuse camera hit x (§7):
//   L(x, tau_f) = (1/M) sum_p k_r(|x - x_p|) K_T(tau_f - (tau_p + tau_c)) f_r Phi_p,
// with f_r = albedo/pi (Lambert, so no dependence on the photon's direction). `normal` faces the
// camera side; `weight` is the camera throughput W_c up to x and tau_c the camera OPL to x.
//
// Depth: Mitsuba's max_depth counts the segments of the emitter-to-camera path, i.e. its non-null
// interactions + 1 (§3). A photon of light depth d has met d interactions before arriving at x,
// the camera path has met d_c specular events before reaching x, and the reflection at x is one
// more interaction: d + d_c + 1 interactions, depth d + d_c + 2, the same count as a beam x query
// pair where the gather scattering plays the reflection's part. Direct light on a diffuse plane
// (d = d_c = 0) is depth 2, which Mitsuba renders at max_depth = 2 ("direct illumination").
void gather_surface(const CameraPass& p, const PixelSplat& splat, const Vec3d& x, const Vec3d& normal,
                    const Vec3d& albedo, const Vec3d& weight, double tau_c, int depth_c,
                    std::vector<std::uint32_t>& cand, TileStats& ts) {
  const RenderSettings& st = *p.st;
  p.photon_grid->query(x, cand);  // ascending photon indices: a canonical summation order (§9)
  ++ts.surface_queries;
  const Vec3d common = weight * albedo * (p.inv_paths / kPi);
  const std::vector<SurfacePhoton>& photons = *p.photons;
  for (std::uint32_t index : cand) {
    const SurfacePhoton& ph = photons[index];
    if (st.max_depth >= 0 && ph.light_depth + depth_c + 2 > st.max_depth) continue;
    const double k = surface_photon_weight(ph, x, normal, p.surface_radius, st.spatial_kernel, st.surface_normal_cos);
    if (k == 0.0) continue;
    // Unwarped: the time the light reached the surface, without the camera leg (§1).
    const double tau = ph.tau + (st.camera_unwarp ? 0.0 : tau_c);
    splat.add(tau, common * ph.power * k, ph.timeless, p.surface_time_half_width);
    ++ts.surface_pairs;
  }
}

}  // namespace ptpb
