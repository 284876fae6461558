// What render() takes besides the scene: the settings of a progressive render and their enums. The
// defaults below are the only ones: the bindings parse and report the settings by the keys of
// for_each_setting, and the config schema (pipeline/schema/ptpb.py) takes its defaults from them.
#pragma once
#include <cstdint>
#include <optional>

#include "ptpb/kernels.hpp"

namespace ptpb {

enum class BeamKind { Long, Short };
enum class AccelKind { Grid, Embree };
// Which estimator a scattering medium gets (DESIGN.md §12): beams, camera paths, or per iteration
// by its mean free path against the beam radius.
enum class MediumEstimator { Auto, Beams, Paths };

// The largest path_splits: a path then stands for up to 2^8 copies of itself.
constexpr int kMaxPathSplits = 8;

struct RenderSettings {
  int iterations = 64;                              // upper bound on iterations
  double time_budget_s = 0.0;                       // wall-clock budget; > 0 stops after the iteration in flight
  std::uint64_t light_paths_per_iteration = 20000;  // M
  // The bandwidth schedule (§6). Unset values take the defaults resolve_schedule (schedule.hpp)
  // gives them, which a render reports in RenderStats::schedule.
  std::optional<double> alpha;                    // kernel-volume schedule parameter; unset: 4/5, 2/3 in gate
  double initial_beam_radius = 0.01;              // R_0, m
  std::optional<double> initial_time_half_width;  // T_0, m of OPL (gate mode); unset: R_0
  // Surface photons (§7) run their own schedule (§6): disk radius r_0 and, in gate mode, T_0.
  std::optional<double> initial_surface_radius;           // r_0, m; unset: R_0
  std::optional<double> initial_surface_time_half_width;  // m of OPL; unset: the beams' T_0
  std::optional<double> surface_alpha;  // unset: 2/3 in bins/steady, 4/7 in gate (alpha* for d = 2, 3)
  double surface_normal_cos = 0.9;      // photons whose normal is further than acos(this) from x's are rejected
  SpatialKernel spatial_kernel = SpatialKernel::Epanechnikov;
  TemporalKernel temporal_kernel = TemporalKernel::Epanechnikov;
  BeamKind photon_beam_kind = BeamKind::Long;
  BeamKind query_beam_kind = BeamKind::Long;
  double parallel_guard_sin2 = 1e-5;
  // Dense media (§12): with Auto, a medium keeps beams in an iteration only while R_i is at most
  // beam_radius_mfp of its shortest mean free path and it is optically thin at the scene's scale
  // (max σ_t times the bounding radius at most dense_optical_radius); otherwise camera paths
  // scattering in it are path traced. Path tracing keeps a path after rr_depth with
  // min(path_max_survival, throughput).
  MediumEstimator medium_estimator = MediumEstimator::Auto;
  double beam_radius_mfp = 0.1;
  double dense_optical_radius = 50.0;
  double path_max_survival = 0.999;
  // Splitting in time (§12): in bins and gate films a path-traced camera path doubles path_splits times as
  // its OPL past its first vertex passes W/2^L, ..., W/2 (W the film's length, L = path_splits), and goes
  // back to one path once it can light no frame.
  int path_splits = 0;  // at most kMaxPathSplits
  // Shell transport (§12, "Hops"): deep in an isotropically scattering medium a path-traced walk crosses a
  // surface-free ball in one step drawn from tabulated exit laws, its time and absorption exact.
  bool path_hops = true;
  int max_depth = -1;  // Mitsuba meaning; -1 unbounded
  int rr_depth = 8;
  std::uint64_t seed = 0;
  int threads = 0;  // 0: all hardware threads
  AccelKind accel = AccelKind::Embree;
  int grid_resolution = 32;  // cells along the longest axis (grid only)
  double dice_length = 0.0;  // beam piece length for the BVH/grid, m; 0 = automatic
  bool jitter = true;        // false: pixel-centre rays (analytic tests)
  bool camera_unwarp = false;
  double transmittance_cutoff = 1e-4;  // long beams/queries end where max-channel Tr drops below
  int tile_size = 16;
  int snapshot_every = 8;  // > 0: keep the steady average every k iterations
  // Checkpoints (§9): hand the accumulated state to the checkpoint callback every k iterations
  // and/or after this much wall time since the last one; 0 = never.
  int checkpoint_every_iterations = 0;
  double checkpoint_every_s = 0.0;
  // render() refuses a film whose buffers (render_memory_bytes) exceed this many GiB; 0 = no limit.
  double memory_budget_gib = 8.0;
  // From this iteration on the float32 frame sums carry their rounding remainders (RenderState).
  // Not a user setting (the bindings keep the default); tests lower it to reach that code.
  int compensated_sums_from = 10000;
  // Shards (DESIGN.md §9): run iterations [first_iteration, iterations) of the global schedule, and with
  // keep_sums return the undivided sums in double (frames summed in double too) for an exact merge.
  int first_iteration = 0;
  bool keep_sums = false;
};

// A setting whose 0 means none (no budget, never): a caller may give it as None, and its default of 0 is reported so.
struct ZeroMeansNone {};

// Every setting a caller gives by name, with its key: the one list that the bindings parse a settings dict by
// and report the defaults from (render._core.render_settings_defaults). A setting left out of it, such as
// compensated_sums_from, keeps its default. Settings is RenderSettings or const RenderSettings.
template <typename Settings, typename Visit>
void for_each_setting(Settings& s, Visit&& visit) {
  visit("iterations", s.iterations);
  visit("time_budget_s", s.time_budget_s, ZeroMeansNone{});
  visit("light_paths_per_iteration", s.light_paths_per_iteration);
  visit("alpha", s.alpha);
  visit("initial_beam_radius", s.initial_beam_radius);
  visit("initial_time_half_width", s.initial_time_half_width);
  visit("initial_surface_radius", s.initial_surface_radius);
  visit("initial_surface_time_half_width", s.initial_surface_time_half_width);
  visit("surface_alpha", s.surface_alpha);
  visit("surface_normal_cos", s.surface_normal_cos);
  visit("spatial_kernel", s.spatial_kernel);
  visit("temporal_kernel", s.temporal_kernel);
  visit("photon_beam_kind", s.photon_beam_kind);
  visit("query_beam_kind", s.query_beam_kind);
  visit("parallel_guard_sin2", s.parallel_guard_sin2);
  visit("medium_estimator", s.medium_estimator);
  visit("beam_radius_mfp", s.beam_radius_mfp);
  visit("dense_optical_radius", s.dense_optical_radius);
  visit("path_max_survival", s.path_max_survival);
  visit("path_splits", s.path_splits);
  visit("path_hops", s.path_hops);
  visit("max_depth", s.max_depth);
  visit("rr_depth", s.rr_depth);
  visit("seed", s.seed);
  visit("threads", s.threads);
  visit("accel", s.accel);
  visit("grid_resolution", s.grid_resolution);
  visit("dice_length", s.dice_length);
  visit("jitter", s.jitter);
  visit("camera_unwarp", s.camera_unwarp);
  visit("transmittance_cutoff", s.transmittance_cutoff);
  visit("tile_size", s.tile_size);
  visit("snapshot_every", s.snapshot_every);
  visit("checkpoint_every_iterations", s.checkpoint_every_iterations);
  visit("checkpoint_every_s", s.checkpoint_every_s, ZeroMeansNone{});
  visit("memory_budget_gib", s.memory_budget_gib, ZeroMeansNone{});
  visit("first_iteration", s.first_iteration);
  visit("keep_sums", s.keep_sums);
}

}  // namespace ptpb
