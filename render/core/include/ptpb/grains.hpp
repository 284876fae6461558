// Snow as grains: an exact geometric-optics Monte Carlo through a periodic packing of dielectric ice
// spheres, and the same source, receivers and estimators for a homogeneous Henyey–Greenstein half-space
// (render/lidar/LIDAR.md §10). Pure functions of their inputs; no I/O.
#pragma once
#include <cstddef>
#include <cstdint>
#include <functional>
#include <vector>

namespace ptpb {

// A periodic cubic cell of side `cell_size` holding non-overlapping spheres. Snow is the cell tiled in
// x and y and downward in z, keeping the sphere images whose centre lies below z = 0; above is vacuum.
struct GrainPacking {
  double cell_size = 0.0;       // Lc [m]
  std::vector<double> centres;  // (N, 3) row-major [m]; x, y in [0, Lc), z in [-Lc, 0)
  std::vector<double> radii;    // (N,) [m]
};

struct GrainOptics {
  double ice_index = 1.3117;        // real refractive index of ice (phase index, for Fresnel and Snell)
  double ice_group_index = 1.3117;  // group index of ice: optical time = air length + n_g x ice length
  double ice_absorption = 0.0;      // gamma = 4 pi k / lambda [m^-1]
};

struct HomogeneousMedium {
  double scattering = 0.0;  // sigma_s [m^-1]
  double absorption = 0.0;  // sigma_a [m^-1]
  double asymmetry = 0.0;   // g of the Henyey–Greenstein phase function
  double time_index = 1.0;  // optical time = time_index x geometric path
};

// Source, receivers and binning shared by both tracers. Time is optical path length [m], measured from a
// reflection off the reference plane z = 0 along the exit direction (LIDAR.md §10).
struct GrainTraceSettings {
  std::uint64_t photons = 0;
  std::uint64_t seed = 0;
  double start_opl = 0.0;       // first time bin's lower edge [m of OPL]
  double bin_width_opl = 1e-3;  // [m]
  int temporal_bins = 1;
  double cone_half_angle = 0.1;   // nadir receiver cone [rad]
  double depth_bin_width = 1e-3;  // absorbed-energy depth profile bins [m] below z = 0
  int depth_bins = 1;
  double max_path = 1e3;  // path cap [m of geometric path]: a photon past it ends as truncated
  int threads = 0;        // 0 = all hardware threads; results do not depend on it
};

struct GrainTraceResult {
  std::vector<double> time_flux;                    // (temporal_bins,) exits per bin over all directions, per photon
  std::vector<double> time_cone;                    // (temporal_bins,) exits within the nadir cone, per photon
  std::vector<double> air_by_bin;                   // (temporal_bins,) sum of exits' air path per bin, per photon [m]
  std::vector<double> ice_by_bin;                   // (temporal_bins,) sum of exits' ice path per bin, per photon [m]
  std::vector<double> absorbed_depth;               // (depth_bins,) track-length estimate of absorbed energy per photon
  double albedo = 0.0;                              // exits per photon
  double cone_fraction = 0.0;                       // exits within the cone per photon
  double absorbed = 0.0;                            // photons absorbed per photon (analog)
  double truncated = 0.0;                           // photons stopped at max_path per photon
  double early = 0.0, late = 0.0;                   // flux exits before start_opl and past the last bin, per photon
  double exit_opl = 0.0;                            // sum of exits' OPL per photon [m]
  double air_path = 0.0, ice_path = 0.0;            // all photons' air / ice (or medium) path per photon [m]
  double exit_air_path = 0.0, exit_ice_path = 0.0;  // exits' only, per photon [m]
  double sphere_hits = 0.0;                         // sphere (or scattering) events per photon
  double interactions = 0.0;                        // surface interactions (Fresnel events) per photon
  double total_internal_reflections = 0.0;          // per photon; 0 for spheres (a sphere has none)
  std::uint64_t photons_done = 0;                   // less than photons when cancelled
  bool cancelled = false;
};

// Called between chunks on the calling thread with (photons done, photons); false cancels.
using GrainProgress = std::function<bool(std::uint64_t, std::uint64_t)>;

GrainTraceResult trace_packing(const GrainPacking& packing, const GrainOptics& optics,
                               const GrainTraceSettings& settings, const GrainProgress& progress = nullptr);
GrainTraceResult trace_homogeneous(const HomogeneousMedium& medium, const GrainTraceSettings& settings,
                                   const GrainProgress& progress = nullptr);

// One sphere of radius r lit by a parallel beam over its cross-section: exact geometric optics.
struct SphereScatter {
  double absorbed = 0.0;                    // absorbed per incident photon (expected, 1 - exp(-gamma l) summed)
  double mean_ice_path = 0.0;               // per incident photon [m]
  double mean_cos = 0.0;                    // asymmetry g of the geometric-optics phase function
  double energy_out = 0.0;                  // scattered + absorbed per incident photon (1 up to rounding)
  double total_internal_reflections = 0.0;  // per photon: 0, a sphere admits none
};
SphereScatter scatter_sphere(double radius, const GrainOptics& optics, std::uint64_t rays, std::uint64_t seed);

}  // namespace ptpb
