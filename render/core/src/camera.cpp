// The camera pass (DESIGN.md §4, §7): the pinhole frame and one pixel's camera path, which gathers
// beams along its medium segments, follows specular surfaces and ends on diffuse ones.
#include "ptpb/camera.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <string>

#include "ptpb/free_flight.hpp"
#include "ptpb/gather.hpp"
#include "ptpb/path_tracer.hpp"
#include "ptpb/rng.hpp"
#include "ptpb/sampling.hpp"

namespace ptpb {

CameraFrame make_camera_frame(const Camera& cam) {
  CameraFrame f;
  // Mitsuba's look_at frame: columns (left, up, forward).
  f.forward = normalize(cam.target - cam.origin);
  f.left = normalize(cross(cam.up, f.forward));
  f.up = cross(f.forward, f.left);
  f.origin = cam.origin;
  const int W = cam.width, H = cam.height;
  const double aspect = double(W) / H;
  if (cam.projection == Projection::Orthographic) {
    f.orthographic = true;
    f.half_width = 0.5 * cam.ortho_width;
    f.half_height = f.half_width / aspect;
    return f;
  }
  const double tan_half = std::tan(cam.fov_deg * kPi / 360.0);
  std::string axis = cam.fov_axis;
  if (axis == "smaller") axis = W <= H ? "x" : "y";
  if (axis == "larger") axis = W >= H ? "x" : "y";
  if (axis == "x")
    f.tan_x = tan_half;
  else if (axis == "y")
    f.tan_x = tan_half * aspect;
  else
    f.tan_x = tan_half * aspect / std::sqrt(1.0 + aspect * aspect);
  f.tan_y = f.tan_x / aspect;
  return f;
}

void trace_camera_path(const CameraPass& p, TileFilm& tile, int px, int py, std::vector<std::uint32_t>& cand,
                       TileStats& ts) {
  const CompiledScene& cs = *p.cs;
  const Scene& scene = cs.scene();
  const RenderSettings& st = *p.st;
  const int W = scene.camera.width, H = scene.camera.height;
  const std::size_t pixel = std::size_t(py) * W + px;
  KeyedRng rng(st.seed, p.iteration, StreamDomain::CameraPixel, pixel);
  const double jx = st.jitter ? rng.next_double() : 0.5, jy = st.jitter ? rng.next_double() : 0.5;
  const double sx = (px + jx) / W, sy = (py + jy) / H;
  // Mitsuba's sensors: +x of camera space is "left", film y points down. A perspective ray leaves the
  // pinhole; an orthographic one leaves its film point on the plane through the origin, along forward.
  const CameraFrame& cam = p.camera;
  Vec3d dir = cam.forward, pos = cam.origin;
  if (cam.orthographic)
    pos = cam.origin + cam.left * ((1.0 - 2.0 * sx) * cam.half_width) + cam.up * ((1.0 - 2.0 * sy) * cam.half_height);
  else
    dir = normalize(cam.left * ((1.0 - 2.0 * sx) * cam.tan_x) + cam.up * ((1.0 - 2.0 * sy) * cam.tan_y) + dir);
  const PixelSplat splat{scene.film, st.temporal_kernel, tile,
                         std::size_t(py - tile.y0) * tile.side + std::size_t(px - tile.x0)};
  Vec3d weight{1, 1, 1};
  int medium = scene.camera.medium, depth_c = 0;
  double tau_c = 0.0;
  // A pair of a beam and this camera segment makes a path of depth >= depth_c + 2 (§3).
  auto gathers_allowed = [&](int depth) { return st.max_depth < 0 || depth + 2 <= st.max_depth; };
  // The query segment along a camera ray in a medium (§4): long queries run to the face or to the
  // transmittance cutoff, short ones to the sampled free flight s; unbounded ones to far_length.
  auto query_length = [&](const Vec3d& sigma_t, double dist, double s) {
    const double t_q = st.query_beam_kind == BeamKind::Long
                           ? std::min(dist, cutoff_distance(sigma_t, st.transmittance_cutoff))
                           : std::min(s, dist);
    return std::isfinite(t_q) ? t_q : p.far_length;
  };
  for (int guard = 0; guard < 100000; ++guard) {
    const SurfaceHit hit = cs.intersect(pos, dir);
    const double dist = hit.valid ? hit.t : std::numeric_limits<double>::infinity();
    if (cs.scattering(medium) && (*p.path_media)[medium]) {
      // A medium where beams would be biased: sample a free flight; a scattering there hands the
      // path to the path tracer (§12), which estimates the whole rest of it.
      const Medium& m = scene.media[medium];
      const Vec3d sigma_t = m.sigma_t();
      const double s = sample_free_flight(sigma_t, rng);
      // Light from a delta light that crossed a dielectric before it first scattered cannot be reached
      // by the path tracer's next-event estimation: it is estimated here, by the specular-delta beams
      // along the segment, for every first camera vertex the segment holds, and by nothing else
      // (§12, "Delta lights behind dielectrics").
      if (!p.specular_beams.beams->empty() && gathers_allowed(depth_c)) {
        const double t_q = query_length(sigma_t, dist, s);
        ts.specular_pairs +=
            gather(p, p.specular_beams, splat, pos, dir, t_q, medium, weight, tau_c, depth_c, cand, ts);
      }
      if (s < dist) {
        PathVertex start;
        start.position = pos + dir * s;
        start.incoming = dir;
        start.medium = medium;
        start.weight = weight * (m.sigma_s * transmittance(sigma_t, s)) / pdf_mixture(sigma_t, s);
        start.tau = tau_c + m.ior * s;
        start.interactions = depth_c + 1;
        trace_path(p, splat, rng, start, ts);
        return;
      }
      if (!hit.valid) return;
      const Vec3d tr = transmittance(sigma_t, dist);
      weight = weight * tr / survival_mixture(tr);
    } else if (cs.scattering(medium)) {
      const Vec3d sigma_t = scene.media[medium].sigma_t();
      // Short query beams end at a sampled free flight; long ones ignore it (and draw none).
      const double s = st.query_beam_kind == BeamKind::Short ? sample_free_flight(sigma_t, rng)
                                                             : std::numeric_limits<double>::infinity();
      const bool stop_inside = s < dist;
      const double t_q = query_length(sigma_t, dist, s);
      if (gathers_allowed(depth_c))
        ts.pairs += gather(p, p.beams, splat, pos, dir, t_q, medium, weight, tau_c, depth_c, cand, ts);
      if (stop_inside || !hit.valid) return;
      weight = weight * transmittance(sigma_t, dist);
      if (st.query_beam_kind == BeamKind::Short) weight = weight / survival_mixture(sigma_t, dist);
    } else if (cs.attenuating(medium) && hit.valid) {
      weight = weight * transmittance(scene.media[medium].sigma_t(), dist);
    }
    if (!hit.valid) {
      // Sky seen directly: no time origin, so it only enters the steady image (§1).
      if (max_component(scene.environment_radiance) > 0 && (st.max_depth < 0 || depth_c + 1 <= st.max_depth))
        splat.add(0.0, weight * scene.environment_radiance, true, p.time_half_width);
      return;
    }
    if (!(max_component(weight) > 0)) return;
    tau_c += cs.ior(medium) * dist;
    const Shape& shape = scene.shapes[hit.shape];
    if (shape.is_emitter() && hit.entering && (st.max_depth < 0 || depth_c + 1 <= st.max_depth)) {
      splat.add(st.camera_unwarp ? 0.0 : tau_c, weight * shape.radiance, false, p.time_half_width);
    }
    pos = hit.position;
    const Vec3d facing = hit.entering ? hit.normal : -hit.normal;
    if (shape.kind == SurfaceKind::Null) {
      medium = hit.medium_after;
      continue;
    }
    if (shape.kind == SurfaceKind::Diffuse) {
      // The camera path ends here (§7); depth d_c + 2 is the shallowest path a photon can close.
      if (max_component(shape.albedo) > 0 && p.photon_grid->size() > 0 &&
          (st.max_depth < 0 || depth_c + 2 <= st.max_depth))
        gather_surface(p, splat, pos, facing, shape.albedo, weight, tau_c, depth_c, cand, ts);
      return;
    }
    ++depth_c;
    if (st.max_depth >= 0 && depth_c + 1 > st.max_depth) return;
    if (fresnel_branch(dir, weight, facing, cs.ior(medium), cs.ior(hit.medium_after), rng.next_double()))
      medium = hit.medium_after;
    if (depth_c >= st.rr_depth) {
      const double q = std::min(kMaxSurvival, max_component(weight));
      if (!(rng.next_double() < q)) return;
      weight = weight / q;
    }
  }
}

}  // namespace ptpb
