// A validated scene ready for tracing: the Embree triangle scene, per-mesh surface data, light
// sampling tables and the bounding sphere that fixes the sun's time origin.
#pragma once
#include <algorithm>
#include <cmath>
#include <memory>
#include <vector>

#include "ptpb/ray_engine.hpp"
#include "ptpb/rng.hpp"
#include "ptpb/scene.hpp"

namespace ptpb {

// What a ray found at a surface, with the media on the two sides resolved.
struct SurfaceHit {
  bool valid = false;
  double t = 0.0;
  Vec3d position{};
  Vec3d normal{};         // outward (winding) normal
  bool entering = false;  // ray travels against the outward normal
  std::uint32_t shape = 0;
  int medium_before = kVacuum;  // medium on the side the ray comes from
  int medium_after = kVacuum;   // medium on the far side
};

// A connection from a shading point x to one light, made by next-event estimation (DESIGN.md §12):
// what arrives at x from the light along -direction, already through every index-matched boundary
// and medium on the way, divided by the probability of having chosen this connection.
struct LightConnection {
  Vec3d direction{};  // unit, from x towards the light
  Vec3d value{};      // radiance × transmittance (irradiance for the sun, I/d^2 for a point) / pdf
  double pdf = 0.0;   // solid-angle pdf of the direction, light choice included; 0 for delta lights
  double tau = 0.0;   // OPL from the light's emission to x (DESIGN.md §1); unused when timeless
  bool timeless = false;
};

struct LightSample {
  Vec3d origin{}, direction{};
  Vec3d power{};  // beta_0 divided by the light-selection probability, W
  int medium = kVacuum;
  bool timeless = false;  // environment light: no time origin, steady image only
  bool delta = false;     // point light or sun: next-event estimation is the only way a camera path reaches it
};

class CompiledScene {
 public:
  explicit CompiledScene(const Scene& scene);  // throws std::invalid_argument on bad input

  const Scene& scene() const { return scene_; }
  // The first surface along the ray. Rays leaving a surface skip ray_epsilon() to avoid finding it
  // again; rays leaving a scattering vertex inside a medium (`from_medium`) skip nothing, since in a
  // dense medium a vertex closer than the epsilon to a face is common and must still see it (§12).
  SurfaceHit intersect(const Vec3d& origin, const Vec3d& direction, bool from_medium = false) const;
  double ior(int medium) const { return medium == kVacuum ? scene_.ambient_ior : scene_.media[medium].ior; }
  bool scattering(int medium) const { return medium != kVacuum && has_scattering_[medium]; }
  // Distance from p to the nearest surface, or `reach` when none is closer (DESIGN.md §12, clearance),
  // less a float ulp or so of p, so that Embree's single-precision rays could not see a face inside it.
  double clearance(const Vec3d& p, double reach) const {
    const double margin = 1e-6 * (1.0 + std::max({std::fabs(p.x), std::fabs(p.y), std::fabs(p.z)}));
    return std::max(0.0, rays_.closest_distance(p, reach) - margin);
  }
  // Whether every light lies on or beyond a surface, so that a shadow ray from a medium vertex crosses
  // at least its clearance of that medium (no point or spot light sits inside a medium).
  bool lights_beyond_surfaces() const { return scene_.point_lights.empty(); }
  bool attenuating(int medium) const { return medium != kVacuum && has_extinction_[medium]; }

  // Starts one light path: picks a light by power and samples its emission (DESIGN.md §3).
  bool sample_emission(KeyedRng& rng, LightSample& out) const;
  double total_light_power() const { return total_power_; }

  // Next-event estimation from x in `medium` (direct_light.cpp): picks a light by power, samples a
  // point or direction on it and traces the shadow ray through index-matched boundaries. Returns
  // false when the connection carries nothing (blocked, back side, black light).
  // `from_medium`: x is a scattering vertex inside `medium` (see intersect).
  bool connect_light(KeyedRng& rng, const Vec3d& x, int medium, bool from_medium, LightConnection& out) const;
  // Solid-angle pdf with which connect_light picks a direction that reaches the emitter shape
  // `shape` at distance `distance` with cosine `cos_light` on the emitter, or the sky (for MIS).
  double area_light_pdf(std::uint32_t shape, double distance, double cos_light) const;
  double sky_light_pdf(const Vec3d& direction) const;
  // True when some surface is diffuse with a non-zero albedo (surface photons have somewhere to land).
  bool has_diffuse_reflectors() const { return has_diffuse_reflectors_; }
  // True when a delta light (point or sun) with power and a smooth dielectric surface share the scene:
  // light paths can then reach a medium along a way next-event estimation cannot follow (DESIGN.md §12,
  // "Delta lights behind dielectrics").
  bool has_specular_delta_light() const { return has_specular_delta_light_; }
  double ray_epsilon() const { return ray_epsilon_; }
  Vec3d sphere_center() const { return sphere_center_; }
  double sphere_radius() const { return sphere_radius_; }

 private:
  Scene scene_;
  RayScene rays_;
  std::vector<char> has_scattering_, has_extinction_;
  // Light table: kind 0 point, 1 area shape, 2 directional, 3 constant sky; cdf over mean-channel power.
  struct LightEntry {
    int kind;
    std::size_t index;
    double power;
  };
  std::vector<LightEntry> lights_;
  std::vector<double> light_cdf_;
  double total_power_ = 0.0;
  // Area emitters: per-shape triangle cdf and total area.
  std::vector<std::vector<double>> triangle_cdf_;
  std::vector<double> shape_area_;
  Vec3d sphere_center_{};
  double sphere_radius_ = 0.0;
  double ray_epsilon_ = 1e-5;
  bool has_diffuse_reflectors_ = false;
  bool has_specular_delta_light_ = false;
  std::vector<double> area_light_pick_;  // per shape: probability of picking it as a light (0: none)
  double sky_pick_ = 0.0;
  Vec3d sky_up_{};  // next-event estimation samples the sky's hemisphere around it (zero: whole sphere)

  void sample_area_point(std::size_t shape, KeyedRng& rng, Vec3d& point, Vec3d& normal) const;
  // Transmittance from x along dir over `distance` (infinite: to the scene's end) through
  // index-matched boundaries; 0 when anything else is in the way. Adds the OPL to `opl` and leaves
  // the end point in `end`. Past a face, a transmittance already below kShadowRoulette is rouletted
  // (unbiased) with `rng` before the ray goes on.
  Vec3d shadow_transmittance(Vec3d x, const Vec3d& dir, double distance, int medium, bool from_medium, KeyedRng& rng,
                             double& opl, Vec3d& end) const;
};

}  // namespace ptpb
