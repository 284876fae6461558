// A validated scene ready for tracing: the Embree triangle scene, per-mesh surface data, light
// sampling tables and the bounding sphere that fixes the sun's time origin.
#pragma once
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

struct LightSample {
  Vec3d origin{}, direction{};
  Vec3d power{};  // beta_0 divided by the light-selection probability, W
  int medium = kVacuum;
  bool timeless = false;  // environment light: no time origin, steady image only
};

class CompiledScene {
 public:
  explicit CompiledScene(const Scene& scene);  // throws std::invalid_argument on bad input

  const Scene& scene() const { return scene_; }
  SurfaceHit intersect(const Vec3d& origin, const Vec3d& direction) const;
  double ior(int medium) const { return medium == kVacuum ? scene_.ambient_ior : scene_.media[medium].ior; }
  bool scattering(int medium) const { return medium != kVacuum && has_scattering_[medium]; }
  bool attenuating(int medium) const { return medium != kVacuum && has_extinction_[medium]; }

  // Starts one light path: picks a light by power and samples its emission (DESIGN.md §3).
  bool sample_emission(KeyedRng& rng, LightSample& out) const;
  double total_light_power() const { return total_power_; }
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
};

}  // namespace ptpb
