// Next-event estimation (DESIGN.md §12): connections from a shading point to the lights, through
// index-matched boundaries and the media behind them. Paths in dense media (path_tracer.cpp) use it.
#include <algorithm>
#include <cmath>
#include <limits>

#include "ptpb/compiled_scene.hpp"
#include "ptpb/free_flight.hpp"
#include "ptpb/sampling.hpp"

namespace ptpb {
namespace {

// A shadow ray whose transmittance through the media it has crossed so far has fallen below this goes on
// to its next face (and the test for occluders beyond) with probability max(tr) / kShadowRoulette,
// divided by it (DESIGN.md §12, "Shadow rays that leave dense media").
constexpr double kShadowRoulette = 0.05;

}  // namespace

Vec3d CompiledScene::shadow_transmittance(Vec3d x, const Vec3d& dir, double distance, int medium, bool from_medium,
                                          KeyedRng& rng, double& opl, Vec3d& end) const {
  Vec3d tr{1, 1, 1};
  const bool bounded = std::isfinite(distance);
  // The light's own surface lies at `distance`: stop a little short of it.
  double remaining = bounded ? distance - 4.0 * ray_epsilon_ : distance;
  for (int guard = 0; guard < 10000 && remaining > 0; ++guard) {
    const SurfaceHit hit = intersect(x, dir, guard == 0 && from_medium);
    const double step = hit.valid ? std::min(hit.t, remaining) : remaining;
    if (attenuating(medium)) {
      if (!std::isfinite(step)) return {0, 0, 0};
      tr = tr * transmittance(scene_.media[medium].sigma_t(), step);
    }
    if (!hit.valid || hit.t >= remaining) {
      if (std::isfinite(step)) {
        opl += ior(medium) * step;
        x = x + dir * step;
      }
      end = x;
      return tr;
    }
    if (scene_.shapes[hit.shape].kind != SurfaceKind::Null) return {0, 0, 0};
    opl += ior(medium) * hit.t;
    x = hit.position;
    remaining -= hit.t;
    medium = hit.medium_after;
    const double largest = max_component(tr);
    if (!(largest > 0)) return tr;
    if (largest < kShadowRoulette) {
      const double keep = largest / kShadowRoulette;
      if (!(rng.next_double() < keep)) return {0, 0, 0};
      tr = tr / keep;
    }
  }
  end = x;
  return tr;
}

double CompiledScene::area_light_pdf(std::uint32_t shape, double distance, double cos_light) const {
  if (shape >= area_light_pick_.size() || !(cos_light > 0)) return 0.0;
  return area_light_pick_[shape] * distance * distance / (cos_light * shape_area_[shape]);
}

double CompiledScene::sky_light_pdf(const Vec3d& direction) const {
  if (length(sky_up_) == 0) return sky_pick_ * kInvFourPi;
  return dot(direction, sky_up_) > 0 ? sky_pick_ * kInvTwoPi : 0.0;
}

bool CompiledScene::connect_light(KeyedRng& rng, const Vec3d& x, int medium, bool from_medium,
                                  LightConnection& out) const {
  const double u_pick = rng.next_double(), u1 = rng.next_double(), u2 = rng.next_double();
  if (lights_.empty() || !(total_power_ > 0)) return false;
  std::size_t li = std::upper_bound(light_cdf_.begin(), light_cdf_.end(), u_pick * total_power_) - light_cdf_.begin();
  li = std::min(li, lights_.size() - 1);
  const LightEntry& e = lights_[li];
  if (!(e.power > 0)) return false;
  const double pick = e.power / total_power_;
  double opl = 0.0;
  Vec3d end = x;
  out.timeless = false;
  out.pdf = 0.0;
  if (e.kind == 0) {  // point light
    const PointLight& l = scene_.point_lights[e.index];
    const Vec3d w = l.position - x;
    const double d = length(w);
    if (!(d > 0)) return false;
    out.direction = w / d;
    const Vec3d tr = shadow_transmittance(x, out.direction, d, medium, from_medium, rng, opl, end);
    out.value = l.intensity * tr / (d * d * pick);
    out.tau = opl;
  } else if (e.kind == 1) {  // area light: a uniform point on its surface
    Vec3d point, normal;
    sample_area_point(e.index, rng, point, normal);
    const Vec3d w = point - x;
    const double d = length(w);
    if (!(d > 0)) return false;
    out.direction = w / d;
    const double cos_light = -dot(normal, out.direction);  // emission is one-sided, along the normal
    if (!(cos_light > 0)) return false;
    const Vec3d tr = shadow_transmittance(x, out.direction, d, medium, from_medium, rng, opl, end);
    out.pdf = area_light_pdf(static_cast<std::uint32_t>(e.index), d, cos_light);
    out.value = scene_.shapes[e.index].radiance * tr / out.pdf;
    out.tau = opl;
  } else if (e.kind == 2) {  // sun: a plane wave along -s
    const DirectionalLight& l = scene_.directional_lights[e.index];
    const Vec3d s = normalize(l.to_sun);
    out.direction = s;
    const Vec3d tr =
        shadow_transmittance(x, s, std::numeric_limits<double>::infinity(), medium, from_medium, rng, opl, end);
    out.value = l.irradiance * (l.profile(x) * tr) / pick;
    // The wavefront leaves the plane Pi_0 at tau = 0 and reaches the shadow ray's last point `end`
    // through the surroundings (DESIGN.md §1), then x through the path just traced.
    const double plane_offset = l.has_reference_point ? dot(l.reference_point - sphere_center_, s) : sphere_radius_;
    out.tau = scene_.ambient_ior * (plane_offset - dot(end - sphere_center_, s)) + opl;
  } else {  // constant sky: a uniform direction
    // Uniform over the sky's upper hemisphere (the ground below a snowfield sends none of it), or the sphere.
    out.direction = length(sky_up_) > 0 ? from_frame(sky_up_, 1.0 - u1, 2.0 * kPi * u2) : sample_uniform_sphere(u1, u2);
    const Vec3d tr = shadow_transmittance(x, out.direction, std::numeric_limits<double>::infinity(), medium,
                                          from_medium, rng, opl, end);
    out.pdf = sky_light_pdf(out.direction);
    out.value = scene_.environment_radiance * tr / out.pdf;
    out.tau = 0.0;
    out.timeless = true;
  }
  return max_component(out.value) > 0;
}

}  // namespace ptpb
