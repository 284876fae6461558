// Exact properties of the grain tracer (grains.hpp): a single sphere conserves energy to rounding, admits no
// total internal reflection, and absorbs what the closed-form quadrature over impact parameters gives; the
// packing's photons are all accounted for, and the result does not depend on the thread count.
#include <cmath>
#include <vector>

#include "check.hpp"
#include "ptpb/grains.hpp"
#include "ptpb/rng.hpp"
#include "ptpb/sampling.hpp"

using namespace ptpb;

namespace {

// Absorbed fraction of a sphere lit over its cross-section: each impact parameter enters with 1 - R, and every
// internal chord (length 2 r cos_t) meets the surface with the same reflectance R: (1-R)(1-a)/(1-R a).
double sphere_absorption_quadrature(double r, double n, double gamma) {
  const int steps = 200000;
  double sum = 0;
  for (int i = 0; i < steps; ++i) {
    const double s2 = (i + 0.5) / steps;  // (b/r)^2, uniform over the cross-section
    const double cos_i = std::sqrt(1.0 - s2);
    const FresnelResult f = fresnel_dielectric(cos_i, 1.0, n);
    const double a = std::exp(-gamma * 2.0 * r * f.cos_t);
    sum += (1.0 - f.reflectance) * (1.0 - a) / (1.0 - f.reflectance * a);
  }
  return sum / steps;
}

}  // namespace

TEST_CASE("grains: one sphere conserves energy, has no TIR, absorbs the quadrature's share") {
  GrainOptics o;
  o.ice_index = 1.3117;
  o.ice_absorption = 400.0;  // gamma r = 0.2: strong enough to see
  const double r = 5e-4;
  const SphereScatter s = scatter_sphere(r, o, 200000, 3);
  CHECK_NEAR(s.energy_out, 1.0, 1e-12);
  CHECK(s.total_internal_reflections == 0.0);
  CHECK_CLOSE(s.absorbed, sphere_absorption_quadrature(r, o.ice_index, o.ice_absorption), 0.01);
  // Weak absorption: ice path per incident photon is B x (4/3) r, B = n^2 [1 - (1 - 1/n^2)^(3/2)].
  o.ice_absorption = 0.0;
  const SphereScatter w = scatter_sphere(r, o, 200000, 4);
  const double n2 = o.ice_index * o.ice_index;
  const double b = n2 * (1.0 - std::pow(1.0 - 1.0 / n2, 1.5));
  CHECK_CLOSE(w.mean_ice_path, b * 4.0 / 3.0 * r, 0.01);
  CHECK(w.mean_cos > 0.7 && w.mean_cos < 0.85);
}

TEST_CASE("grains: a packing accounts for every photon, at any thread count") {
  GrainPacking p;
  p.cell_size = 4e-3;
  // Random sequential addition of 48 spheres (phi = 0.2), periodic, from a fixed stream: no overlaps.
  KeyedRng rng(1, 0, StreamDomain::Test, 0);
  const double r = 0.4e-3, lc = p.cell_size;
  while (p.radii.size() < 48) {
    const double c[3] = {rng.next_double() * lc, rng.next_double() * lc, -rng.next_double() * lc};
    bool free = true;
    for (std::size_t k = 0; k < p.radii.size() && free; ++k) {
      double d2 = 0;
      for (int a = 0; a < 3; ++a) {
        const double dx = std::remainder(c[a] - p.centres[3 * k + a], lc);
        d2 += dx * dx;
      }
      free = d2 >= 4 * r * r;
    }
    if (!free) continue;
    p.centres.insert(p.centres.end(), {c[0], c[1], c[2] == 0.0 ? -1e-9 : c[2]});
    p.radii.push_back(r);
  }
  GrainOptics o;
  o.ice_group_index = 1.31;
  o.ice_absorption = 50.0;
  GrainTraceSettings s;
  s.photons = 3000;
  s.seed = 9;
  s.temporal_bins = 200;
  s.bin_width_opl = 5e-4;
  s.start_opl = -2e-3;
  s.depth_bins = 2000;
  s.depth_bin_width = 1e-3;
  s.threads = 1;
  const GrainTraceResult a = trace_packing(p, o, s);
  s.threads = 3;
  const GrainTraceResult b = trace_packing(p, o, s);
  CHECK_NEAR(a.albedo + a.absorbed + a.truncated, 1.0, 1e-12);
  CHECK(a.total_internal_reflections == 0.0);
  CHECK(a.albedo > 0.2 && a.albedo < 0.95);
  bool same = a.albedo == b.albedo && a.ice_path == b.ice_path;
  for (int i = 0; i < s.temporal_bins; ++i) same &= a.time_flux[i] == b.time_flux[i];
  for (int i = 0; i < s.depth_bins; ++i) same &= a.absorbed_depth[i] == b.absorbed_depth[i];
  CHECK(same);
  // Track-length absorption estimate and the analog count agree in expectation.
  double deposited = 0;
  for (double x : a.absorbed_depth) deposited += x;
  CHECK_NEAR(deposited, a.absorbed, 0.03);
  CHECK_NEAR(deposited, o.ice_absorption * a.ice_path, 1e-9);
}

TEST_CASE("grains: homogeneous half-space without absorption loses no photon") {
  HomogeneousMedium m;
  m.scattering = 1000.0;
  m.asymmetry = 0.5;
  GrainTraceSettings s;
  s.photons = 2000;
  s.max_path = 10.0;  // a return time's law falls as t^(-3/2): the cap ends the few long walks
  const GrainTraceResult r = trace_homogeneous(m, s);
  CHECK_NEAR(r.albedo + r.truncated, 1.0, 1e-12);
  CHECK(r.absorbed == 0.0 && r.truncated < 0.05);
}

PTPB_TEST_MAIN()
