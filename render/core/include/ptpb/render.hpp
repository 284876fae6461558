// The progressive transient photon-beam renderer: a pure function from scene and settings to
// images (steady, frames) and run statistics.
#pragma once
#include <cstdint>
#include <functional>
#include <optional>
#include <vector>

#include "ptpb/scene.hpp"
#include "ptpb/schedule.hpp"
#include "ptpb/settings.hpp"

namespace ptpb {

struct Progress {
  int iteration = 0;   // iterations completed
  int iterations = 0;  // planned
  double elapsed_s = 0.0;
  double radius = 0.0;  // R_i of the iteration in flight or just done
  double time_half_width = 0.0;
  std::uint64_t beams = 0;      // beams stored in the iteration, specular-delta beams (§12) included
  double surface_radius = 0.0;  // r_i of the surface photons
  std::uint64_t surface_photons = 0;
};

// Returns false to cancel; called from the rendering thread, rate-limited.
using ProgressCallback = std::function<bool(const Progress&)>;

struct RenderStats {
  int iterations_done = 0;
  bool cancelled = false;
  std::uint64_t light_paths = 0, beams = 0, queries = 0, candidates = 0, pair_evaluations = 0;
  std::uint64_t parallel_rejected = 0, false_positives = 0, accel_references = 0;
  double time_light_s = 0, time_build_s = 0, time_camera_s = 0, time_total_s = 0;
  double final_radius = 0, final_time_half_width = 0;
  // Surface photons (§7): photons stored, gathers at diffuse camera hits, accepted photon terms.
  std::uint64_t surface_photons = 0, surface_queries = 0, surface_pairs = 0;
  double time_surface_build_s = 0;
  // Path tracing in dense media (§12): vertices traced, light connections splatted, clearance queries
  // made and free flights that ended inside a clearance sphere (no ray traced), and how many media
  // used paths in the last iteration.
  std::uint64_t path_vertices = 0, path_connections = 0, path_clearance_queries = 0, path_clear_flights = 0;
  std::uint64_t path_splits = 0;                          // copies made by splitting in time (§12)
  std::uint64_t path_hops = 0, path_hop_scatterings = 0;  // hops taken and the collisions they stood for (§12)
  int path_media = 0;
  // Delta lights behind dielectrics (§12): specular-delta beams stored, pairs accepted, and the largest
  // of their per-medium radii in the last iteration that stored any.
  std::uint64_t specular_beams = 0, specular_pairs = 0;
  double final_specular_radius = 0;
  double final_surface_radius = 0, final_surface_time_half_width = 0;
  double steady_total = 0, early_total = 0, late_total = 0;  // image sums, for the window check
  Schedule schedule;                                         // the bandwidth schedule this run resolved and used (§6)
};

// The accumulated state of a progressive render after stats.iterations_done iterations: the sums
// of the per-iteration estimates (not averages), the counters and timings, and the snapshots.
// Random streams are keyed by (seed, iteration, index) (§9), so a render resumed from it gives
// the same bits as one that was never interrupted. stats.final_* hold the bandwidths of the last
// completed iteration and stats.time_total_s the render time so far (time budgets continue it).
struct RenderState {
  int width = 0, height = 0, frame_count = 0;
  std::uint64_t seed = 0;
  std::vector<double> steady, early, late;  // H x W x 3
  // F x H x W x 3 in float32 (DESIGN.md §9: float sums are exact enough up to ~10^4 iterations).
  // From iteration settings.compensated_sums_from on, frames_carry (same size) holds each sum's rounding
  // remainder: the sum is then frames + frames_carry, about 48 significant bits. Empty before.
  std::vector<float> frames;
  std::vector<float> frames_carry;
  std::vector<double> frames_double;  // with settings.keep_sums: the frame sums in double, frames empty
  RenderStats stats;
  std::vector<int> snapshot_iterations;
  std::vector<double> snapshot_seconds;
  std::vector<std::vector<float>> snapshots;
};

// Called on the calling thread between iterations (and once more when a run is cancelled);
// returns false to cancel.
using CheckpointCallback = std::function<bool(const RenderState&)>;

struct RenderResult {
  int width = 0, height = 0, frame_count = 0;
  std::vector<float> steady;       // H x W x 3
  std::vector<float> frames;       // F x H x W x 3
  std::vector<float> early, late;  // H x W x 3: energy before / after the frame window
  std::vector<int> snapshot_iterations;
  std::vector<double> snapshot_seconds;       // wall time since the start of the render, per snapshot
  std::vector<std::vector<float>> snapshots;  // steady averages, H x W x 3 each
  // With settings.keep_sums, the undivided double sums instead of the averages (which stay empty).
  std::vector<double> steady_sum, early_sum, late_sum, frames_sum;
  RenderStats stats;
};

// Validates scene and settings (std::invalid_argument naming the parameter) and renders.
// `resume`: continue from a state an earlier run of the same scene and settings handed to its
// checkpoint callback (refused when its film, seed or bandwidth schedule differ). `checkpoint`
// receives the state as settings.checkpoint_every_* ask.
RenderResult render(const Scene& scene, const RenderSettings& settings, const ProgressCallback& progress = nullptr,
                    std::optional<RenderState> resume = std::nullopt, const CheckpointCallback& checkpoint = nullptr);

}  // namespace ptpb
