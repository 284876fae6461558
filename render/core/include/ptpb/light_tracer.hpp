// The light tracer (DESIGN.md §3, §7): light paths from emission to their last bounce, leaving photon
// beams in media and surface photons on diffuse surfaces.
#pragma once
#include <cstdint>
#include <vector>

#include "ptpb/beams.hpp"
#include "ptpb/compiled_scene.hpp"
#include "ptpb/settings.hpp"
#include "ptpb/surface_photons.hpp"

namespace ptpb {

// What light paths leave behind: beams (medium segments) and surface photons (diffuse hits), and
// the specular-delta beams in media on paths (DESIGN.md §12, "Delta lights behind dielectrics").
struct LightRecords {
  std::vector<Beam> beams;
  std::vector<SurfacePhoton> photons;
  std::vector<Beam> specular_beams;
};

// Traces light path `path_index` of iteration `iteration` and appends its beams and surface
// photons, each in the order the path made them. Media flagged in `path_media` (DESIGN.md §12) get
// no ordinary beams: the light path crosses them, and camera paths estimate what scatters there,
// except the light that next-event estimation cannot reach. A path from a delta light (point, sun)
// that meets a dielectric before its first scattering or diffuse vertex is such light: its segments in
// those media go to `specular_beams` instead. An empty vector means beams in every medium.
void trace_light_path(const CompiledScene& scene, const RenderSettings& settings, std::uint64_t iteration,
                      std::uint64_t path_index, LightRecords& out, const std::vector<char>& path_media = {});

// Traces the settings.light_paths_per_iteration paths of one iteration into `out` (cleared first),
// in path order whatever the thread count (§9). The vectors keep their capacity from one iteration
// to the next.
void trace_light_paths(const CompiledScene& scene, const RenderSettings& settings, std::uint64_t iteration,
                       LightRecords& out, const std::vector<char>& path_media = {});

}  // namespace ptpb
