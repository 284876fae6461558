// Shell transport for path tracing deep in dense media (DESIGN.md §12, "Hops"): the exit laws of a
// scattering-only random walk with isotropic scattering that starts with a scattering event at the
// centre of a ball. In units of the scattering length the walk is scale-free, so one table per radius
// serves every medium. Each table is a large sample of exits (path length, scatterings, exit cosine),
// built once per process on first use from a fixed key, and therefore the same in every run.
#pragma once
#include <cstdint>

namespace ptpb {

// Radii R_k = 2 * 2^(k/2) scattering lengths, k = 0 .. kHopTables - 1 (2 to about 45).
constexpr int kHopTables = 10;
// Exits held per table: the tables' own sampling error of the mean path length is about 0.6/sqrt(N).
constexpr int kHopSamples = 1 << 18;

double hop_radius(int k);

// One exit of the walk from a ball of radius R_k: the path length to the crossing of the sphere (in
// scattering lengths), the number of scattering events strictly inside (the one at the centre not
// counted), and the cosine between the exit direction and the outward normal at the exit point. By the
// walk's rotational symmetry the exit point is uniform on the sphere and independent of these, and the
// exit direction's azimuth about the normal is uniform: a sampler draws both itself.
struct HopExit {
  float length = 0.0f;
  float cosine = 0.0f;
  std::uint32_t scatterings = 0;
};

// The exit held at position floor(u * kHopSamples) of table k (u in [0, 1)), building the table (and
// the smaller ones it is composed from) on first use; safe to call from several threads.
HopExit sample_hop(int k, double u);

// The mean number of inner scatterings of table k: what a hop saves.
double hop_mean_scatterings(int k);

}  // namespace ptpb
