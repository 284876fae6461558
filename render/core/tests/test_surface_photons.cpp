// Tests of the surface photon estimator (DESIGN.md §7): the 2-D disk kernels through the gather's
// weight, the density of a synthetic uniform photon field, the hash grid against brute force,
// the surface schedule of §6 reaching the grid, and a rendered diffuse plane under the sun.
#include <algorithm>
#include <cmath>
#include <cstring>
#include <vector>

#include "check.hpp"
#include "ptpb/kernels.hpp"
#include "ptpb/render.hpp"
#include "ptpb/rng.hpp"
#include "ptpb/sampling.hpp"
#include "ptpb/surface_photons.hpp"

using namespace ptpb;

namespace {

SurfacePhoton photon_at(const Vec3d& x, const Vec3d& normal, const Vec3d& power) {
  SurfacePhoton p;
  p.position = x;
  p.normal = normal;
  p.direction = -normal;
  p.power = power;
  return p;
}

// Sum of k_r(|x - x_p|) Phi_p over the photons the grid returns and the weight accepts.
double gather_density(const SurfacePhotonGrid& grid, const std::vector<SurfacePhoton>& photons, const Vec3d& x,
                      const Vec3d& normal, SpatialKernel kernel, std::vector<std::uint32_t>& cand) {
  grid.query(x, cand);
  double sum = 0.0;
  for (std::uint32_t i : cand)
    sum += surface_photon_weight(photons[i], x, normal, grid.radius(), kernel, 0.9) * photons[i].power.x;
  return sum;
}

// A 2 x 2 m diffuse plane z = 0 (normal +z) under a sun of irradiance E, seen from 3 m above.
Scene sunlit_plane(double to_sun_deg, double E) {
  Scene sc;
  Shape plane;
  plane.kind = SurfaceKind::Diffuse;
  plane.albedo = {0.5, 0.5, 0.5};
  plane.vertices = {-1, -1, 0, 1, -1, 0, 1, 1, 0, -1, 1, 0};
  plane.faces = {0, 1, 2, 0, 2, 3};
  sc.shapes.push_back(plane);
  DirectionalLight sun;
  const double th = to_sun_deg * kPi / 180.0;
  sun.to_sun = {std::sin(th), 0.0, std::cos(th)};
  sun.irradiance = {E, E, E};
  sc.directional_lights.push_back(sun);
  sc.camera.origin = {0, 0, 3};
  sc.camera.target = {0, 0, 0};
  sc.camera.up = {0, 1, 0};
  sc.camera.fov_deg = 10;
  sc.camera.width = sc.camera.height = 8;
  return sc;
}

RenderSettings plane_settings() {
  RenderSettings s;
  s.iterations = 4;
  s.light_paths_per_iteration = 100000;
  s.initial_beam_radius = 0.05;
  s.initial_surface_radius = 0.08;
  s.max_depth = 8;
  s.seed = 2;
  s.threads = 2;
  return s;
}

}  // namespace

TEST_CASE("the gather's 2-D disk kernels integrate to 1 within 1e-6 and vanish beyond r") {
  const double r = 0.023;
  const Vec3d normal{0, 0, 1}, origin{0.3, -0.2, 0.0};
  for (SpatialKernel k : {SpatialKernel::Box, SpatialKernel::Epanechnikov}) {
    const SurfacePhoton p = photon_at(origin, normal, {1, 1, 1});
    // Polar midpoint rule around the photon; the direction in the plane varies with the angle.
    const int nr = 100000, nphi = 16;
    double integral = 0.0;
    for (int j = 0; j < nphi; ++j) {
      const double phi = 2.0 * kPi * (j + 0.5) / nphi;
      const Vec3d e{std::cos(phi), std::sin(phi), 0.0};
      for (int i = 0; i < nr; ++i) {
        const double rho = r * (i + 0.5) / nr;
        integral += surface_photon_weight(p, origin + e * rho, normal, r, k, 0.9) * rho * (r / nr) * (2.0 * kPi / nphi);
      }
    }
    CHECK_NEAR(integral, 1.0, 1e-6);
    CHECK(surface_photon_weight(p, origin + Vec3d{r * 1.0001, 0, 0}, normal, r, k, 0.9) == 0.0);
    const double centre = surface_photon_weight(p, origin, normal, r, k, 0.9);
    CHECK_CLOSE(centre, (k == SpatialKernel::Box ? 1.0 : 2.0) / (kPi * r * r), 1e-12);
    // The far side of the surface and a surface tilted by 30 degrees are rejected.
    CHECK(surface_photon_weight(p, origin, -normal, r, k, 0.9) == 0.0);
    const Vec3d tilted{std::sin(kPi / 6), 0.0, std::cos(kPi / 6)};
    CHECK(surface_photon_weight(p, origin, tilted, r, k, 0.9) == 0.0);
    CHECK(surface_photon_weight(p, origin, tilted, r, k, 0.8) > 0.0);
  }
}

TEST_CASE("a gather on a uniform photon field returns its flux density") {
  // N photons of power E A / N, uniform on the square [-1, 1]^2 (A = 4 m^2): density E W/m^2.
  // Decoys that must not count: the same number on the plane's back side (normal -z) and on a
  // wall x = 0.05 (normal +x) that crosses every query disk near x = 0.
  const double E = 2.5, A = 4.0, r = 0.1;
  const std::size_t N = 1000000;
  std::vector<SurfacePhoton> photons;
  KeyedRng rng(21, 0, StreamDomain::Test, 7);
  for (std::size_t i = 0; i < N; ++i) {
    const double x = 2.0 * rng.next_double() - 1.0, y = 2.0 * rng.next_double() - 1.0;
    photons.push_back(photon_at({x, y, 0.0}, {0, 0, 1}, Vec3d{1, 1, 1} * (E * A / N)));
    if (i % 4 == 0) photons.push_back(photon_at({x, y, 0.0}, {0, 0, -1}, Vec3d{1, 1, 1} * (100.0 * E * A / N)));
    if (i % 4 == 1) photons.push_back(photon_at({0.05, x, 0.5 * y}, {1, 0, 0}, Vec3d{1, 1, 1} * (100.0 * E * A / N)));
  }
  SurfacePhotonGrid grid;
  grid.build(photons, r);
  CHECK(grid.radius() == r);
  CHECK(grid.size() == photons.size());
  std::vector<std::uint32_t> cand;
  for (SpatialKernel k : {SpatialKernel::Box, SpatialKernel::Epanechnikov}) {
    // Var of one estimate = N Phi^2 (int k^2 dA) / A: int k^2 = 1/(pi r^2) (box), 4/(3 pi r^2) (Epanechnikov).
    const double k2 = (k == SpatialKernel::Box ? 1.0 : 4.0 / 3.0) / (kPi * r * r);
    const double sigma = std::sqrt(N * (E * A / N) * (E * A / N) * k2 / A);
    double sum = 0.0, worst = 0.0;
    int points = 0;
    // A 7 x 7 lattice of query points 0.25 m apart (disjoint disks, so nearly independent).
    for (int i = -3; i <= 3; ++i)
      for (int j = -3; j <= 3; ++j) {
        const double est = gather_density(grid, photons, {0.25 * i, 0.25 * j, 0.0}, {0, 0, 1}, k, cand);
        worst = std::max(worst, std::fabs(est - E) / sigma);
        sum += est;
        ++points;
      }
    const double mean = sum / points;
    std::printf("uniform field (%s): mean %.5f vs %.5f (%.3f%%), sigma of one gather %.3f%%, worst %.2f sigma\n",
                k == SpatialKernel::Box ? "box" : "epanechnikov", mean, E, 100.0 * (mean / E - 1.0), 100.0 * sigma / E,
                worst);
    CHECK(worst < 4.5);
    CHECK_NEAR(mean, E, 4.0 * sigma / std::sqrt(double(points)));
  }
}

TEST_CASE("grid queries return exactly the photons within r, ascending, for any radius") {
  KeyedRng rng(4, 0, StreamDomain::Test, 9);
  std::vector<SurfacePhoton> photons;
  for (int i = 0; i < 20000; ++i) {
    // A curved sheet with some spread across it, and a few far-away photons.
    const double u = 4.0 * rng.next_double() - 2.0, v = 4.0 * rng.next_double() - 2.0;
    const double w = i % 97 == 0 ? 50.0 * (rng.next_double() - 0.5) : 0.3 * std::sin(u) + 0.01 * rng.next_double();
    photons.push_back(photon_at({u, v, w}, {0, 0, 1}, {1, 1, 1}));
  }
  SurfacePhotonGrid grid;
  std::vector<std::uint32_t> got, want;
  for (double r : {0.003, 0.05, 0.4, 5.0}) {
    grid.build(photons, r);
    bool same = true;
    std::size_t total = 0;
    for (int q = 0; q < 300; ++q) {
      const Vec3d x = q % 3 == 0 ? photons[q * 37].position
                                 : Vec3d{4.4 * rng.next_double() - 2.2, 4.4 * rng.next_double() - 2.2,
                                         0.6 * rng.next_double() - 0.3};
      grid.query(x, got);
      want.clear();
      for (std::size_t i = 0; i < photons.size(); ++i) {
        const Vec3d d = photons[i].position - x;
        if (dot(d, d) < r * r) want.push_back(std::uint32_t(i));
      }
      same &= got == want;
      total += got.size();
    }
    CHECK(same);
    CHECK(total > 0);
  }
  CHECK_THROWS(grid.build(photons, 0.0));
  CHECK_THROWS(grid.build(photons, std::nan("")));
}

TEST_CASE("the surface schedule of §6 reaches the photon grid in every mode") {
  Scene sc = sunlit_plane(0.0, 1.0);
  RenderSettings s = plane_settings();
  s.iterations = 11;
  s.light_paths_per_iteration = 2000;
  s.initial_time_half_width = 0.04;
  sc.film.temporal_bins = 10;
  sc.film.start_opl = 4.0;
  sc.film.bin_width_opl = 0.01;
  sc.film.mode = FrameMode::Gate;  // alpha = 4/7: gamma_10 = 0.397352, r and T shrink by its cube root
  RenderResult r = render(sc, s);
  CHECK_CLOSE(r.stats.final_surface_radius, *s.initial_surface_radius * std::cbrt(0.397352), 1e-5);
  CHECK_CLOSE(r.stats.final_surface_time_half_width, *s.initial_time_half_width * std::cbrt(0.397352), 1e-5);
  CHECK(r.stats.surface_photons > 0);
  CHECK(r.stats.surface_pairs > 0);
  s.initial_surface_time_half_width = 0.02;
  r = render(sc, s);
  CHECK_CLOSE(r.stats.final_surface_time_half_width, 0.02 * std::cbrt(0.397352), 1e-5);
  sc.film.mode = FrameMode::Bins;  // alpha = 2/3: gamma_10 = 0.493106, r shrinks by its square root
  r = render(sc, s);
  CHECK_CLOSE(r.stats.final_surface_radius, *s.initial_surface_radius * std::sqrt(0.493106), 1e-5);
  CHECK_CLOSE(r.stats.final_surface_time_half_width, 0.02, 1e-12);
  sc.film.mode = FrameMode::Steady;
  s.surface_alpha = 0.8;  // explicit: gamma_10 = 0.659878
  r = render(sc, s);
  CHECK_CLOSE(r.stats.final_surface_radius, *s.initial_surface_radius * std::sqrt(0.659878), 1e-5);
}

TEST_CASE("a sunlit diffuse plane renders E cos(theta) rho / pi; max_depth 1 leaves it black") {
  for (double deg : {0.0, 60.0}) {
    const double E = 3.0, expected = E * std::cos(deg * kPi / 180.0) * 0.5 / kPi;
    RenderSettings s = plane_settings();
    s.iterations = 8;  // about 0.6% noise on the image mean
    const RenderResult r = render(sunlit_plane(deg, E), s);
    double mean = 0.0;
    for (float v : r.steady) mean += v;
    mean /= double(r.steady.size());
    std::printf("sunlit plane at %.0f deg: %.5f vs %.5f (%.2f%%)\n", deg, mean, expected,
                100.0 * (mean / expected - 1.0));
    CHECK_CLOSE(mean, expected, 0.03);
  }
  RenderSettings s = plane_settings();
  s.iterations = 1;
  s.max_depth = 1;  // direct light on the plane is a depth-2 path
  const RenderResult black = render(sunlit_plane(0.0, 3.0), s);
  CHECK(*std::max_element(black.steady.begin(), black.steady.end()) == 0.0f);
  s.max_depth = 2;
  const RenderResult lit = render(sunlit_plane(0.0, 3.0), s);
  CHECK(*std::min_element(lit.steady.begin(), lit.steady.end()) > 0.0f);
}

TEST_CASE("bad surface settings throw with the parameter's name") {
  const Scene sc = sunlit_plane(0.0, 1.0);
  auto message = [&](const RenderSettings& s) -> std::string {
    try {
      render(sc, s);
    } catch (const std::invalid_argument& e) {
      return e.what();
    }
    return "";
  };
  RenderSettings s = plane_settings();
  s.initial_surface_radius = 0.0;
  CHECK(message(s).find("initial_surface_radius") != std::string::npos);
  s = plane_settings();
  s.surface_alpha = 1.5;
  CHECK(message(s).find("surface_alpha") != std::string::npos);
  s = plane_settings();
  s.surface_normal_cos = 0.0;
  CHECK(message(s).find("surface_normal_cos") != std::string::npos);
  s = plane_settings();
  s.initial_surface_time_half_width = -1.0;
  CHECK(message(s).find("initial_surface_time_half_width") != std::string::npos);
}

PTPB_TEST_MAIN()
