// The progressive transient photon-beam renderer: a pure function from scene and settings to
// images (steady, frames) and run statistics.
#pragma once
#include <cstdint>
#include <functional>
#include <optional>
#include <vector>

#include "ptpb/kernels.hpp"
#include "ptpb/scene.hpp"

namespace ptpb {

enum class BeamKind { Long, Short };
enum class AccelKind { Grid, Embree };

struct RenderSettings {
  int iterations = 16;                 // upper bound on iterations
  double time_budget_s = 0.0;          // wall-clock budget; > 0 stops after the iteration in flight
  std::uint64_t light_paths_per_iteration = 10000;  // M
  double alpha = 0.8;                  // kernel-volume schedule parameter (§6)
  double initial_beam_radius = 0.01;   // R_0, m
  double initial_time_half_width = 0.01;  // T_0, m of OPL (gate mode)
  // Surface photons (§7) run their own schedule (§6): disk radius r_0 and, in gate mode, T_0.
  double initial_surface_radius = 0.01;  // r_0, m
  std::optional<double> initial_surface_time_half_width;  // m of OPL; unset: initial_time_half_width
  std::optional<double> surface_alpha;   // unset: 2/3 in bins/steady, 4/7 in gate (alpha* for d = 2, 3)
  double surface_normal_cos = 0.9;       // photons whose normal is further than acos(this) from x's are rejected
  SpatialKernel spatial_kernel = SpatialKernel::Epanechnikov;
  TemporalKernel temporal_kernel = TemporalKernel::Epanechnikov;
  BeamKind photon_beam_kind = BeamKind::Long;
  BeamKind query_beam_kind = BeamKind::Long;
  double parallel_guard_sin2 = 1e-5;
  int max_depth = -1;                  // Mitsuba meaning; -1 unbounded
  int rr_depth = 5;
  std::uint64_t seed = 0;
  int threads = 0;                     // 0: all hardware threads
  AccelKind accel = AccelKind::Embree;
  int grid_resolution = 32;            // cells along the longest axis (grid only)
  double dice_length = 0.0;            // beam piece length for the BVH/grid, m; 0 = automatic
  bool jitter = true;                  // false: pixel-centre rays (analytic tests)
  bool camera_unwarp = false;
  double transmittance_cutoff = 1e-4;  // long beams/queries end where max-channel Tr drops below
  int tile_size = 16;
  int snapshot_every = 0;              // > 0: keep the steady average every k iterations
  // Checkpoints (§9): hand the accumulated state to the checkpoint callback every k iterations
  // and/or after this much wall time since the last one; 0 = never.
  int checkpoint_every_iterations = 0;
  double checkpoint_every_s = 0.0;
  // render() refuses a film whose buffers (render_memory_bytes) exceed this many GiB; 0 = no limit.
  double memory_budget_gib = 8.0;
  // From this iteration on the float32 frame sums carry their rounding remainders (RenderState).
  // Not a user setting (the bindings keep the default); tests lower it to reach that code.
  int compensated_sums_from = 10000;
};

struct Progress {
  int iteration = 0;       // iterations completed
  int iterations = 0;      // planned
  double elapsed_s = 0.0;
  double radius = 0.0;     // R_i of the iteration in flight or just done
  double time_half_width = 0.0;
  std::uint64_t beams = 0;
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
  double final_surface_radius = 0, final_surface_time_half_width = 0;
  double steady_total = 0, early_total = 0, late_total = 0;  // image sums, for the window check
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
  // F x H x W x 3 in float32 (ptpb.md §9: float sums are exact enough up to ~10^4 iterations).
  // From iteration settings.compensated_sums_from on, frames_carry (same size) holds each sum's rounding
  // remainder: the sum is then frames + frames_carry, about 48 significant bits. Empty before.
  std::vector<float> frames;
  std::vector<float> frames_carry;
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
  std::vector<float> steady;  // H x W x 3
  std::vector<float> frames;  // F x H x W x 3
  std::vector<float> early, late;  // H x W x 3: energy before / after the frame window
  std::vector<int> snapshot_iterations;
  std::vector<double> snapshot_seconds;  // wall time since the start of the render, per snapshot
  std::vector<std::vector<float>> snapshots;  // steady averages, H x W x 3 each
  RenderStats stats;
};

// Validates scene and settings (std::invalid_argument naming the parameter) and renders.
// `resume`: continue from a state an earlier run of the same scene and settings handed to its
// checkpoint callback (refused when its film, seed or bandwidth schedule differ). `checkpoint`
// receives the state as settings.checkpoint_every_* ask.
RenderResult render(const Scene& scene, const RenderSettings& settings,
                    const ProgressCallback& progress = nullptr, std::optional<RenderState> resume = std::nullopt,
                    const CheckpointCallback& checkpoint = nullptr);

// Peak bytes of render()'s image buffers (§9 "Memory"): the double sums of steady, early and late
// (H W 3 each), the float32 frame sums (F H W 3; twice that with the remainders of a run past
// settings.compensated_sums_from iterations or on a time budget), one tile buffer per thread, the float32
// results (the frames are scaled in place, not copied) and the float32 steady snapshots. With
// `state_copy` (a checkpoint callback or a resume state) one more copy of the sums and snapshots.
// Frames are never split into chunks: every ray-beam pair splats into all the frames its kernel
// covers within one pass, so a film that does not fit is refused instead.
double render_memory_bytes(const Scene& scene, const RenderSettings& settings, bool state_copy);

// Throws std::invalid_argument, naming the keys that shrink the film or raise the budget, when
// render_memory_bytes exceeds settings.memory_budget_gib; render() calls it before allocating.
void check_memory_budget(const Scene& scene, const RenderSettings& settings, bool state_copy);

// Bandwidths of iteration i for a film mode (§6): gate shrinks R and T with gamma^(1/2),
// bins/steady shrink R with gamma.
void iteration_bandwidths(FrameMode mode, const RenderSettings& s, long iteration, double& radius,
                          double& time_half_width);

// The surface photons' schedule parameter: surface_alpha, or alpha* = 4/(d + 4) for the disk
// (d = 2) in bins/steady and the disk x time kernel (d = 3) in gate mode (§6).
double surface_schedule_alpha(FrameMode mode, const RenderSettings& s);

// Surface bandwidths of iteration i (§6): the kernel volume r^2 (bins/steady) or r^2 T (gate)
// follows gamma_i, so r_i = r_0 gamma^(1/2) in bins/steady, and r_i = r_0 gamma^(1/3),
// T_i = T_0 gamma^(1/3) in gate mode, where space and time shrink at the same rate.
void surface_bandwidths(FrameMode mode, const RenderSettings& s, long iteration, double& radius,
                        double& time_half_width);

}  // namespace ptpb
