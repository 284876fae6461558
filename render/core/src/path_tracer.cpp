// Transient path tracing in dense media (DESIGN.md §12). Unidirectional, with next-event estimation
// to point, area, sun and sky lights combined with phase/BSDF sampling by the power heuristic where
// both can make the same path (area lights and the sky seen through index-matched boundaries only).
#include "ptpb/path_tracer.hpp"

#include <algorithm>
#include <cmath>
#include <limits>

#include "ptpb/free_flight.hpp"
#include "ptpb/hops.hpp"
#include "ptpb/sampling.hpp"

namespace ptpb {
namespace {

double power_heuristic(double used, double other) {
  const double a = used * used, b = other * other;
  return a + b > 0 ? a / (a + b) : 0.0;
}

// Clearance (DESIGN.md §12): a vertex that knows no surface lies within c of it takes a free flight
// shorter than c without a ray. The ball the scene was asked about stays with the path: a vertex at p
// inside the ball (q, c_q) is at least c_q - |p - q| from every surface, which a random walk uses up
// as its displacement (about sqrt(n) flights), not its path length (n flights). It asks the scene again
// once that falls below kClearanceRequery mean free paths, searching kClearanceReach of the thinnest
// channel's mean free paths (at most the scene's diameter).
constexpr double kClearanceRequery = 1.0;
constexpr double kClearanceReach = 32.0;
// Next-event estimation from a vertex whose shadow ray must cross c of its medium (transmittance at most
// exp(-sigma_t,min c)) is kept with probability min(1, that bound / kNeeBound) and divided by it. At 0.01
// the late frames of the diffusion slab, lit from deep vertices only, grew noisy enough to bias their
// log-fit (sigma_a +4 to +6 %); at 1e-4 they match the roulette-free renderer.
constexpr double kNeeBound = 1e-4;

// Hops (DESIGN.md §12, "Hops"). At a scattering vertex x with clearance c, in a medium that scatters
// isotropically, the walk until it first leaves a ball B(x, R) with R <= c - kHopMargin mean free paths is
// replaced by one walk drawn from the tables of hops.hpp: its exit (a point on the sphere, a direction, a
// path length L and n inner collisions), with time tau += ior L and weight exp(-sigma_a L) per channel
// (times the ratio of the channels' scattering densities, (sigma_s,c / sigma_s,h)^n exp(-(sigma_s,c -
// sigma_s,h) L), where sigma_s is chromatic and the walk was drawn for channel h). The next-event estimates
// of the skipped events are made at one of them, z_J, which stands for all: the table's factor makes
// factor * estimate(z_J) unbiased for their sum. Light that the exit flight meets directly is the last
// skipped event's, weighed by MIS from there (the table holds how far back it lies). R is the largest table
// radius that fits, if its mean saves at least kHopMinSaving collisions.
constexpr double kHopMinSaving = 4.0;
// Mean free paths (of the thinnest channel) kept between a hop's ball and every surface, so that the
// skipped events' shadow rays cross some medium and z_J's estimate stays bounded.
constexpr double kHopMargin = 1.0;
// In a chromatic medium the log of a channel's weight after a hop of n collisions spreads by about
// n delta^2 (delta the channels' relative spread in sigma_s); tables whose mean n delta^2 exceeds this are
// not used.
constexpr double kHopChromaticSpread = 0.1;
// Where hops are possible the clearance query searches this many of the thinnest channel's mean free paths.
constexpr double kHopClearanceReach = 64.0;

// Whether the medium of a vertex allows hops, and the constants a hop needs.
struct HopMedium {
  bool on = false;
  double sigma_t_min = 0.0;  // the thinnest channel's extinction
  double delta2 = 0.0;       // largest (sigma_s,c / sigma_s,min - 1)^2
  double useful = 0.0;       // the least clearance at which a hop can save kHopMinSaving collisions
};

HopMedium hop_medium(const CompiledScene& cs, const RenderSettings& st, int medium) {
  HopMedium h;
  if (!st.path_hops || st.max_depth >= 0 || !cs.scattering(medium)) return h;
  const Medium& m = cs.scene().media[medium];
  const double smin = min_component(m.sigma_s), smax = max_component(m.sigma_s);
  if (m.g != 0.0 || !(smin > 0)) return h;
  h.on = true;
  h.sigma_t_min = min_component(m.sigma_t());
  h.delta2 = (smax / smin - 1.0) * (smax / smin - 1.0);
  // The smallest table with a mean above kHopMinSaving, behind the margin.
  int k = 0;
  while (k + 1 < kHopTables && hop_mean_scatterings(k) < kHopMinSaving) ++k;
  h.useful = kHopMargin / h.sigma_t_min + hop_radius(k) / smax;
  return h;
}

// Splitting in time (DESIGN.md §12, "Splitting in time"): in a bins or gate film a path stands for n = 2^l
// copies of itself, l the number of the thresholds W/2^L, ..., W/4, W/2 (W the film's length, L =
// path_splits) that its OPL past its first vertex has passed; once it can light no frame it stands for
// one again. A path whose n grows splits into copies that each carry 1/ratio of its weight; one whose n
// falls is rouletted with the ratio. Either way the estimate keeps its expectation.
struct TimeSplitting {
  double origin_tau = 0.0;  // tau of the path's first vertex
  double tail_start = 0.0;  // film OPL past which no frame receives light
  int levels = 0;           // 0: no splitting
  double thresholds[kMaxPathSplits] = {};

  double copies(double tau, double film_tau) const {
    if (levels == 0 || film_tau > tail_start) return 1.0;
    const double excess = tau - origin_tau;
    int l = 0;
    while (l < levels && excess >= thresholds[l]) ++l;
    return static_cast<double>(1 << l);
  }
};

TimeSplitting time_splitting(const Film& film, const RenderSettings& st, double time_half_width, double origin_tau) {
  TimeSplitting ts;
  if (film.mode == FrameMode::Steady || film.temporal_bins <= 0 || st.path_splits <= 0) return ts;
  const double length = film.temporal_bins * film.bin_width_opl;
  ts.origin_tau = origin_tau;
  ts.tail_start = film.start_opl + length + (film.mode == FrameMode::Gate ? time_half_width : 0.0);
  ts.levels = std::min(st.path_splits, kMaxPathSplits);
  for (int k = 0; k < ts.levels; ++k) ts.thresholds[k] = std::ldexp(length, k - ts.levels);
  return ts;
}

void walk(const CameraPass& p, const PixelSplat& splat, KeyedRng& rng, const PathVertex& start, TileStats& ts,
          const TimeSplitting& split, double copies);

}  // namespace

std::vector<char> media_using_paths(const CompiledScene& cs, const RenderSettings& st, double radius) {
  const Scene& scene = cs.scene();
  std::vector<char> paths(scene.media.size(), 0);
  for (std::size_t m = 0; m < scene.media.size(); ++m) {
    if (!cs.scattering(static_cast<int>(m))) continue;
    if (st.medium_estimator == MediumEstimator::Paths) {
      paths[m] = 1;
    } else if (st.medium_estimator == MediumEstimator::Auto) {
      const double sigma = max_component(scene.media[m].sigma_t());
      paths[m] = radius * sigma > st.beam_radius_mfp || sigma * cs.sphere_radius() > st.dense_optical_radius;
    }
  }
  return paths;
}

std::vector<double> specular_beam_radii(const CompiledScene& cs, const RenderSettings& st,
                                        const std::vector<char>& path_media, double radius, double initial_radius) {
  const Scene& scene = cs.scene();
  std::vector<double> radii(scene.media.size(), 0.0);
  for (std::size_t m = 0; m < scene.media.size(); ++m) {
    if (!path_media[m]) continue;
    const double unbiased = st.beam_radius_mfp / max_component(scene.media[m].sigma_t());
    radii[m] = std::min(initial_radius, unbiased) * (radius / initial_radius);
  }
  return radii;
}

void trace_path(const CameraPass& p, const PixelSplat& splat, KeyedRng& rng, const PathVertex& start, TileStats& ts) {
  const TimeSplitting split = time_splitting(splat.film, *p.st, p.time_half_width, start.tau);
  walk(p, splat, rng, start, ts, split, 1.0);
}

namespace {

void walk(const CameraPass& p, const PixelSplat& splat, KeyedRng& rng, const PathVertex& start, TileStats& ts,
          const TimeSplitting& split, double copies) {
  const CompiledScene& cs = *p.cs;
  const Scene& scene = cs.scene();
  const RenderSettings& st = *p.st;
  const double T = p.time_half_width;
  // camera_unwarp drops the camera leg up to the first vertex, where the estimate is made (§1).
  const double unwarp = st.camera_unwarp ? start.tau : 0.0;
  const bool sky = max_component(scene.environment_radiance) > 0;
  // A path with k non-null interactions has Mitsuba depth k + 1 (§3).
  auto within_depth = [&](int interactions) { return st.max_depth < 0 || interactions + 1 <= st.max_depth; };

  PathVertex v = start;
  HopMedium hm;  // of medium hop_of, refreshed when the walk enters another medium
  int hop_of = -2;
  for (int guard = 0; guard < 10000000; ++guard) {
    if (!within_depth(v.interactions)) return;
    // Splitting in time: the copies this path should stand for at this vertex.
    if (split.levels > 0) {
      const double wanted = split.copies(v.tau, v.tau - unwarp);
      if (wanted < copies) {
        if (!(rng.next_double() < wanted / copies)) return;
        v.weight = v.weight * (copies / wanted);
        copies = wanted;
      } else if (wanted > copies) {
        const int ratio = static_cast<int>(std::lround(wanted / copies));
        v.weight = v.weight / static_cast<double>(ratio);
        for (int c = 1; c < ratio; ++c) {
          KeyedRng child(rng.next_u64(), 0, StreamDomain::PathSplit, static_cast<std::uint64_t>(c));
          ++ts.path_splits;
          walk(p, splat, child, v, ts, split, wanted);
        }
        copies = wanted;
      }
    }
    ++ts.path_vertices;
    const double g = v.surface ? 0.0 : scene.media[v.medium].g;
    // 0. The vertex's clearance: how far it is from every surface (medium vertices only).
    double clearance = 0.0, nee_keep = 1.0;
    if (!v.surface) {
      if (hop_of != v.medium) {
        hm = hop_medium(cs, st, v.medium);
        hop_of = v.medium;
      }
      const Vec3d sigma_t = scene.media[v.medium].sigma_t();
      const double from_centre = length(v.position - v.clear_centre);
      clearance = v.clear_radius > 0 ? v.clear_radius - from_centre : 0.0;
      const double thinnest = min_component(sigma_t);
      const double diameter = 2.0 * cs.sphere_radius();
      const double reach =
          thinnest > 0 ? std::min((hm.on ? kHopClearanceReach : kClearanceReach) / thinnest, diameter) : diameter;
      // Asked again where a hop might fit: the nearest surface may be as far as clear_radius + |p - q| when
      // the last query found one, and the walk has moved two mean free paths since.
      const bool hop_worth_asking = hm.on && clearance < hm.useful &&
                                    (v.clear_radius >= 0.999 * reach || v.clear_radius + from_centre >= hm.useful) &&
                                    from_centre * thinnest >= 2.0;
      if (clearance < kClearanceRequery / max_component(sigma_t) || hop_worth_asking) {
        // The last query found a surface at clear_radius from its centre (less the float margin that
        // CompiledScene::clearance takes off), so none is farther than that plus the walk's displacement: a
        // search bounded there, with room for both margins, visits fewer triangles and finds the same one.
        const bool bounded = v.clear_radius > 0 && v.clear_radius < 0.999 * reach;
        const Vec3d& p = v.position;
        const double slack = 1e-5 * (1.0 + std::max({std::fabs(p.x), std::fabs(p.y), std::fabs(p.z)}));
        clearance = cs.clearance(p, bounded ? std::min(reach, 1.001 * (v.clear_radius + from_centre) + slack) : reach);
        v.clear_centre = v.position;
        v.clear_radius = clearance;
        ++ts.path_clearance_queries;
      }
      if (clearance > 0 && cs.lights_beyond_surfaces())
        nee_keep = std::min(1.0, std::exp(-thinnest * clearance) / kNeeBound);
    }
    // 1. Next-event estimation (kept with probability nee_keep).
    LightConnection c;
    const bool nee = nee_keep >= 1.0 || rng.next_double() < nee_keep;
    if (nee && cs.connect_light(rng, v.position, v.medium, !v.surface, c)) {
      double f, pdf_scatter;
      if (v.surface) {
        const double cosine = dot(c.direction, v.normal);
        f = cosine > 0 ? cosine / kPi : 0.0;
        pdf_scatter = f;
      } else {
        // Light arrives along -c.direction and leaves towards the camera along -incoming.
        f = hg_eval(dot(c.direction, v.incoming), g);
        pdf_scatter = f;
      }
      if (f > 0) {
        const double mis = c.pdf > 0 ? power_heuristic(c.pdf, pdf_scatter) : 1.0;
        Vec3d value = v.weight * c.value * (f * mis / nee_keep);
        if (v.surface) value = value * v.albedo;
        splat.add(v.tau + c.tau - unwarp, value, c.timeless, T);
        ++ts.path_connections;
      }
    }
    // 2. A hop across the vertex's surface-free ball, or the next direction (weight f/pdf is 1 for HG and the
    // albedo for Lambert). `origin` is where the coming flight started: after a hop, the last skipped event.
    Vec3d dir, pos = v.position, origin = v.position;
    double pdf_dir = 0.0, tau = v.tau, start_clearance = clearance;
    Vec3d weight = v.weight;
    int interactions = v.interactions;
    bool hopped = false;
    if (hm.on && clearance >= hm.useful) {
      const Medium& m = scene.media[v.medium];
      const int h = pick_channel(channel_probabilities(weight), rng.next_double());
      const double sh = m.sigma_s[h], scale = 1.0 / sh;
      int best = -1;
      for (int k = 0; k < kHopTables; ++k) {
        const double mean = hop_mean_scatterings(k);
        if (clearance - hop_radius(k) * scale < kHopMargin / hm.sigma_t_min || mean * hm.delta2 > kHopChromaticSpread)
          break;
        if (mean >= kHopMinSaving) best = k;
      }
      if (best >= 0) {
        // The channels' weights over a stretch of the walk with n collisions and length L.
        auto stretch = [&](double n, double L) {
          Vec3d f;
          for (int ch = 0; ch < 3; ++ch)
            f[ch] = std::exp(n * std::log(m.sigma_s[ch] * scale) - (m.sigma_s[ch] - sh) * L - m.sigma_a[ch] * L);
          return f;
        };
        const HopExit& e = sample_hop(best, rng.next_double());
        const double u1 = rng.next_double(), u2 = rng.next_double(), u3 = rng.next_double();
        const HopFrame frame(u1, u2, u3);
        // The skipped events' next-event estimates, made at z_J, kept like any vertex's by its clearance.
        if (e.scatterings > 0) {
          const Vec3d z = v.position + frame.vertex(e) * scale;
          const double to_z = e.vertex_length * scale;
          double keep = 1.0;
          if (cs.lights_beyond_surfaces())
            keep =
                std::min(1.0, e.factor * std::exp(-hm.sigma_t_min * (clearance - length(z - v.position))) / kNeeBound);
          LightConnection cz;
          if ((keep >= 1.0 || rng.next_double() < keep) && cs.connect_light(rng, z, v.medium, true, cz)) {
            const double mis = cz.pdf > 0 ? power_heuristic(cz.pdf, kInvFourPi) : 1.0;
            const Vec3d value =
                weight * stretch(e.vertex_scatterings, to_z) * cz.value * (kInvFourPi * mis * e.factor / keep);
            splat.add(v.tau + m.ior * to_z + cz.tau - unwarp, value, cz.timeless, T);
            ++ts.path_connections;
          }
        }
        const double L = e.length * scale;
        pos = v.position + frame.normal * (hop_radius(best) * scale);
        dir = frame.direction(e);
        origin = pos - dir * (e.last * scale);
        pdf_dir = kInvFourPi;
        weight = weight * stretch(e.scatterings, L);
        tau += m.ior * L;
        interactions += static_cast<int>(std::min<std::uint32_t>(e.scatterings, 1u << 30));
        start_clearance = v.clear_radius - length(pos - v.clear_centre);
        hopped = true;
        ++ts.path_hops;
        ts.path_hop_scatterings += e.scatterings;
      }
    }
    if (!hopped) {
      const double u1 = rng.next_double(), u2 = rng.next_double();
      if (v.surface) {
        dir = sample_cosine_hemisphere(v.normal, u1, u2);
        pdf_dir = std::max(0.0, dot(dir, v.normal)) / kPi;
        weight = weight * v.albedo;
      } else {
        dir = hg_sample(v.incoming, g, u1, u2);
        pdf_dir = hg_eval(dot(dir, v.incoming), g);
      }
    }
    if (interactions >= st.rr_depth) {
      const double q = std::min(st.path_max_survival, max_component(weight) * copies);
      if (!(rng.next_double() < q)) return;
      weight = weight / q;
    }
    // 3. Along dir through boundaries to the next vertex, an emitter or the sky.
    int medium = v.medium;
    bool null_chain = true;  // only index-matched crossings since the vertex: NEE could make this path
    bool next = false;
    for (int hop = 0; hop < 100000 && !next; ++hop) {
      const bool scattering = cs.scattering(medium);
      const Vec3d sigma_t = scattering ? scene.media[medium].sigma_t() : Vec3d{};
      const Vec3d prob = channel_probabilities(weight);
      const double s = scattering ? sample_free_flight(sigma_t, prob, rng) : 0.0;
      // Inside the clearance sphere no surface can end the flight: no ray needed.
      const bool clear = hop == 0 && scattering && s < start_clearance;
      const SurfaceHit hit = clear ? SurfaceHit{} : cs.intersect(pos, dir, hop == 0 && !v.surface);
      const double dist = hit.valid ? hit.t : std::numeric_limits<double>::infinity();
      if (scattering) {
        const Medium& m = scene.media[medium];
        if (clear || s < dist) {
          const Vec3d tr = transmittance(sigma_t, s);
          weight = weight * (m.sigma_s * tr) / pdf_mixture(sigma_t, tr, prob);
          const Vec3d clear_centre = v.clear_centre;
          const double clear_radius = clear ? v.clear_radius : 0.0;
          v = PathVertex{};
          v.position = pos + dir * s;
          v.incoming = dir;
          v.medium = medium;
          v.weight = weight;
          v.tau = tau + m.ior * s;
          v.interactions = interactions + 1;
          v.clear_centre = clear_centre;
          v.clear_radius = clear_radius;
          ts.path_clear_flights += clear ? 1 : 0;
          next = true;
          break;
        }
        if (!hit.valid) return;
        const Vec3d tr = transmittance(sigma_t, dist);
        weight = weight * tr / survival_mixture(tr, prob);
      } else if (cs.attenuating(medium) && hit.valid) {
        weight = weight * transmittance(scene.media[medium].sigma_t(), dist);
      }
      if (!hit.valid) {
        if (sky && within_depth(interactions)) {
          const double mis = null_chain ? power_heuristic(pdf_dir, cs.sky_light_pdf(dir)) : 1.0;
          splat.add(0.0, weight * scene.environment_radiance * mis, true, T);
        }
        return;
      }
      if (!(max_component(weight) > 0)) return;
      tau += cs.ior(medium) * dist;
      pos = hit.position;
      const Shape& shape = scene.shapes[hit.shape];
      if (shape.is_emitter() && hit.entering && within_depth(interactions)) {
        double mis = 1.0;
        if (null_chain)
          mis = power_heuristic(pdf_dir, cs.area_light_pdf(hit.shape, length(pos - origin), -dot(dir, hit.normal)));
        splat.add(tau - unwarp, weight * shape.radiance * mis, false, T);
      }
      const Vec3d facing = hit.entering ? hit.normal : -hit.normal;
      if (shape.kind == SurfaceKind::Null) {
        medium = hit.medium_after;
        continue;
      }
      ++interactions;
      if (shape.kind == SurfaceKind::Diffuse) {
        if (!(max_component(shape.albedo) > 0)) return;
        v = PathVertex{};
        v.position = pos;
        v.incoming = dir;
        v.medium = hit.medium_before;
        v.surface = true;
        v.normal = facing;
        v.albedo = shape.albedo;
        v.weight = weight;
        v.tau = tau;
        v.interactions = interactions;
        next = true;
        break;
      }
      if (!within_depth(interactions)) return;
      if (fresnel_branch(dir, weight, facing, cs.ior(medium), cs.ior(hit.medium_after), rng.next_double()))
        medium = hit.medium_after;
      null_chain = false;
      if (interactions >= st.rr_depth) {
        const double q = std::min(st.path_max_survival, max_component(weight) * copies);
        if (!(rng.next_double() < q)) return;
        weight = weight / q;
      }
    }
    if (!next) return;
  }
}

}  // namespace

}  // namespace ptpb
