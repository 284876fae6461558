// What render() takes besides the scene: the settings of a progressive render and their enums. Each
// setting is declared here once: its default in RenderSettings; its key, bounds, description and, for an
// enum, its spellings in for_each_setting and choices(). The bindings parse and report the settings by that
// table (render._core.render_settings_spec), and the config schema (pipeline/schema/ptpb.py) builds its
// fields from it. Adding a setting: render/core/DESIGN.md, "Adding a render setting".
#pragma once
#include <cstdint>
#include <optional>
#include <utility>

#include "ptpb/kernels.hpp"

namespace ptpb {

enum class BeamKind { Long, Short };
enum class AccelKind { Grid, Embree };
// Which estimator a scattering medium gets (DESIGN.md §12): beams, camera paths, or per iteration
// by its mean free path against the beam radius.
enum class MediumEstimator { Auto, Beams, Paths };

// How a settings dict spells each value of the enums of RenderSettings: the choices the schema offers.
inline constexpr std::pair<const char*, SpatialKernel> kSpatialKernelChoices[] = {
    {"box", SpatialKernel::Box}, {"epanechnikov", SpatialKernel::Epanechnikov}};
inline constexpr std::pair<const char*, TemporalKernel> kTemporalKernelChoices[] = {
    {"box", TemporalKernel::Box}, {"epanechnikov", TemporalKernel::Epanechnikov}, {"quintic", TemporalKernel::Quintic}};
inline constexpr std::pair<const char*, BeamKind> kBeamKindChoices[] = {{"long", BeamKind::Long},
                                                                        {"short", BeamKind::Short}};
inline constexpr std::pair<const char*, MediumEstimator> kMediumEstimatorChoices[] = {
    {"auto", MediumEstimator::Auto}, {"beams", MediumEstimator::Beams}, {"paths", MediumEstimator::Paths}};
inline constexpr std::pair<const char*, AccelKind> kAccelKindChoices[] = {{"grid", AccelKind::Grid},
                                                                          {"embree", AccelKind::Embree}};
constexpr const auto& choices(SpatialKernel) { return kSpatialKernelChoices; }
constexpr const auto& choices(TemporalKernel) { return kTemporalKernelChoices; }
constexpr const auto& choices(BeamKind) { return kBeamKindChoices; }
constexpr const auto& choices(MediumEstimator) { return kMediumEstimatorChoices; }
constexpr const auto& choices(AccelKind) { return kAccelKindChoices; }

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

// What the table below says of a setting besides its key: a description with its [unit] (the config
// reference prints it), the bounds of its value (the config schema refuses a value past one; the core's own
// checks, with the rules that tie settings together, are validate_settings in src/validation.cpp), and two
// flags.
struct SettingInfo {
  const char* description = "";
  std::optional<double> ge, gt, le, lt;  // value >= ge, > gt, <= le, < lt
  bool zero_means_none = false;          // 0 means none (no budget, never): given as None, reported as None
  bool api_only = false;                 // no config sets it; callers of the Python API do (tests, shards)

  SettingInfo at_least(double bound) const {
    SettingInfo info = *this;
    info.ge = bound;
    return info;
  }
  SettingInfo above(double bound) const {
    SettingInfo info = *this;
    info.gt = bound;
    return info;
  }
  SettingInfo at_most(double bound) const {
    SettingInfo info = *this;
    info.le = bound;
    return info;
  }
  SettingInfo below(double bound) const {
    SettingInfo info = *this;
    info.lt = bound;
    return info;
  }
  SettingInfo none_when_zero() const {
    SettingInfo info = *this;
    info.zero_means_none = true;
    return info;
  }
  SettingInfo only_from_the_api() const {
    SettingInfo info = *this;
    info.api_only = true;
    return info;
  }
};

inline SettingInfo about(const char* description) {
  SettingInfo info;
  info.description = description;
  return info;
}

// Every setting a caller gives by name, with its key and SettingInfo: the one list that the bindings parse a
// settings dict by and report the settings from (render._core.render_settings_spec). A setting left out of it,
// such as compensated_sums_from, keeps its default. Settings is RenderSettings or const RenderSettings.
template <typename Settings, typename Visit>
void for_each_setting(Settings& s, Visit&& visit) {
  visit("iterations", s.iterations,
        about("Number of progressive iterations (upper bound unless a time budget is set) [-].").at_least(1));
  visit("time_budget_s", s.time_budget_s,
        about("Wall-clock budget; when set it overrides `iterations` (stops after the iteration in flight) [s].")
            .above(0)
            .none_when_zero());
  visit("light_paths_per_iteration", s.light_paths_per_iteration,
        about("M: light paths launched per iteration; every sum is divided by M [-].")
            .at_least(1)
            .below(4294967296.0));  // 2^32
  visit("alpha", s.alpha,
        about("Kernel-volume schedule parameter; null picks 2/3 for gate and 4/5 for bins/steady [-].")
            .above(0)
            .at_most(1));
  // The config gives the three starting values below in units of its own (pipeline/schema/ptpb.py), which
  // render/ptpb/settings.py resolves to metres.
  visit("initial_beam_radius", s.initial_beam_radius,
        about("R_0, the beams' initial 1D spatial kernel radius [m].").above(0));
  visit("initial_time_half_width", s.initial_time_half_width,
        about("T_0, the initial temporal kernel half-width of gate mode; unset: R_0 [m].").above(0));
  visit("initial_surface_radius", s.initial_surface_radius,
        about("r_0, the surface photons' initial 2D disk kernel radius; unset: R_0 [m].").above(0));
  visit("initial_surface_time_half_width", s.initial_surface_time_half_width,
        about("The surface photons' own T_0, from render.initial_time_half_width with r_0 in place of R_0; unset: "
              "the beams' T_0 [m].")
            .above(0)
            .only_from_the_api());
  visit("surface_alpha", s.surface_alpha,
        about("Surface kernel-volume schedule parameter; null picks 4/7 for gate (r and T shrink as gamma^(1/3)) "
              "and 2/3 for bins/steady (r shrinks as gamma^(1/2)) [-].")
            .above(0)
            .at_most(1));
  visit("surface_normal_cos", s.surface_normal_cos,
        about("A surface photon counts only where its normal and the shading normal have at least this cosine [-].")
            .above(0)
            .at_most(1));
  visit("spatial_kernel", s.spatial_kernel,
        about("Spatial kernel: 1D k_R of the beams and the matching 2D disk kernel of the surface photons [-]."));
  visit("temporal_kernel", s.temporal_kernel, about("Temporal kernel K_T of gate mode [-]."));
  visit("photon_beam_kind", s.photon_beam_kind,
        about("Photon beams run to the boundary (long) or to the next vertex (short) [-]."));
  visit("query_beam_kind", s.query_beam_kind, about("Camera query segments, long or short [-]."));
  visit("parallel_guard_sin2", s.parallel_guard_sin2,
        about("Pairs with sin^2(theta) below this are skipped [-].").at_least(0).below(1));
  visit("medium_estimator", s.medium_estimator,
        about("Estimator of light scattered in media (render/core/DESIGN.md §12): beams; camera paths with "
              "next-event estimation; or auto, which in each iteration path-traces a medium whose shortest mean "
              "free path is below R_i / beam_radius_mfp and keeps beams in the others [-]."));
  visit("beam_radius_mfp", s.beam_radius_mfp,
        about("With medium_estimator auto, a medium keeps beams while R_i is at most this many of its mean free "
              "paths; beams are biased low by about 0.2 R_i sigma_t near lit faces (render/core/DESIGN.md §12) [-].")
            .above(0));
  visit("dense_optical_radius", s.dense_optical_radius,
        about("With medium_estimator auto, a medium whose largest sigma_t times the scene's bounding radius "
              "exceeds this is path-traced at any radius: its light paths make hundreds of collisions and its beams "
              "are a few mean free paths long, too short to share between pixels (render/core/DESIGN.md §12) [-].")
            .above(0));
  visit("path_max_survival", s.path_max_survival,
        about("Russian roulette of path-traced camera paths keeps a path with min(this, throughput); dense, "
              "high-albedo media need values near 1 so that paths of hundreds of collisions are not cut. 0.999 "
              "agrees with the auto-depth reference within 1 % in fresh snow, the highest albedo of any preset "
              "(DESIGN.md §12) [-].")
            .above(0)
            .below(1));
  visit("path_splits", s.path_splits,
        about("Splitting in time for path-traced camera paths in bins and gate films: a path doubles this many "
              "times, as its optical path past its first scattering passes W/2^n, ..., W/4, W/2 of the film's "
              "length W, so that late frames, lit by the few paths that stay long in dense snow, get more of them; "
              "a path that can light no frame is rouletted back to one. Pays where late frames are the noisy ones "
              "(snow's diffusion tail under the sun: the demo uses 3); costs where they are not "
              "(render/core/DESIGN.md §12) [-].")
            .at_least(0)
            .at_most(kMaxPathSplits));
  visit("path_hops", s.path_hops,
        about("Shell transport for path-traced camera paths in isotropically scattering media: deep in the medium "
              "a walk crosses a surface-free ball in one step drawn from tabulated exit laws (path length, "
              "direction, collisions), with its time and absorption exact; one of the skipped events, weighted to "
              "stand for all of them, makes their next-event estimate. Off only to compare against the "
              "collision-by-collision walk (render/core/DESIGN.md §12, 'Hops') [-]."));
  // A pipeline config takes these three from scene.max_depth and its root's seed and threads
  // (pipeline/schema/__init__.py refuses them under render:); they are keys for direct use of the API.
  visit("max_depth", s.max_depth,
        about("Mitsuba's max_depth: non-null interactions + 1; -1 unbounded (API use only) [-].").at_least(-1));
  visit("rr_depth", s.rr_depth,
        about("Depth from which the Russian roulette of our renderer's paths starts; path-traced camera paths "
              "then survive with min(path_max_survival, throughput). The references have their own, "
              "reference.rr_depth [-].")
            .at_least(1));
  visit("seed", s.seed, about("Key of every random stream (API use only) [-].").at_least(0));
  visit("threads", s.threads, about("Worker threads; 0 uses every core (API use only) [-].").at_least(0));
  visit("accel", s.accel,
        about("Beam query structure: uniform grid of diced beams, or an Embree BVH over the same pieces [-]."));
  visit("grid_resolution", s.grid_resolution,
        about("Grid cells along the longest axis [-].").at_least(1).at_most(1024));
  visit("dice_length", s.dice_length,
        about("Length of the beam pieces the BVH or grid holds; 0 lets the core pick it (tests and benchmarks) [m].")
            .at_least(0)
            .only_from_the_api());
  visit("jitter", s.jitter,
        about("Jitter the camera rays within their pixels; false: rays through pixel centres (analytic tests) [-].")
            .only_from_the_api());
  visit("transmittance_cutoff", s.transmittance_cutoff,
        about("Long beams and queries end where the largest channel transmittance falls below this [-].")
            .above(0)
            .below(1));
  visit("camera_unwarp", s.camera_unwarp,
        about("Remove camera-side OPL from tau (never compare such frames with mitransient) [-]."));
  visit("tile_size", s.tile_size,
        about("Side of the camera pass's square pixel tiles (tests of the tiling) [pixels].")
            .at_least(1)
            .only_from_the_api());
  visit("snapshot_every", s.snapshot_every,
        about("Keep the steady average every k iterations for error-against-time curves (0: never) [-].").at_least(0));
  visit("checkpoint_every_iterations", s.checkpoint_every_iterations,
        about("Save the accumulated render (double sums, counters, snapshots) to runs/<name>/.render.checkpoint/ "
              "every k iterations, so that `pipeline run --resume` continues an interrupted render with the same "
              "bits (0: never) [-].")
            .at_least(0));
  visit("checkpoint_every_s", s.checkpoint_every_s,
        about("Also save a checkpoint when this much wall time has passed since the last one (null: never) [s].")
            .above(0)
            .none_when_zero());
  visit("memory_budget_gib", s.memory_budget_gib,
        about("Peak image buffers of one render pass. They take about 4 bytes per value of temporal_bins x height "
              "x width x 3 (float32 frame sums; 8 in a shard, which sums in float64) plus 36 per pixel value for "
              "steady, early and late and a double tile film per thread. A film over this renders in frame "
              "windows, one pass each (every pass re-traces the same random streams and keeps its window's frames, "
              "written straight to frames.npy), so the result does not depend on the split; the render stage logs "
              "the windows. 8 suits a 24 GiB machine; null: one pass whatever the size [GiB].")
            .above(0)
            .none_when_zero());
  visit("first_iteration", s.first_iteration,
        about("First iteration of the global schedule that this render runs; a shard runs [first_iteration, "
              "iterations) (render/ptpb/split.py) [-].")
            .at_least(0)
            .only_from_the_api());
  visit("keep_sums", s.keep_sums,
        about("Return the undivided sums in double, for an exact merge of shards (render/ptpb/split.py) [-].")
            .only_from_the_api());
}

}  // namespace ptpb
