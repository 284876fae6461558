// Light tracing (ptpb.md §3, §7): emission, free flights, boundaries, roulette, beam records and
// surface photons.
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <utility>

#include "ptpb/beams.hpp"
#include "ptpb/parallel.hpp"
#include "ptpb/rng.hpp"
#include "ptpb/sampling.hpp"

namespace ptpb {

void trace_light_path(const CompiledScene& cs, const RenderSettings& st, std::uint64_t iteration,
                      std::uint64_t path_index, LightRecords& out) {
  KeyedRng rng(st.seed, iteration, StreamDomain::LightPath, path_index);
  LightSample ls;
  if (!cs.sample_emission(rng, ls)) return;
  const Scene& scene = cs.scene();
  const double inf = std::numeric_limits<double>::infinity();
  // Unbounded beams (a channel without extinction and no boundary ahead) end beyond the scene.
  const double far_length = 4.0 * cs.sphere_radius() + length(ls.origin - cs.sphere_center());
  Vec3d pos = ls.origin, dir = normalize(ls.direction), beta = ls.power;
  const double beta0_max = max_component(ls.power);
  int medium = ls.medium, depth = 0;
  double tau = 0.0;
  for (int guard = 0; guard < 1000000; ++guard) {
    // A beam or surface photon at light depth d forms paths of depth >= d + 2 (§3; render.cpp
    // gives the count for photons).
    if (st.max_depth >= 0 && depth + 2 > st.max_depth) return;
    const SurfaceHit hit = cs.intersect(pos, dir);
    const double dist = hit.valid ? hit.t : inf;
    bool scattered = false;
    double travel = dist;
    if (cs.scattering(medium)) {
      const Medium& m = scene.media[medium];
      const Vec3d sigma_t = m.sigma_t();
      const int channel = std::min(2, static_cast<int>(rng.next_double() * 3.0));
      const double s = sigma_t[channel] > 0 ? -std::log1p(-rng.next_double()) / sigma_t[channel] : inf;
      scattered = s < dist;
      double beam_length = st.photon_beam_kind == BeamKind::Long
                               ? std::min(dist, cutoff_distance(sigma_t, st.transmittance_cutoff))
                               : std::min(s, dist);
      if (!std::isfinite(beam_length)) beam_length = far_length;
      if (beam_length > 0 && max_component(beta) > 0) {
        Beam b;
        b.origin = pos;
        b.direction = dir;
        b.length = beam_length;
        b.power = beta;
        b.tau0 = tau;
        b.medium = medium;
        b.kind = st.photon_beam_kind;
        b.light_depth = depth;
        b.timeless = ls.timeless;
        b.path = static_cast<std::uint32_t>(path_index);
        out.beams.push_back(b);
      }
      if (scattered) {
        beta = beta * (m.sigma_s * transmittance(sigma_t, s)) / pdf_mixture(sigma_t, s);
        travel = s;
      } else {
        if (!hit.valid) return;
        beta = beta * transmittance(sigma_t, dist) / survival_mixture(sigma_t, dist);
      }
    } else if (cs.attenuating(medium)) {
      if (!hit.valid) return;
      beta = beta * transmittance(scene.media[medium].sigma_t(), dist);
    } else if (!hit.valid) {
      return;
    }
    tau += cs.ior(medium) * travel;
    if (scattered) {
      pos = pos + dir * travel;
      ++depth;
      const double u1 = rng.next_double(), u2 = rng.next_double();
      dir = hg_sample(dir, scene.media[medium].g, u1, u2);
    } else {
      const Shape& shape = scene.shapes[hit.shape];
      pos = hit.position;
      const Vec3d facing = hit.entering ? hit.normal : -hit.normal;  // towards the incoming side
      if (shape.kind == SurfaceKind::Null) {
        medium = hit.medium_after;
        continue;  // index-matched crossings are not interactions
      }
      if (shape.kind == SurfaceKind::Diffuse && max_component(shape.albedo) > 0 && max_component(beta) > 0) {
        // Phi_p is the power that arrives, before the albedo: f_r = albedo/pi belongs to the
        // estimator, as Tr_b does for beams. Black surfaces (emitters) can never return light.
        SurfacePhoton p;
        p.position = pos;
        p.direction = dir;
        p.normal = facing;
        p.power = beta;
        p.tau = tau;
        p.shape = hit.shape;
        p.light_depth = depth;  // this hit is not counted: it is the gather's reflection
        p.timeless = ls.timeless;
        p.path = static_cast<std::uint32_t>(path_index);
        out.photons.push_back(p);
      }
      ++depth;
      if (shape.kind == SurfaceKind::Dielectric) {
        const double n_i = cs.ior(medium), n_t = cs.ior(hit.medium_after);
        const double cos_i = -dot(dir, facing);
        const FresnelResult fr = fresnel_dielectric(cos_i, n_i, n_t);
        if (rng.next_double() < fr.reflectance) {
          dir = normalize(reflect(dir, facing));
        } else {
          dir = refract(dir, facing, n_i, n_t, fr.cos_t);
          medium = hit.medium_after;
        }
      } else {
        beta = beta * shape.albedo;
        if (!(max_component(beta) > 0)) return;
        const double u1 = rng.next_double(), u2 = rng.next_double();
        dir = sample_cosine_hemisphere(facing, u1, u2);
      }
    }
    if (depth >= st.rr_depth) {
      const double q = std::min(kMaxSurvival, max_component(beta) / beta0_max);
      if (!(rng.next_double() < q)) return;
      beta = beta / q;
    }
  }
}

namespace {

// The 10 bits of v spread to every third bit of a 30-bit Morton code.
std::uint32_t spread_bits(std::uint32_t v) {
  v &= 0x3FFu;
  v = (v | (v << 16)) & 0x030000FFu;
  v = (v | (v << 8)) & 0x0300F00Fu;
  v = (v | (v << 4)) & 0x030C30C3u;
  v = (v | (v << 2)) & 0x09249249u;
  return v;
}

}  // namespace

void sort_beams_spatially(std::vector<Beam>& beams, int threads) {
  const std::size_t n = beams.size();
  if (n < 2 || n > std::numeric_limits<std::uint32_t>::max()) return;
  const double inf = std::numeric_limits<double>::infinity();
  Vec3d lo{inf, inf, inf}, hi{-inf, -inf, -inf};
  auto midpoint = [](const Beam& b) { return b.origin + b.direction * (0.5 * b.length); };
  for (const Beam& b : beams) {
    const Vec3d m = midpoint(b);
    for (int a = 0; a < 3; ++a) { lo[a] = std::min(lo[a], m[a]); hi[a] = std::max(hi[a], m[a]); }
  }
  // (Morton code << 32) | index: sorting the keys sorts by code, then by the previous order.
  std::vector<std::uint64_t> keys(n);
  parallel_for_chunks(n, 8192, threads, [&](std::size_t i0, std::size_t i1) {
    for (std::size_t i = i0; i < i1; ++i) {
      const Vec3d m = midpoint(beams[i]);
      std::uint32_t code = 0;
      for (int a = 0; a < 3; ++a) {
        const double extent = hi[a] - lo[a];
        const double f = extent > 0 ? (m[a] - lo[a]) / extent : 0.0;
        code |= spread_bits(static_cast<std::uint32_t>(std::clamp(f * 1024.0, 0.0, 1023.0))) << a;
      }
      keys[i] = (std::uint64_t(code) << 32) | i;
    }
  });
  std::sort(keys.begin(), keys.end());
  // Slot i receives beam keys[i]'s low half: follow each cycle of the permutation, moving one
  // record at a time; a filled slot's key is marked done.
  constexpr std::uint64_t kDone = ~std::uint64_t(0);
  for (std::size_t start = 0; start < n; ++start) {
    if (keys[start] == kDone) continue;
    std::size_t slot = start;
    Beam held = std::move(beams[start]);
    for (;;) {
      const std::size_t from = static_cast<std::uint32_t>(keys[slot]);
      keys[slot] = kDone;
      if (from == start) { beams[slot] = std::move(held); break; }
      beams[slot] = std::move(beams[from]);
      slot = from;
    }
  }
}

}  // namespace ptpb
