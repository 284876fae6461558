// Light tracing (DESIGN.md §3, §7): emission, free flights, boundaries, roulette, beam records and
// surface photons.
#include "ptpb/light_tracer.hpp"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <utility>

#include "ptpb/free_flight.hpp"
#include "ptpb/parallel.hpp"
#include "ptpb/rng.hpp"
#include "ptpb/sampling.hpp"

namespace ptpb {

void trace_light_path(const CompiledScene& cs, const RenderSettings& st, std::uint64_t iteration,
                      std::uint64_t path_index, LightRecords& out, const std::vector<char>& path_media) {
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
  bool at_vertex = false;  // the ray leaves a scattering vertex inside a medium
  // The path's prefix runs from the emitter to its first scattering or diffuse vertex. A delta light's
  // path whose prefix meets a dielectric is light that next-event estimation cannot connect to
  // (DESIGN.md §12, "Delta lights behind dielectrics"); only such paths leave beams in media on paths.
  bool in_prefix = true, specular_delta = false;
  for (int guard = 0; guard < 1000000; ++guard) {
    // A beam or surface photon at light depth d forms paths of depth >= d + 2 (§3; gather.cpp
    // gives the count for photons).
    if (st.max_depth >= 0 && depth + 2 > st.max_depth) return;
    const SurfaceHit hit = cs.intersect(pos, dir, at_vertex);
    const double dist = hit.valid ? hit.t : inf;
    bool scattered = false;
    double travel = dist;
    if (cs.scattering(medium)) {
      const Medium& m = scene.media[medium];
      const Vec3d sigma_t = m.sigma_t();
      const double s = sample_free_flight(sigma_t, rng);
      scattered = s < dist;
      double beam_length = st.photon_beam_kind == BeamKind::Long
                               ? std::min(dist, cutoff_distance(sigma_t, st.transmittance_cutoff))
                               : std::min(s, dist);
      if (!std::isfinite(beam_length)) beam_length = far_length;
      const bool on_paths = !path_media.empty() && path_media[medium];
      if ((!on_paths || specular_delta) && beam_length > 0 && max_component(beta) > 0) {
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
        (on_paths ? out.specular_beams : out.beams).push_back(b);
      }
      if (scattered) {
        const Vec3d tr = transmittance(sigma_t, s);
        beta = beta * (m.sigma_s * tr) / pdf_mixture(sigma_t, tr);
        travel = s;
      } else {
        if (!hit.valid) return;
        const Vec3d tr = transmittance(sigma_t, dist);
        beta = beta * tr / survival_mixture(tr);
      }
    } else if (cs.attenuating(medium)) {
      if (!hit.valid) return;
      beta = beta * transmittance(scene.media[medium].sigma_t(), dist);
    } else if (!hit.valid) {
      return;
    }
    tau += cs.ior(medium) * travel;
    at_vertex = scattered;
    if (scattered) {
      in_prefix = false;
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
        specular_delta = specular_delta || (in_prefix && ls.delta);
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
        in_prefix = false;
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

void trace_light_paths(const CompiledScene& cs, const RenderSettings& settings, std::uint64_t iteration,
                       LightRecords& out, const std::vector<char>& path_media) {
  const std::uint64_t M = settings.light_paths_per_iteration;
  constexpr std::size_t kPathChunk = 256;
  constexpr int kChunksPerThread = 16;  // light-path chunks per thread in one group
  // Traced a group of chunks at a time and appended in chunk order, so that at most one group's
  // records exist twice (DESIGN.md §9 "Memory").
  const std::size_t path_chunks = (M + kPathChunk - 1) / kPathChunk;
  const std::size_t group = std::size_t(kChunksPerThread) * resolve_thread_count(settings.threads);
  out.beams.clear();
  out.photons.clear();
  out.specular_beams.clear();
  for (std::size_t g0 = 0; g0 < path_chunks; g0 += group) {
    const std::size_t g1 = std::min(path_chunks, g0 + group);
    std::vector<LightRecords> chunk_records(g1 - g0);
    parallel_for_chunks(g1 - g0, 1, settings.threads, [&](std::size_t c0, std::size_t c1) {
      for (std::size_t c = c0; c < c1; ++c) {
        const std::uint64_t end = std::min<std::uint64_t>(M, (g0 + c + 1) * kPathChunk);
        for (std::uint64_t j = (g0 + c) * kPathChunk; j < end; ++j)
          trace_light_path(cs, settings, iteration, j, chunk_records[c], path_media);
      }
    });
    if (g0 == 0 && out.beams.capacity() == 0 && out.specular_beams.capacity() == 0) {
      // Room for the whole iteration at the first group's rate, with a margin: capacity that is
      // never written costs address space, not memory, while a vector grown by doubling leaves
      // freed buffers behind and raises the peak memory (measured by make bench's memory rows).
      std::size_t first_beams = 0, first_photons = 0, first_specular = 0;
      for (const auto& rec : chunk_records) {
        first_beams += rec.beams.size();
        first_photons += rec.photons.size();
        first_specular += rec.specular_beams.size();
      }
      const double scale = 1.25 * double(M) / double(std::min<std::uint64_t>(M, g1 * kPathChunk));
      out.beams.reserve(std::size_t(scale * double(first_beams)) + 1024);
      out.photons.reserve(std::size_t(scale * double(first_photons)) + 1024);
      out.specular_beams.reserve(std::size_t(scale * double(first_specular)) + 1024);
    }
    for (auto& rec : chunk_records) {
      out.beams.insert(out.beams.end(), rec.beams.begin(), rec.beams.end());
      out.photons.insert(out.photons.end(), rec.photons.begin(), rec.photons.end());
      out.specular_beams.insert(out.specular_beams.end(), rec.specular_beams.begin(), rec.specular_beams.end());
      std::vector<Beam>().swap(rec.beams);
      std::vector<SurfacePhoton>().swap(rec.photons);
      std::vector<Beam>().swap(rec.specular_beams);
    }
  }
}

}  // namespace ptpb
