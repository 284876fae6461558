// Transient path tracing for media where beams are biased (DESIGN.md §12): a camera path that
// scatters in such a medium is continued from there with next-event estimation to every light,
// and each contribution is splatted into the frames at its own optical path length.
#pragma once
#include <vector>

#include "ptpb/camera.hpp"
#include "ptpb/rng.hpp"

namespace ptpb {

// One vertex of a path-traced camera path: a scattering event in a medium or a diffuse reflection.
// The camera pass makes the first one, where the path first scatters in a medium that uses paths.
struct PathVertex {
  Vec3d position{};
  Vec3d incoming{};      // the camera path's direction of travel into the vertex
  int medium = kVacuum;  // the medium the outgoing direction enters
  bool surface = false;
  Vec3d normal{}, albedo{};  // surface only; the normal faces the side the path came from
  Vec3d weight{};            // camera throughput, the vertex's own sampling weight included
  double tau = 0.0;          // camera OPL from the pinhole to the vertex
  int interactions = 0;      // non-null interactions on the camera side, this vertex included
  // Medium vertices: no surface lies within clear_radius of clear_centre (0: not known), a ball that holds
  // the vertex; its clearance is clear_radius - |position - clear_centre| (§12).
  Vec3d clear_centre{};
  double clear_radius = 0.0;
};

// Traces the rest of the camera path from `start` with the pixel's stream `rng` and splats every
// light it connects to. A camera path handed over here never gathers beams again, so a full path is
// estimated by exactly one technique: the medium of its first camera-side vertex decides.
void trace_path(const CameraPass& p, const PixelSplat& splat, KeyedRng& rng, const PathVertex& start, TileStats& ts);

// Which media use paths in an iteration with beam radius R (DESIGN.md §12): all with
// MediumEstimator::Paths, none with Beams, and with Auto those whose shortest mean free path is
// below R / beam_radius_mfp or below the scene's bounding radius / dense_optical_radius.
std::vector<char> media_using_paths(const CompiledScene& cs, const RenderSettings& st, double radius);

// Kernel radii of the specular-delta beams (DESIGN.md §12, "Delta lights behind dielectrics"), per
// medium, in an iteration whose beam radius is `radius` on a schedule that starts at `initial_radius`:
// min(R_0, beam_radius_mfp / max sigma_t) shrunk by the beams' own factor R_i / R_0, so that it starts
// where beams are unbiased in that medium and vanishes on the beams' schedule. 0 for media not on paths.
std::vector<double> specular_beam_radii(const CompiledScene& cs, const RenderSettings& st,
                                        const std::vector<char>& path_media, double radius, double initial_radius);

}  // namespace ptpb
