// Checks before a render (DESIGN.md §9): settings, resume states and the memory budget.
#include "ptpb/validation.hpp"

#include <cmath>
#include <cstdio>
#include <stdexcept>
#include <string>

#include "ptpb/film.hpp"
#include "ptpb/parallel.hpp"
#include "ptpb/schedule.hpp"

namespace ptpb {
namespace {

std::string gib_text(double bytes) {
  char text[32];
  std::snprintf(text, sizeof text, "%.2f GiB", bytes / double(1ull << 30));
  return text;
}

template <typename T>
bool all_finite(const std::vector<T>& v) {
  for (T x : v)
    if (!std::isfinite(x)) return false;
  return true;
}

bool uses_frame_remainders(const RenderSettings& s) {
  return !s.keep_sums && (s.time_budget_s > 0 || s.iterations > s.compensated_sums_from);
}

}  // namespace

void validate_settings(const RenderSettings& s) {
  auto require = [](bool ok, const std::string& what) {
    if (!ok) throw std::invalid_argument(what);
  };
  require(s.iterations > 0 || s.time_budget_s > 0, "iterations must be > 0 (or give time_budget_s > 0)");
  require(std::isfinite(s.time_budget_s) && s.time_budget_s >= 0, "time_budget_s must be >= 0");
  require(s.light_paths_per_iteration > 0 && s.light_paths_per_iteration < (1ull << 32),
          "light_paths_per_iteration must lie in [1, 2^32)");
  require(!s.alpha || (*s.alpha > 0 && *s.alpha <= 1), "alpha must lie in (0, 1]");
  require(std::isfinite(s.initial_beam_radius) && s.initial_beam_radius > 0, "initial_beam_radius must be > 0 (m)");
  require(!s.initial_time_half_width || (std::isfinite(*s.initial_time_half_width) && *s.initial_time_half_width > 0),
          "initial_time_half_width must be > 0 (m of OPL)");
  require(s.parallel_guard_sin2 >= 0 && s.parallel_guard_sin2 < 1, "parallel_guard_sin2 must lie in [0, 1)");
  require(s.max_depth == -1 || s.max_depth >= 1, "max_depth must be -1 or >= 1");
  require(s.rr_depth >= 1, "rr_depth must be >= 1");
  require(std::isfinite(s.beam_radius_mfp) && s.beam_radius_mfp > 0, "beam_radius_mfp must be > 0");
  require(s.dense_optical_radius > 0, "dense_optical_radius must be > 0");
  require(s.path_max_survival > 0 && s.path_max_survival < 1, "path_max_survival must lie in (0, 1)");
  require(s.path_splits >= 0 && s.path_splits <= kMaxPathSplits,
          "path_splits must lie in [0, " + std::to_string(kMaxPathSplits) + "]");
  require(s.threads >= 0, "threads must be >= 0");
  require(s.tile_size >= 1, "tile_size must be >= 1");
  require(s.snapshot_every >= 0, "snapshot_every must be >= 0");
  require(s.transmittance_cutoff > 0 && s.transmittance_cutoff < 1, "transmittance_cutoff must lie in (0, 1)");
  require(s.dice_length >= 0, "dice_length must be >= 0");
  require(!s.initial_surface_radius || (std::isfinite(*s.initial_surface_radius) && *s.initial_surface_radius > 0),
          "initial_surface_radius must be > 0 (m)");
  require(!s.initial_surface_time_half_width ||
              (std::isfinite(*s.initial_surface_time_half_width) && *s.initial_surface_time_half_width > 0),
          "initial_surface_time_half_width must be > 0 (m of OPL)");
  require(!s.surface_alpha || (*s.surface_alpha > 0 && *s.surface_alpha <= 1), "surface_alpha must lie in (0, 1]");
  require(s.surface_normal_cos > 0 && s.surface_normal_cos <= 1, "surface_normal_cos must lie in (0, 1]");
  require(s.checkpoint_every_iterations >= 0, "checkpoint_every_iterations must be >= 0");
  require(std::isfinite(s.checkpoint_every_s) && s.checkpoint_every_s >= 0, "checkpoint_every_s must be >= 0 (s)");
  require(s.compensated_sums_from >= 0, "compensated_sums_from must be >= 0");
  require(std::isfinite(s.memory_budget_gib) && s.memory_budget_gib >= 0,
          "memory_budget_gib must be >= 0 (0: no limit)");
  require(s.first_iteration >= 0 && (s.time_budget_s > 0 || s.first_iteration < s.iterations),
          "first_iteration must lie in [0, iterations) (a shard runs iterations [first_iteration, iterations))");
  require(!(s.time_budget_s > 0 && (s.keep_sums || s.first_iteration > 0)),
          "time_budget_s and shards (first_iteration, keep_sums) do not mix: a shard runs a fixed range of iterations");
  require(!(s.keep_sums && (s.checkpoint_every_iterations > 0 || s.checkpoint_every_s > 0)),
          "keep_sums (a shard) does not take checkpoints: rerun a failed shard instead");
}

// A resume state must belong to this film, seed and bandwidth schedule: the bandwidths of its last
// iteration are recomputed and compared bit for bit, which catches changed R_0, T_0, alpha or mode.
void validate_resume(const RenderState& st, const Scene& scene, const RenderSettings& s, int W, int H, int F) {
  auto require = [](bool ok, const std::string& what) {
    if (!ok) throw std::invalid_argument("resume state: " + what);
  };
  require(st.width == W && st.height == H && st.frame_count == F,
          "it holds a " + std::to_string(st.width) + " x " + std::to_string(st.height) + " film with " +
              std::to_string(st.frame_count) + " frames, the scene has " + std::to_string(W) + " x " +
              std::to_string(H) + " with " + std::to_string(F));
  const std::size_t px3 = std::size_t(W) * H * 3;
  require(st.steady.size() == px3 && st.early.size() == px3 && st.late.size() == px3 &&
              st.frames.size() == std::size_t(F) * px3,
          "its sums do not have the film's size");
  require(st.frames_carry.empty() || st.frames_carry.size() == st.frames.size(),
          "its frame remainders do not have the film's size");
  require(
      st.frames_carry.empty() == (st.stats.iterations_done <= s.compensated_sums_from || F == 0),
      st.frames_carry.empty()
          ? "it lacks the frame remainders a state past iteration " + std::to_string(s.compensated_sums_from) + " holds"
          : "it holds frame remainders before iteration " + std::to_string(s.compensated_sums_from));
  require(st.seed == s.seed, "it was rendered with seed " + std::to_string(st.seed) + ", the settings have seed " +
                                 std::to_string(s.seed));
  const int done = st.stats.iterations_done;
  require(done >= 0, "iterations_done must be >= 0");
  require(s.time_budget_s > 0 || done <= s.iterations,
          "it already holds " + std::to_string(done) +
              " iterations, more than settings.iterations = " + std::to_string(s.iterations));
  require(st.snapshot_iterations.size() == st.snapshots.size() && st.snapshot_seconds.size() == st.snapshots.size(),
          "its snapshot lists differ in length");
  for (const auto& snap : st.snapshots) require(snap.size() == px3, "a snapshot does not have the film's size");
  require(all_finite(st.steady) && all_finite(st.early) && all_finite(st.late) && all_finite(st.frames) &&
              all_finite(st.frames_carry),
          "its sums hold NaN or infinite values (a damaged checkpoint)");
  if (done == 0) return;
  double R, T, r_s, T_s;
  const Schedule schedule = resolve_schedule(scene.film.mode, s);
  iteration_bandwidths(scene.film.mode, schedule, done - 1, R, T);
  surface_bandwidths(scene.film.mode, schedule, done - 1, r_s, T_s);
  require(R == st.stats.final_radius && T == st.stats.final_time_half_width && r_s == st.stats.final_surface_radius &&
              T_s == st.stats.final_surface_time_half_width,
          "its bandwidths after " + std::to_string(done) +
              " iterations differ from this schedule's (initial radii, time half-widths, alpha or frame mode changed)");
}

double render_memory_bytes(const Scene& scene, const RenderSettings& s, bool state_copy) {
  const double px3 = double(std::max(0, scene.camera.width)) * double(std::max(0, scene.camera.height)) * 3.0;
  const double F = film_frame_count(scene.film);
  const double snapshots = s.snapshot_every > 0 && s.time_budget_s <= 0 ? double(s.iterations / s.snapshot_every) : 0.0;
  const double snapshot_bytes = snapshots * px3 * sizeof(float);
  // Double sums of steady, early, late and their float32 results; float32 frame sums (scaled in
  // place into the result), with as many remainders in a long run; a double tile film per thread.
  const double planes = 3.0 * px3 * (sizeof(double) + sizeof(float));
  const double frames =
      F * px3 * (s.keep_sums ? sizeof(double) : sizeof(float) * (uses_frame_remainders(s) ? 2.0 : 1.0));
  const double tiles =
      double(resolve_thread_count(s.threads)) * double(s.tile_size) * s.tile_size * 3.0 * (3.0 + F) * sizeof(double);
  double bytes = planes + frames + tiles + snapshot_bytes;
  if (state_copy) bytes += 3.0 * px3 * sizeof(double) + frames + snapshot_bytes;
  return bytes;
}

void check_memory_budget(const Scene& scene, const RenderSettings& s, bool state_copy) {
  if (s.memory_budget_gib <= 0) return;
  const double bytes = render_memory_bytes(scene, s, state_copy);
  if (bytes <= s.memory_budget_gib * double(1ull << 30)) return;
  char budget[32];
  std::snprintf(budget, sizeof budget, "%g", s.memory_budget_gib);
  throw std::invalid_argument(
      "the film needs " + gib_text(bytes) + " for its image buffers (" + std::to_string(film_frame_count(scene.film)) +
      " frames of " + std::to_string(scene.camera.width) + " x " + std::to_string(scene.camera.height) +
      " px), more than render.memory_budget_gib = " + budget +
      "; render the film in frame windows (scene.film window_first/window_count; the render stage plans them), "
      "lower scene.film.temporal_bins or scene.camera.width/height, or raise render.memory_budget_gib");
}

}  // namespace ptpb
