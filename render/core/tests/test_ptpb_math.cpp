// Unit tests of the PTPB core math: keyed RNG, HG phase, Fresnel, kernels, schedules,
// closest approach and unit conversions (DESIGN.md §10, core-level list).
#include <cmath>
#include <vector>

#include "check.hpp"
#include "ptpb/beam_geometry.hpp"
#include "ptpb/hops.hpp"
#include "ptpb/kernels.hpp"
#include "ptpb/rng.hpp"
#include "ptpb/sampling.hpp"
#include "ptpb/units.hpp"

using namespace ptpb;

TEST_CASE("keyed rng: same key same stream, different keys differ, uniform moments") {
  KeyedRng a(7, 3, StreamDomain::LightPath, 11), b(7, 3, StreamDomain::LightPath, 11);
  KeyedRng c(7, 3, StreamDomain::CameraPixel, 11), d(7, 4, StreamDomain::LightPath, 11);
  bool all_equal = true, differ_c = false, differ_d = false;
  for (int i = 0; i < 100; ++i) {
    const double x = a.next_double();
    all_equal &= (x == b.next_double());
    differ_c |= (x != c.next_double());
    differ_d |= (x != d.next_double());
  }
  CHECK(all_equal);
  CHECK(differ_c);
  CHECK(differ_d);
  // First draws of many consecutive keys: mean 1/2, variance 1/12 (catches correlated seeding).
  const int n = 200000;
  double sum = 0, sum2 = 0;
  for (int i = 0; i < n; ++i) {
    KeyedRng r(1, 0, StreamDomain::CameraPixel, i);
    const double x = r.next_double();
    CHECK(x >= 0.0 && x < 1.0);
    sum += x;
    sum2 += x * x;
  }
  CHECK_NEAR(sum / n, 0.5, 5 * std::sqrt(1.0 / 12.0 / n));
  CHECK_NEAR(sum2 / n - (sum / n) * (sum / n), 1.0 / 12.0, 2e-3);
}

TEST_CASE("HG phase integrates to 1 and its sampled mean cosine equals g") {
  for (double g : {0.0, 0.3, -0.5, 0.85, 0.9}) {
    double integral = 0.0;
    const int n = 200000;
    for (int i = 0; i < n; ++i) {
      const double mu = -1.0 + 2.0 * (i + 0.5) / n;
      integral += hg_eval(mu, g) * 2.0 * kPi * (2.0 / n);
    }
    CHECK_NEAR(integral, 1.0, 1e-4);
    double mean = 0.0;
    const int m = 400000;
    KeyedRng rng(3, 0, StreamDomain::Test, 0);
    const Vec3d in = normalize(Vec3d{0.3, -0.4, 0.8});
    for (int i = 0; i < m; ++i) {
      const double u1 = rng.next_double(), u2 = rng.next_double();
      mean += dot(hg_sample(in, g, u1, u2), in);
    }
    mean /= m;
    CHECK_NEAR(mean, g, 4e-3);
  }
}

TEST_CASE("HG sampling chi-square over cosine bins (g = 0.7)") {
  const double g = 0.7;
  const int bins = 40, n = 400000;
  std::vector<double> observed(bins, 0.0);
  KeyedRng rng(5, 0, StreamDomain::Test, 1);
  for (int i = 0; i < n; ++i) {
    const double mu = hg_sample_cos(g, rng.next_double());
    observed[std::min(bins - 1, int((mu + 1.0) * 0.5 * bins))] += 1;
  }
  double chi2 = 0.0;
  for (int b = 0; b < bins; ++b) {
    // Expected count from the analytic HG cdf over the cosine bin.
    auto cdf = [&](double mu) {
      return (1 - g * g) / (2 * g) * (1.0 / std::sqrt(1 + g * g - 2 * g * mu) - 1.0 / (1 + g));
    };
    const double lo = -1.0 + 2.0 * b / bins, hi = -1.0 + 2.0 * (b + 1) / bins;
    const double expected = n * (cdf(hi) - cdf(lo));
    chi2 += (observed[b] - expected) * (observed[b] - expected) / expected;
  }
  // 39 degrees of freedom: the 99.9% quantile is 72.1.
  CHECK(chi2 < 72.1);
}

TEST_CASE("Fresnel at n = 1.31: F(0) and the critical angle; branch choice frequency") {
  CHECK_NEAR(fresnel_dielectric(1.0, 1.0, 1.31).reflectance, 0.0180, 5e-5);
  CHECK_NEAR(fresnel_dielectric(1.0, 1.31, 1.0).reflectance, 0.0180, 5e-5);
  const double critical = std::asin(1.0 / 1.31) * 180.0 / kPi;
  CHECK_NEAR(critical, 49.76, 0.005);
  const double just_below = std::cos((critical - 0.01) * kPi / 180.0);
  const double just_above = std::cos((critical + 0.01) * kPi / 180.0);
  CHECK(fresnel_dielectric(just_below, 1.31, 1.0).reflectance < 1.0);
  CHECK(fresnel_dielectric(just_above, 1.31, 1.0).reflectance == 1.0);
  CHECK_NEAR(fresnel_dielectric(0.0, 1.0, 1.31).reflectance, 1.0, 1e-12);
  // Refraction obeys Snell's law.
  const Vec3d d = normalize(Vec3d{std::sin(0.6), 0, -std::cos(0.6)});
  const FresnelResult fr = fresnel_dielectric(std::cos(0.6), 1.0, 1.31);
  const Vec3d t = refract(d, {0, 0, 1}, 1.0, 1.31, fr.cos_t);
  CHECK_NEAR(std::sin(0.6), 1.31 * t.x, 1e-12);
  // Choosing reflection with probability F: binomial frequency test at 45 degrees.
  const double F = fresnel_dielectric(std::cos(kPi / 4), 1.0, 1.31).reflectance;
  KeyedRng rng(9, 0, StreamDomain::Test, 2);
  const int n = 200000;
  int reflected = 0;
  for (int i = 0; i < n; ++i) reflected += rng.next_double() < F;
  CHECK_NEAR(double(reflected) / n, F, 4 * std::sqrt(F * (1 - F) / n));
}

TEST_CASE("every kernel integrates to 1 within 1e-6") {
  const int n = 200000;
  for (SpatialKernel k : {SpatialKernel::Box, SpatialKernel::Epanechnikov}) {
    const double R = 0.37;
    double s1 = 0.0, s2 = 0.0;
    for (int i = 0; i < n; ++i) {
      const double u = -R + 2 * R * (i + 0.5) / n;
      s1 += spatial_kernel_1d(k, u, R) * 2 * R / n;
      const double rho = R * (i + 0.5) / n;
      s2 += spatial_kernel_2d(k, rho, R) * 2 * kPi * rho * R / n;
    }
    CHECK_NEAR(s1, 1.0, 1e-6);
    CHECK_NEAR(s2, 1.0, 1e-6);
    CHECK(spatial_kernel_1d(k, 0.3701, R) == 0.0);
  }
  for (TemporalKernel k : {TemporalKernel::Box, TemporalKernel::Epanechnikov, TemporalKernel::Quintic}) {
    const double T = 0.021;
    double s = 0.0;
    for (int i = 0; i < n; ++i) {
      const double d = -T + 2 * T * (i + 0.5) / n;
      s += temporal_kernel(k, d, T) * 2 * T / n;
    }
    CHECK_NEAR(s, 1.0, 1e-6);
    CHECK(temporal_kernel(k, -0.5 * T, T) == temporal_kernel(k, 0.5 * T, T));  // two-sided
    CHECK(temporal_kernel(k, 1.001 * T, T) == 0.0);
  }
}

TEST_CASE("schedule gamma_i matches the table of DESIGN.md §6") {
  const int idx[5] = {1, 10, 100, 1000, 10000};
  const double table[3][5] = {{0.833333, 0.493106, 0.237602, 0.110724, 0.051414},
                              {0.900000, 0.659878, 0.426249, 0.269619, 0.170161},
                              {0.785714, 0.397352, 0.155163, 0.058124, 0.021677}};
  const double alphas[3] = {2.0 / 3.0, 0.8, 4.0 / 7.0};
  for (int a = 0; a < 3; ++a) {
    CHECK_NEAR(schedule_gamma(0, alphas[a]), 1.0, 1e-12);
    for (int j = 0; j < 5; ++j) CHECK_NEAR(schedule_gamma(idx[j], alphas[a]), table[a][j], 1.5e-6);
    double product = 1.0;  // the defining product agrees with the closed form
    for (int k = 1; k <= 1000; ++k) product *= (k + alphas[a]) / (k + 1.0);
    CHECK_CLOSE(schedule_gamma(1000, alphas[a]), product, 1e-10);
  }
  CHECK_THROWS(schedule_gamma(-1, 0.5));
  CHECK_THROWS(schedule_gamma(3, 0.0));
}

TEST_CASE("closest approach against brute-force minimisation") {
  KeyedRng rng(11, 0, StreamDomain::Test, 3);
  for (int trial = 0; trial < 200; ++trial) {
    const Vec3d xc{rng.next_double(), rng.next_double(), rng.next_double()};
    const Vec3d xb{rng.next_double(), rng.next_double(), rng.next_double()};
    const Vec3d wc = sample_uniform_sphere(rng.next_double(), rng.next_double());
    const Vec3d wb = sample_uniform_sphere(rng.next_double(), rng.next_double());
    const ClosestApproach ca = closest_approach(xc, wc, xb, wb);
    if (ca.sin2 < 1e-3) continue;
    // Coarse grid then Newton-free refinement by shrinking search windows.
    double bt = 0, bs = 0, best = 1e300, span = 10.0;
    for (int level = 0; level < 12; ++level) {
      const double ct = bt, cs = bs;
      for (int i = -10; i <= 10; ++i)
        for (int j = -10; j <= 10; ++j) {
          const double t = ct + span * i / 10, s = cs + span * j / 10;
          const double dist = length((xc + wc * t) - (xb + wb * s));
          if (dist < best) {
            best = dist;
            bt = t;
            bs = s;
          }
        }
      span *= 0.3;
    }
    CHECK_NEAR(ca.t, bt, 1e-5);
    CHECK_NEAR(ca.s, bs, 1e-5);
    CHECK_NEAR(ca.u, best, 1e-7);
    CHECK_NEAR(ca.sin2, 1.0 - dot(wc, wb) * dot(wc, wb), 1e-12);
  }
}

TEST_CASE("OPL to picoseconds") {
  CHECK_NEAR(kPicosecondsPerMetreOpl, 3335.640952, 1e-6);
  CHECK_NEAR(opl_to_picoseconds(0.003), 10.007, 1e-3);
  CHECK_NEAR(picoseconds_to_opl(1.0) * 1000.0, 0.299792458, 1e-12);
  CHECK_NEAR(opl_to_picoseconds(3.0), 10007.0, 0.1);
  CHECK_NEAR(opl_to_seconds(kSpeedOfLight), 1.0, 0.0);
}

PTPB_TEST_MAIN()

// Shell transport (DESIGN.md §12, "Hops"): a table composed of smaller tables holds the same exits as
// walks taken one flight at a time, and a large ball's mean path length approaches diffusion theory.
TEST_CASE("hop tables: composed exits match single-flight walks, large balls match diffusion") {
  const int k = 4;  // R = 8 scattering lengths, composed from tables 0..3
  const double R = hop_radius(k);
  CHECK_NEAR(R, 8.0, 1e-12);
  const int n = 40000;
  double sl = 0, sl2 = 0, sc = 0, sn = 0, slast = 0, sr2 = 0, spath = 0;
  for (int i = 0; i < n; ++i) {
    KeyedRng rng(3, 0, StreamDomain::Test, i);
    Vec3d p{};
    Vec3d d = sample_uniform_sphere(rng.next_double(), rng.next_double());
    double travelled = 0.0;
    int inner = 0;
    for (;;) {
      const double s = -std::log1p(-rng.next_double());
      const double b = dot(p, d), c = dot(p, p) - R * R;
      const double exit = -b + std::sqrt(b * b - c);
      if (s >= exit) {
        travelled += exit;
        sc += dot(d, p + d * exit) / R;
        slast += exit;
        break;
      }
      p = p + d * s;
      travelled += s;
      ++inner;
      sr2 += dot(p, p);  // sums over the inner events that the sampled event must stand for
      spath += travelled;
      d = sample_uniform_sphere(rng.next_double(), rng.next_double());
    }
    sl += travelled;
    sl2 += travelled * travelled;
    sn += inner;
  }
  double tl = 0, tc = 0, tn = 0, tlast = 0, tcount = 0, tr2 = 0, tpath = 0;
  for (int i = 0; i < kHopSamples; ++i) {
    const HopExit& e = sample_hop(k, (i + 0.5) / kHopSamples);
    tl += e.length;
    tc += e.cosine;
    tn += e.scatterings;
    tlast += e.last;
    tcount += e.factor;
    tr2 += e.factor * (e.vertex[0] * e.vertex[0] + e.vertex[1] * e.vertex[1] + e.vertex[2] * e.vertex[2]);
    tpath += e.factor * e.vertex_length;
    CHECK(e.vertex_scatterings <= e.scatterings && e.vertex_length <= e.length && e.last <= e.length);
  }
  const double mean = sl / n, sd = std::sqrt(sl2 / n - mean * mean);
  const double se = sd * std::sqrt(1.0 / n + 1.0 / kHopSamples);
  CHECK_NEAR(tl / kHopSamples, mean, 4 * se);
  CHECK_NEAR(tn / kHopSamples, sn / n, 4 * se);  // one scattering per unit length, within the same noise
  CHECK_NEAR(tc / kHopSamples, sc / n, 0.01);
  CHECK_NEAR(tlast / kHopSamples, slast / n, 0.02);
  // The sampled inner event times its factor stands for the sum over all inner events: their count, the sum
  // of their squared distances from the centre and of their path lengths (within a few per cent of noise).
  CHECK_NEAR(tcount / kHopSamples / (sn / n), 1.0, 0.02);
  CHECK_NEAR(tr2 / kHopSamples / (sr2 / n), 1.0, 0.03);
  CHECK_NEAR(tpath / kHopSamples / (spath / n), 1.0, 0.03);
  CHECK_NEAR(hop_mean_scatterings(k), tn / kHopSamples, 1e-9);
  // Diffusion with the extrapolated boundary R_e = R + 0.7104 (Milne): mean track length from a point source at
  // the centre = 3 (R^2/2 - R^3/(3 R_e)); exact only as R grows, so within 3 % at the largest table.
  const int last = kHopTables - 1;
  const double Rl = hop_radius(last), Re = Rl + 0.7104;
  double ll = 0;
  for (int i = 0; i < kHopSamples; i += 4) ll += sample_hop(last, (i + 0.5) / kHopSamples).length;
  ll /= kHopSamples / 4;
  CHECK_NEAR(ll / (3.0 * (Rl * Rl / 2.0 - Rl * Rl * Rl / (3.0 * Re))), 1.0, 0.03);
}
