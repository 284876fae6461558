// Light tracing (ptpb.md §3, §7): emission, free flights, boundaries, roulette, beam records and
// surface photons.
#include <cmath>
#include <limits>

#include "ptpb/beams.hpp"
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

}  // namespace ptpb
