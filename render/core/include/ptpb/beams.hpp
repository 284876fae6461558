// Photon beams (DESIGN.md §3): the record stored per medium segment of a light path, and their
// order in memory.
#pragma once
#include <cstdint>
#include <vector>

#include "ptpb/scene.hpp"
#include "ptpb/settings.hpp"
#include "ptpb/vec.hpp"

namespace ptpb {

struct Beam {
  Vec3d origin{};
  Vec3d direction{};    // unit, along the light's travel
  double length = 0.0;  // s_max, m
  Vec3d power{};        // Phi_b: path throughput at the origin, before attenuation along the beam
  double tau0 = 0.0;    // OPL at the origin, m (from the light's time origin)
  int medium = kVacuum;
  BeamKind kind = BeamKind::Long;
  int light_depth = 0;    // non-null interactions before the origin
  bool timeless = false;  // from an emitter without a time origin: steady image only
  std::uint32_t path = 0;
};

// Reorders beams along a Morton curve of their midpoints (ties by their previous index): a
// deterministic function of the beams in light-path order, so results stay independent of the
// thread count (DESIGN.md §9), while beams near in space lie near in memory for the beam structure
// and the gather. Moves the records in place (no second copy of the beams).
void sort_beams_spatially(std::vector<Beam>& beams, int threads);

}  // namespace ptpb
