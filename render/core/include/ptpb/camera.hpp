// The camera pass (DESIGN.md §4, §7): Mitsuba's pinhole camera, and the camera path of one pixel,
// which gathers beams along its medium segments and surface photons where it ends on a diffuse
// surface.
#pragma once
#include <cstdint>
#include <vector>

#include "ptpb/beam_accel.hpp"
#include "ptpb/beams.hpp"
#include "ptpb/compiled_scene.hpp"
#include "ptpb/film.hpp"
#include "ptpb/render.hpp"
#include "ptpb/settings.hpp"
#include "ptpb/surface_photons.hpp"

namespace ptpb {

// Mitsuba's look_at frame, columns (left, up, forward), and the tangents of the half field of view
// (perspective) or the film's half width and height in metres (orthographic).
struct CameraFrame {
  Vec3d origin, left, up, forward;
  bool orthographic = false;
  double tan_x = 0.0, tan_y = 0.0;
  double half_width = 0.0, half_height = 0.0;
};

CameraFrame make_camera_frame(const Camera& camera);

// A set of photon beams with the structure built over them and the kernel radius it was built with.
// A per-medium radius (`medium_radius`, indexed by medium id, none above `radius`) overrides it in the
// gather; the structure is built with `radius`, so it returns a superset of the pairs.
struct BeamLayer {
  const std::vector<Beam>* beams = nullptr;
  const BeamAccel* accel = nullptr;
  double radius = 0.0;
  const std::vector<double>* medium_radius = nullptr;
  double radius_in(int medium) const { return medium_radius ? (*medium_radius)[medium] : radius; }
};

// Everything one iteration's camera pass needs, read-only.
struct CameraPass {
  const CompiledScene* cs;
  const RenderSettings* st;
  BeamLayer beams;  // beams in media that keep them (§3), radius R_i
  // Beams of delta lights that met a dielectric before their first scattering, in media on paths (§12,
  // "Delta lights behind dielectrics"), with their own radius; gathered until the camera path first scatters.
  BeamLayer specular_beams;
  const std::vector<SurfacePhoton>* photons;
  const SurfacePhotonGrid* photon_grid;
  const std::vector<char>* path_media;  // per medium: 1 where camera paths are path traced (§12)
  std::uint64_t iteration;
  double time_half_width, inv_paths;
  double surface_radius, surface_time_half_width;
  CameraFrame camera;
  double far_length;
};

// A tile's counts of queries and pairs, added to the render's stats when the tile is done.
struct TileStats {
  std::uint64_t queries = 0, candidates = 0, pairs = 0, parallel = 0, false_positives = 0;
  std::uint64_t specular_pairs = 0;
  std::uint64_t surface_queries = 0, surface_pairs = 0;
  std::uint64_t path_vertices = 0, path_connections = 0, path_clearance_queries = 0, path_clear_flights = 0;
  std::uint64_t path_splits = 0;                          // copies made by splitting in time (§12)
  std::uint64_t path_hops = 0, path_hop_scatterings = 0;  // hops taken and the collisions they stood for (§12)

  // Integer totals: the order in which tiles add them does not matter.
  void add_to(RenderStats& s) const {
    s.queries += queries;
    s.candidates += candidates;
    s.pair_evaluations += pairs;
    s.specular_pairs += specular_pairs;
    s.parallel_rejected += parallel;
    s.false_positives += false_positives;
    s.surface_queries += surface_queries;
    s.surface_pairs += surface_pairs;
    s.path_vertices += path_vertices;
    s.path_connections += path_connections;
    s.path_clearance_queries += path_clearance_queries;
    s.path_clear_flights += path_clear_flights;
    s.path_splits += path_splits;
    s.path_hops += path_hops;
    s.path_hop_scatterings += path_hop_scatterings;
  }
};

// Traces the camera path of pixel (px, py) and splats its estimates into `tile`; `cand` is the
// caller's scratch space for candidate indices.
void trace_camera_path(const CameraPass& p, TileFilm& tile, int px, int py, std::vector<std::uint32_t>& cand,
                       TileStats& ts);

}  // namespace ptpb
