// Snow as grains (grains.hpp, LIDAR.md §10): a photon-by-photon geometric-optics tracer through a periodic
// packing of ice spheres, accelerated by a uniform grid over the cell, and the homogeneous half-space with the
// same source, receivers and estimators.
#include "ptpb/grains.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <numeric>
#include <stdexcept>
#include <string>

#include "ptpb/parallel.hpp"
#include "ptpb/rng.hpp"
#include "ptpb/sampling.hpp"
#include "ptpb/vec.hpp"

namespace ptpb {

namespace {

constexpr std::size_t kChunk = 64;           // photons per chunk: the unit of work and of summation order
constexpr std::size_t kChunksPerGroup = 64;  // chunks between progress calls
constexpr double kInf = std::numeric_limits<double>::infinity();

// One chunk's sums; chunks are added in index order, so any thread count gives the same bits.
struct Tally {
  std::vector<double> time_flux, time_cone, air_by_bin, ice_by_bin, absorbed_depth;
  double exits = 0, cone = 0, absorbed = 0, truncated = 0, early = 0, late = 0, exit_opl = 0;
  double air = 0, ice = 0, exit_air = 0, exit_ice = 0, hits = 0, interactions = 0, tir = 0;

  explicit Tally(const GrainTraceSettings& s)
      : time_flux(s.temporal_bins, 0.0),
        time_cone(s.temporal_bins, 0.0),
        air_by_bin(s.temporal_bins, 0.0),
        ice_by_bin(s.temporal_bins, 0.0),
        absorbed_depth(s.depth_bins, 0.0) {}

  void add(const Tally& o) {
    for (std::size_t i = 0; i < time_flux.size(); ++i) {
      time_flux[i] += o.time_flux[i];
      time_cone[i] += o.time_cone[i];
      air_by_bin[i] += o.air_by_bin[i];
      ice_by_bin[i] += o.ice_by_bin[i];
    }
    for (std::size_t i = 0; i < absorbed_depth.size(); ++i) absorbed_depth[i] += o.absorbed_depth[i];
    exits += o.exits;
    cone += o.cone;
    absorbed += o.absorbed;
    truncated += o.truncated;
    early += o.early;
    late += o.late;
    exit_opl += o.exit_opl;
    air += o.air;
    ice += o.ice;
    exit_air += o.exit_air;
    exit_ice += o.exit_ice;
    hits += o.hits;
    interactions += o.interactions;
    tir += o.tir;
  }
};

// Receivers: one photon leaving with direction cosine mu at OPL `opl` after `air` and `ice` metres.
void score_exit(Tally& t, const GrainTraceSettings& s, double cos_cone, double opl, double mu, double air, double ice) {
  t.exits += 1;
  t.exit_opl += opl;
  t.exit_air += air;
  t.exit_ice += ice;
  const bool in_cone = mu >= cos_cone;
  if (in_cone) t.cone += 1;
  const double b = std::floor((opl - s.start_opl) / s.bin_width_opl);
  if (b < 0) {
    t.early += 1;
  } else if (b >= s.temporal_bins) {
    t.late += 1;
  } else {
    const auto i = static_cast<std::size_t>(b);
    t.time_flux[i] += 1;
    t.air_by_bin[i] += air;
    t.ice_by_bin[i] += ice;
    if (in_cone) t.time_cone[i] += 1;
  }
}

// Track-length estimate of absorbed energy: `absorbed` deposited at depth -z (depths above z = 0 go to bin 0).
void score_absorption(Tally& t, const GrainTraceSettings& s, double z, double absorbed) {
  const double b = std::floor(std::max(0.0, -z) / s.depth_bin_width);
  if (b < s.depth_bins) t.absorbed_depth[static_cast<std::size_t>(b)] += absorbed;
}

void check_settings(const GrainTraceSettings& s) {
  if (s.temporal_bins < 1 || s.depth_bins < 1)
    throw std::invalid_argument("temporal_bins and depth_bins must be at least 1");
  if (!(s.bin_width_opl > 0) || !(s.depth_bin_width > 0))
    throw std::invalid_argument("bin_width_opl and depth_bin_width must be positive");
  if (!(s.max_path > 0)) throw std::invalid_argument("max_path must be positive (metres of geometric path)");
  if (!(s.cone_half_angle > 0 && s.cone_half_angle <= kPi / 2))
    throw std::invalid_argument("cone_half_angle must lie in (0, pi/2] radians");
}

// The loop apart from the estimator: photons in fixed chunks, chunks in fixed groups, sums in index order.
template <typename TracePhoton>
GrainTraceResult run_photons(const GrainTraceSettings& s, const GrainProgress& progress, TracePhoton&& trace) {
  check_settings(s);
  GrainTraceResult r;
  Tally total(s);
  const std::size_t n = s.photons;
  const std::size_t group = kChunk * kChunksPerGroup;
  std::uint64_t done = 0;
  for (std::size_t g0 = 0; g0 < n; g0 += group) {
    const std::size_t g1 = std::min(n, g0 + group);
    const std::size_t chunks = (g1 - g0 + kChunk - 1) / kChunk;
    std::vector<Tally> tallies(chunks, Tally(s));
    parallel_for_chunks(g1 - g0, kChunk, s.threads, [&](std::size_t begin, std::size_t end) {
      Tally& t = tallies[begin / kChunk];
      for (std::size_t i = begin; i < end; ++i) trace(g0 + i, t);
    });
    for (const Tally& t : tallies) total.add(t);
    done = g1;
    if (progress && !progress(done, n)) {
      r.cancelled = done < n;
      break;
    }
  }
  r.photons_done = done;
  const double inv = done > 0 ? 1.0 / static_cast<double>(done) : 0.0;
  auto scaled = [inv](std::vector<double> v) {
    for (double& x : v) x *= inv;
    return v;
  };
  r.time_flux = scaled(std::move(total.time_flux));
  r.time_cone = scaled(std::move(total.time_cone));
  r.air_by_bin = scaled(std::move(total.air_by_bin));
  r.ice_by_bin = scaled(std::move(total.ice_by_bin));
  r.absorbed_depth = scaled(std::move(total.absorbed_depth));
  r.albedo = total.exits * inv;
  r.cone_fraction = total.cone * inv;
  r.absorbed = total.absorbed * inv;
  r.truncated = total.truncated * inv;
  r.early = total.early * inv;
  r.late = total.late * inv;
  r.exit_opl = total.exit_opl * inv;
  r.air_path = total.air * inv;
  r.ice_path = total.ice * inv;
  r.exit_air_path = total.exit_air * inv;
  r.exit_ice_path = total.exit_ice * inv;
  r.sphere_hits = total.hits * inv;
  r.interactions = total.interactions * inv;
  r.total_internal_reflections = total.tir * inv;
  return r;
}

// A sphere registered in one grid cell: its index and the lattice shift (in periods) of its image nearest that
// cell of the base period. Eight bytes, so a cell's list is one cache line; the spheres themselves are few.
struct CellSphere {
  std::uint32_t id;
  std::int8_t kx, ky, kz;
};
struct Sphere {
  double x, y, z, radius;
};

// The uniform grid over the periodic cell: every sphere listed in every cell its bounding box overlaps
// (with periodic wrap). z is stored as u = z + Lc, so the base period is [0, Lc)^3. The periods below are
// sheared: the lattice is a1 = (Lc, 0, 0), a2 = (0, Lc, 0), a3 = (mx, my, g) h, so that a vertical line meets
// g different columns of the cell before it repeats, and the nadir beam finds no straight channel to fall down.
struct PackingGrid {
  double cell_size = 0, h = 0, inv_h = 0, u_top = 0;
  int g = 1, mx = 0, my = 0;
  std::vector<std::uint32_t> start;  // (g^3 + 1) offsets into entries
  std::vector<CellSphere> entries;
  std::vector<Sphere> spheres;  // u = z + Lc

  std::size_t cell(int ix, int iy, int iz) const {
    return (static_cast<std::size_t>(iz) * g + static_cast<std::size_t>(iy)) * g + static_cast<std::size_t>(ix);
  }
};

int floor_div(int a, int b) { return a >= 0 ? a / b : -((-a + b - 1) / b); }

PackingGrid build_grid(const GrainPacking& p) {
  const std::size_t n = p.radii.size();
  if (!(p.cell_size > 0)) throw std::invalid_argument("cell_size must be positive (metres)");
  if (n == 0) throw std::invalid_argument("the packing holds no spheres");
  if (p.centres.size() != 3 * n) throw std::invalid_argument("centres must have shape (N, 3) matching radii (N,)");
  const double lc = p.cell_size;
  double mean_r = 0, max_r = 0, top = -kInf;
  for (std::size_t i = 0; i < n; ++i) {
    const double x = p.centres[3 * i], y = p.centres[3 * i + 1], z = p.centres[3 * i + 2], r = p.radii[i];
    if (!(r > 0) || !(x >= 0 && x < lc && y >= 0 && y < lc && z >= -lc && z < 0))
      throw std::invalid_argument("sphere " + std::to_string(i) +
                                  " must have radius > 0 and centre in x, y in [0, Lc), z in [-Lc, 0)");
    mean_r += r;
    max_r = std::max(max_r, r);
    top = std::max(top, z + r);
  }
  mean_r /= static_cast<double>(n);
  if (2 * max_r >= lc) throw std::invalid_argument("spheres must be smaller than the cell (2 r < Lc)");
  PackingGrid grid;
  grid.cell_size = lc;
  // About 1.4 radii a cell: a few spheres to test per cell, and few cells per air chord (the fastest of 1, 1.4, 2).
  grid.g = std::clamp(static_cast<int>(std::lround(0.7 * lc / mean_r)), 1, 256);
  grid.h = lc / grid.g;
  grid.inv_h = 1.0 / grid.h;
  grid.u_top = top + lc;
  const int g = grid.g;
  // Shear steps near the golden sections of g, coprime with it: the columns a vertical line visits spread out.
  auto coprime_near = [g](double f) {
    int m = std::max(1, static_cast<int>(std::lround(f * g)));
    while (std::gcd(m, g) != 1) ++m;
    return g == 1 ? 0 : m % g;
  };
  grid.mx = coprime_near(0.381966);
  grid.my = coprime_near(0.618034);
  std::vector<std::vector<CellSphere>> lists(static_cast<std::size_t>(g) * g * g);
  for (std::size_t i = 0; i < n; ++i) {
    const double c[3] = {p.centres[3 * i], p.centres[3 * i + 1], p.centres[3 * i + 2] + lc};
    const double r = p.radii[i];
    int lo[3], hi[3];
    for (int a = 0; a < 3; ++a) {
      lo[a] = static_cast<int>(std::floor((c[a] - r) * grid.inv_h));
      hi[a] = static_cast<int>(std::floor((c[a] + r) * grid.inv_h));
    }
    for (int iz = lo[2]; iz <= hi[2]; ++iz)
      for (int iy = lo[1]; iy <= hi[1]; ++iy)
        for (int ix = lo[0]; ix <= hi[0]; ++ix) {
          const int kz = floor_div(iz, g);
          const int jx = ix - kz * grid.mx, jy = iy - kz * grid.my;
          const int kx = floor_div(jx, g), ky = floor_div(jy, g);
          lists[grid.cell(jx - kx * g, jy - ky * g, iz - kz * g)].push_back(
              {static_cast<std::uint32_t>(i), static_cast<std::int8_t>(kx), static_cast<std::int8_t>(ky),
               static_cast<std::int8_t>(kz)});
        }
  }
  grid.start.assign(lists.size() + 1, 0);
  for (std::size_t c = 0; c < lists.size(); ++c)
    grid.start[c + 1] = grid.start[c] + static_cast<std::uint32_t>(lists[c].size());
  grid.entries.reserve(grid.start.back());
  for (const auto& l : lists) grid.entries.insert(grid.entries.end(), l.begin(), l.end());
  for (std::size_t i = 0; i < n; ++i)
    grid.spheres.push_back({p.centres[3 * i], p.centres[3 * i + 1], p.centres[3 * i + 2] + lc, p.radii[i]});
  return grid;
}

struct Hit {
  double t = kInf;
  Vec3d centre;
  double radius = 0;
  std::uint32_t id = 0;
};

// The first sphere image (centre below z = 0) that the ray p + t d meets in air, by a 3D DDA through the periodic
// grid; `skip` is the image the ray leaves (a convex body cannot be met again at once). t = inf: the ray
// rises above the highest grain and leaves the snow. p is in (x, y, u = z + Lc) coordinates.
Hit first_hit(const PackingGrid& grid, const Vec3d& p, const Vec3d& d, const Hit& skip, double t_max) {
  const int g = grid.g;
  const double h = grid.h, lc = grid.cell_size, inv_g = 1.0 / g;
  int idx[3], step[3];
  double t_next[3], t_delta[3];
  for (int a = 0; a < 3; ++a) {
    idx[a] = static_cast<int>(std::floor(p[a] * grid.inv_h));
    if (d[a] > 0) {
      step[a] = 1;
      t_next[a] = ((idx[a] + 1) * h - p[a]) / d[a];
      t_delta[a] = h / d[a];
    } else if (d[a] < 0) {
      step[a] = -1;
      t_next[a] = (idx[a] * h - p[a]) / d[a];
      t_delta[a] = -h / d[a];
    } else {
      step[a] = 0;
      t_next[a] = kInf;
      t_delta[a] = kInf;
    }
  }
  const double skip_tol = 1e-9 * lc * lc;
  Hit best;
  for (;;) {
    if (d.z > 0 && idx[2] * h >= grid.u_top) return best;  // above every grain, rising: gone
    // floor(i / g) by a multiply: i + 1/2 keeps the quotient half a step from an integer.
    const int kz = static_cast<int>(std::floor((idx[2] + 0.5) * inv_g));
    const int jx = idx[0] - kz * grid.mx, jy = idx[1] - kz * grid.my;
    const int kx = static_cast<int>(std::floor((jx + 0.5) * inv_g)),
              ky = static_cast<int>(std::floor((jy + 0.5) * inv_g));
    const std::size_t c = grid.cell(jx - kx * g, jy - ky * g, idx[2] - kz * g);
    const double t_exit = std::min(t_next[0], std::min(t_next[1], t_next[2]));
    for (std::uint32_t k = grid.start[c]; k < grid.start[c + 1]; ++k) {
      const CellSphere& e = grid.entries[k];
      const Sphere& s = grid.spheres[e.id];
      const int sx = kx - e.kx, sy = ky - e.ky, sz = kz - e.kz;
      const Vec3d centre{s.x + sx * lc + sz * grid.mx * h, s.y + sy * lc + sz * grid.my * h, s.z + sz * lc};
      if (centre.z >= lc) continue;  // an image above z = 0: air
      const Vec3d oc = p - centre;
      const double b = dot(oc, d);
      if (b > 0) continue;  // moving away from the centre, outside: no hit ahead
      const double cc = dot(oc, oc) - s.radius * s.radius;
      const double disc = b * b - cc;
      if (disc < 0) continue;
      if (e.id == skip.id && skip.radius > 0) {
        const Vec3d dc = centre - skip.centre;
        if (dot(dc, dc) < skip_tol) continue;
      }
      const double t = -b - std::sqrt(disc);
      if (t > 0 && t < best.t) best = {t, centre, s.radius, e.id};
    }
    if (best.t <= t_exit) return best;
    if (t_exit > t_max) return best;  // past the path cap: the caller truncates
    const int a = t_next[0] < t_next[1] ? (t_next[0] < t_next[2] ? 0 : 2) : (t_next[1] < t_next[2] ? 1 : 2);
    idx[a] += step[a];
    t_next[a] += t_delta[a];
  }
}

enum class SphereExit { Reflected, Transmitted, Absorbed };

// A photon meeting a sphere at q (relative to the centre, |q| = r) with direction d from outside: Fresnel at the
// surface, then chords inside until it refracts out or the ice absorbs it. Every internal chord meets the
// surface at the refraction angle, so total internal reflection cannot happen (counted in `tir` to show it).
// `ice_left`: ice path before absorption (analog); `weight` (optional) instead carries exp(-gamma l).
template <typename OnChord>
SphereExit cross_sphere(Vec3d& q, Vec3d& d, double r, const GrainOptics& o, KeyedRng& rng, double& ice_left,
                        double& interactions, double& tir, OnChord&& on_chord) {
  Vec3d n = q / r;
  const FresnelResult outer = fresnel_dielectric(-dot(d, n), 1.0, o.ice_index);
  interactions += 1;
  if (rng.next_double() < outer.reflectance) {
    d = normalize(reflect(d, n));
    return SphereExit::Reflected;
  }
  d = refract(d, n, 1.0, o.ice_index, outer.cos_t);
  for (;;) {
    const double chord = std::max(0.0, -2.0 * dot(q, d));
    if (chord >= ice_left) {
      on_chord(q, d, ice_left);
      q = q + d * ice_left;
      return SphereExit::Absorbed;
    }
    on_chord(q, d, chord);
    ice_left -= chord;
    q = q + d * chord;
    q = q * (r / length(q));
    n = q / r;
    const FresnelResult inner = fresnel_dielectric(dot(d, n), o.ice_index, 1.0);
    interactions += 1;
    if (inner.cos_t == 0.0) tir += 1;
    if (rng.next_double() < inner.reflectance) {
      d = normalize(reflect(d, n));
      continue;
    }
    d = refract(d, -n, o.ice_index, 1.0, inner.cos_t);
    return SphereExit::Transmitted;
  }
}

}  // namespace

GrainTraceResult trace_packing(const GrainPacking& packing, const GrainOptics& optics,
                               const GrainTraceSettings& settings, const GrainProgress& progress) {
  if (!(optics.ice_index > 1) || !(optics.ice_group_index >= 1) || !(optics.ice_absorption >= 0))
    throw std::invalid_argument("ice_index must exceed 1, ice_group_index be at least 1, ice_absorption >= 0");
  const PackingGrid grid = build_grid(packing);
  const double lc = grid.cell_size, z_top = grid.u_top - lc;
  const double cos_cone = std::cos(settings.cone_half_angle);
  const double gamma = optics.ice_absorption, ng = optics.ice_group_index;
  return run_photons(settings, progress, [&](std::size_t index, Tally& t) {
    KeyedRng rng(settings.seed, 0, StreamDomain::Grains, index);
    Vec3d p{rng.next_double() * lc, rng.next_double() * lc, grid.u_top};
    Vec3d d{0.0, 0.0, -1.0};
    // Ice path before absorption, drawn once: exp(-gamma l) survival, exactly.
    const double u_abs = rng.next_double();
    double ice_left = gamma > 0 ? -std::log1p(-u_abs) / gamma : kInf;
    double air = 0, ice = 0, interactions = 0, tir = 0, hits = 0;
    Hit last;
    auto on_chord = [&](const Vec3d& q, const Vec3d& dir, double len) {
      ice += len;
      if (gamma > 0) score_absorption(t, settings, last.centre.z - lc + q.z + 0.5 * len * dir.z, gamma * len);
    };
    for (;;) {
      // Keep x, y within the base period: the grid wraps, and small numbers keep their precision.
      p.x -= std::floor(p.x / lc) * lc;
      p.y -= std::floor(p.y / lc) * lc;
      const double path_left = settings.max_path - air - ice;
      const Hit hit = first_hit(grid, p, d, last, path_left);
      if (hit.t == kInf && d.z > 0 && path_left > (grid.u_top - p.z) / d.z) {
        air += (grid.u_top - p.z) / d.z;  // up to the plane the photons started from
        const double opl = air + ng * ice - z_top * (1.0 + 1.0 / d.z);
        score_exit(t, settings, cos_cone, opl, d.z, air, ice);
        break;
      }
      if (hit.t > path_left) {
        air += path_left;
        t.truncated += 1;
        break;
      }
      air += hit.t;
      hits += 1;
      last = hit;
      Vec3d q = p + d * hit.t - hit.centre;
      q = q * (hit.radius / length(q));
      const SphereExit e = cross_sphere(q, d, hit.radius, optics, rng, ice_left, interactions, tir, on_chord);
      if (e == SphereExit::Absorbed) {
        t.absorbed += 1;
        break;
      }
      p = hit.centre + q;
    }
    t.air += air;
    t.ice += ice;
    t.hits += hits;
    t.interactions += interactions;
    t.tir += tir;
  });
}

GrainTraceResult trace_homogeneous(const HomogeneousMedium& m, const GrainTraceSettings& settings,
                                   const GrainProgress& progress) {
  if (!(m.scattering >= 0 && m.absorption >= 0 && m.scattering + m.absorption > 0))
    throw std::invalid_argument("scattering and absorption must be >= 0 and not both 0 (m^-1)");
  if (!(m.asymmetry > -1 && m.asymmetry < 1)) throw std::invalid_argument("asymmetry must lie in (-1, 1)");
  if (!(m.time_index >= 1)) throw std::invalid_argument("time_index must be at least 1");
  const double sigma_t = m.scattering + m.absorption, albedo = m.scattering / sigma_t;
  const double cos_cone = std::cos(settings.cone_half_angle);
  return run_photons(settings, progress, [&](std::size_t index, Tally& t) {
    KeyedRng rng(settings.seed, 0, StreamDomain::Grains, index);
    Vec3d p{0.0, 0.0, 0.0}, d{0.0, 0.0, -1.0};
    double path = 0, events = 0;
    for (;;) {
      const double s = -std::log1p(-rng.next_double()) / sigma_t;
      const double to_surface = d.z > 0 ? -p.z / d.z : kInf;
      const double step = std::min({s, to_surface, settings.max_path - path});
      score_absorption(t, settings, p.z + 0.5 * step * d.z, m.absorption * step);
      path += step;
      if (step == to_surface) {
        score_exit(t, settings, cos_cone, m.time_index * path, d.z, path, 0.0);
        break;
      }
      if (step < s) {
        t.truncated += 1;
        break;
      }
      p = p + d * step;
      events += 1;
      if (rng.next_double() >= albedo) {
        t.absorbed += 1;
        break;
      }
      d = hg_sample(d, m.asymmetry, rng.next_double(), rng.next_double());
    }
    t.air += path;
    t.hits += events;
  });
}

SphereScatter scatter_sphere(double radius, const GrainOptics& optics, std::uint64_t rays, std::uint64_t seed) {
  if (!(radius > 0) || rays == 0) throw std::invalid_argument("radius must be positive and rays at least 1");
  SphereScatter out;
  double scattered = 0.0;
  const double gamma = optics.ice_absorption;
  for (std::uint64_t i = 0; i < rays; ++i) {
    KeyedRng rng(seed, 1, StreamDomain::Grains, i);
    // Uniform over the cross-section, travelling -z onto the upper hemisphere.
    const double b = radius * std::sqrt(rng.next_double()), phi = 2.0 * kPi * rng.next_double();
    Vec3d q{b * std::cos(phi), b * std::sin(phi), std::sqrt(std::max(0.0, radius * radius - b * b))};
    Vec3d d{0.0, 0.0, -1.0};
    double weight = 1.0, absorbed = 0.0, ice = 0.0, interactions = 0.0, tir = 0.0, ice_left = kInf;
    auto on_chord = [&](const Vec3d&, const Vec3d&, double len) {
      const double survive = std::exp(-gamma * len);
      absorbed += weight * (1.0 - survive);
      weight *= survive;
      ice += len;
    };
    cross_sphere(q, d, radius, optics, rng, ice_left, interactions, tir, on_chord);
    out.absorbed += absorbed;
    out.mean_ice_path += ice;
    out.mean_cos += weight * -d.z;
    scattered += weight;
    out.energy_out += weight + absorbed;
    out.total_internal_reflections += tir;
  }
  const double inv = 1.0 / static_cast<double>(rays);
  out.absorbed *= inv;
  out.mean_ice_path *= inv;
  out.mean_cos /= scattered;
  out.energy_out *= inv;
  out.total_internal_reflections *= inv;
  return out;
}

}  // namespace ptpb
