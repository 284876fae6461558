// Photon beams (ptpb.md §3): the record stored per medium segment of a light path, and the
// light tracer that produces them together with the surface photons of §7.
#pragma once
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <vector>

#include "ptpb/compiled_scene.hpp"
#include "ptpb/render.hpp"
#include "ptpb/surface_photons.hpp"

namespace ptpb {

struct Beam {
  Vec3d origin{};
  Vec3d direction{};     // unit, along the light's travel
  double length = 0.0;   // s_max, m
  Vec3d power{};         // Phi_b: path throughput at the origin, before attenuation along the beam
  double tau0 = 0.0;     // OPL at the origin, m (from the light's time origin)
  int medium = kVacuum;
  BeamKind kind = BeamKind::Long;
  int light_depth = 0;   // non-null interactions before the origin
  bool timeless = false; // from an emitter without a time origin: steady image only
  std::uint32_t path = 0;
};

// What light paths leave behind: beams (medium segments) and surface photons (diffuse hits).
struct LightRecords {
  std::vector<Beam> beams;
  std::vector<SurfacePhoton> photons;
};

// Traces light path `path_index` of iteration `iteration` and appends its beams and surface
// photons, each in the order the path made them.
void trace_light_path(const CompiledScene& scene, const RenderSettings& settings,
                      std::uint64_t iteration, std::uint64_t path_index, LightRecords& out);

// Reorders beams along a Morton curve of their midpoints (ties by their previous index): a
// deterministic function of the beams in light-path order, so results stay independent of the
// thread count (ptpb.md §9), while beams near in space lie near in memory for the beam structure
// and the gather. Moves the records in place (no second copy of the beams).
void sort_beams_spatially(std::vector<Beam>& beams, int threads);

// Russian roulette keeps a path with probability min(kMaxSurvival, throughput ratio) on both
// sides, as Mitsuba's volpath does: a lossless medium (albedo 1) or total internal reflection
// would otherwise keep q = 1 and a path alive without bound.
constexpr double kMaxSurvival = 0.95;

// Exponential free-flight helpers shared by light and camera tracing (channel-average mixture).
inline double survival_mixture(const Vec3d& sigma_t, double s) {
  return (std::exp(-sigma_t.x * s) + std::exp(-sigma_t.y * s) + std::exp(-sigma_t.z * s)) / 3.0;
}
inline double pdf_mixture(const Vec3d& sigma_t, double s) {
  return (sigma_t.x * std::exp(-sigma_t.x * s) + sigma_t.y * std::exp(-sigma_t.y * s) +
          sigma_t.z * std::exp(-sigma_t.z * s)) / 3.0;
}
inline Vec3d transmittance(const Vec3d& sigma_t, double s) {
  return {std::exp(-sigma_t.x * s), std::exp(-sigma_t.y * s), std::exp(-sigma_t.z * s)};
}
// Distance at which the largest channel transmittance reaches `cutoff`.
inline double cutoff_distance(const Vec3d& sigma_t, double cutoff) {
  const double smallest = std::min(sigma_t.x, std::min(sigma_t.y, sigma_t.z));
  if (!(smallest > 0.0) || !(cutoff > 0.0)) return std::numeric_limits<double>::infinity();
  return -std::log(cutoff) / smallest;
}

}  // namespace ptpb
