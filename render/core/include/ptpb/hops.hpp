// Shell transport for path tracing deep in dense media (DESIGN.md §12, "Hops"): the exit laws of a
// scattering-only random walk with isotropic scattering that starts with a scattering event at the
// centre of a ball. In units of the scattering length the walk is scale-free, so one table per radius
// serves every medium. Each table is a large sample of walks, each reduced to its exit and to one of its
// inner scattering events, built once per process on first use from a fixed key, and therefore the same
// in every run.
#pragma once
#include <cstdint>

#include "ptpb/vec.hpp"

namespace ptpb {

// Radii R_k = 2 * 2^(k/2) scattering lengths, k = 0 .. kHopTables - 1 (2 to about 45).
constexpr int kHopTables = 10;
// Walks held per table: the tables' own sampling error of the mean path length is about 0.7/sqrt(N).
constexpr int kHopSamples = 1 << 17;

double hop_radius(int k);

// One walk from the centre of a ball of radius R_k, in scattering lengths, as seen from its exit. The
// exit frame has e3 along the outward normal at the exit point and e1 such that the exit direction is
// cosine e3 + sqrt(1 - cosine^2) e1 (e2 = e3 x e1). By the walk's rotational symmetry that frame is
// uniformly oriented and independent of everything held here, so a sampler draws it itself.
struct HopExit {
  float length = 0.0f;            // path length to the crossing of the sphere
  float cosine = 0.0f;            // between the exit direction and the outward normal
  std::uint32_t scatterings = 0;  // inner scattering events (the one at the centre not counted)
  float last = 0.0f;              // path length from the last inner event (or the centre) to the crossing
  // One inner event J, picked with probability proportional to w_i = exp(|z_i| - R) (the bound on what a
  // next-event estimate from z_i can carry, up to a common factor), and factor = sum_i w_i / w_J: then
  // factor * g(z_J) is an unbiased estimate of sum_i g(z_i) over the walk's inner events, for any g.
  // factor is 0 for a walk without inner events.
  float factor = 0.0f;
  float vertex_length = 0.0f;            // path length from the centre to z_J
  std::uint32_t vertex_scatterings = 0;  // scattering events up to and including z_J, the centre not counted
  float vertex[3] = {0.0f, 0.0f, 0.0f};  // z_J in the exit frame
};

// The walk held at position floor(u * kHopSamples) of table k (u in [0, 1)), building the table (and the
// smaller ones it is composed from) on first use; safe to call from several threads.
const HopExit& sample_hop(int k, double u);

// The mean number of inner scatterings of table k: what a hop saves.
double hop_mean_scatterings(int k);

// A uniformly oriented exit frame drawn from three uniform numbers in [0, 1): the outward normal at the exit
// (e3) uniform on the sphere, and e1 at a uniform azimuth about it (e2 = e3 x e1). It places a table walk:
// its exit point is normal * R, its exit direction and inner event z_J (relative to the centre, in the
// table's units) are below.
struct HopFrame {
  Vec3d normal, e1, e2;
  HopFrame(double u1, double u2, double u3);
  Vec3d direction(const HopExit& e) const;
  Vec3d vertex(const HopExit& e) const;
};

}  // namespace ptpb
