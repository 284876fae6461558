// The progressive PTPB loop (DESIGN.md §4–§7, §9): per iteration, trace M light paths into beams
// and surface photons, build the beam structure with R_i and the photon grid with r_i, trace one
// jittered camera path per pixel, evaluate every ray–beam pair and every photon at a diffuse
// camera hit once, and splat it into the steady image and every frame its kernel covers. The
// estimators live elsewhere: light_tracer.cpp, camera.cpp and gather.cpp, with the film in film.cpp.
#include "ptpb/render.hpp"

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <memory>
#include <mutex>
#include <thread>

#include "ptpb/beam_accel.hpp"
#include "ptpb/beams.hpp"
#include "ptpb/camera.hpp"
#include "ptpb/compiled_scene.hpp"
#include "ptpb/film.hpp"
#include "ptpb/light_tracer.hpp"
#include "ptpb/parallel.hpp"
#include "ptpb/path_tracer.hpp"
#include "ptpb/schedule.hpp"
#include "ptpb/surface_photons.hpp"
#include "ptpb/validation.hpp"

namespace ptpb {
namespace {

using Clock = std::chrono::steady_clock;
double seconds_since(Clock::time_point t0) { return std::chrono::duration<double>(Clock::now() - t0).count(); }

}  // namespace

RenderResult render(const Scene& scene, const RenderSettings& settings, const ProgressCallback& progress,
                    std::optional<RenderState> resume, const CheckpointCallback& checkpoint) {
  validate_settings(settings);
  check_memory_budget(scene, settings,
                      resume.has_value() || (checkpoint && (settings.checkpoint_every_iterations > 0 ||
                                                            settings.checkpoint_every_s > 0)));
  const auto t_start = Clock::now();
  const CompiledScene cs(scene);
  const Camera& cam = scene.camera;
  const Film& film = scene.film;
  const int W = cam.width, H = cam.height;
  const int F = film_frame_count(film);
  const std::size_t px_count = std::size_t(W) * H;
  const std::size_t frame_values = std::size_t(F) * px_count * 3;

  if (resume) validate_resume(*resume, scene, settings, W, H, F);
  RenderState state = resume ? std::move(*resume) : empty_state(W, H, F, settings);
  resume.reset();
  RenderStats& stats = state.stats;
  stats.cancelled = false;
  stats.schedule = resolve_schedule(film.mode, settings);
  const double time_before = stats.time_total_s;  // render time of the runs this one continues
  auto elapsed = [&] { return time_before + seconds_since(t_start); };

  CameraPass pass{};
  pass.cs = &cs;
  pass.st = &settings;
  pass.camera = make_camera_frame(cam);
  pass.far_length = 4.0 * cs.sphere_radius() + length(cam.origin - cs.sphere_center());
  pass.inv_paths = 1.0 / double(settings.light_paths_per_iteration);
  TileFilmPool tile_films(settings.tile_size, F);

  auto accel = make_beam_accel(settings.accel, settings.grid_resolution, settings.dice_length);
  auto specular_accel = make_beam_accel(settings.accel, settings.grid_resolution, settings.dice_length);
  const std::thread::id caller = std::this_thread::get_id();
  std::atomic<bool> cancel{false};
  auto last_report = Clock::now();
  auto last_checkpoint = Clock::now();
  int checkpointed_iterations = stats.iterations_done;
  std::mutex stats_mutex;  // tiles add their counts to stats (the resumed totals continue)
  const bool checkpointing =
      checkpoint && (settings.checkpoint_every_iterations > 0 || settings.checkpoint_every_s > 0);
  auto save_checkpoint = [&] {
    stats.time_total_s = elapsed();
    checkpointed_iterations = stats.iterations_done;
    last_checkpoint = Clock::now();
    return checkpoint(state);
  };
  const int tiles_x = (W + settings.tile_size - 1) / settings.tile_size;
  const int tiles_y = (H + settings.tile_size - 1) / settings.tile_size;
  const long max_iterations = settings.time_budget_s > 0 ? (1L << 40) : settings.iterations;
  const std::uint64_t M = settings.light_paths_per_iteration;

  auto report = [&](int done, double R, double T, std::uint64_t nbeams, double r_s, std::uint64_t nphotons) {
    if (!progress) return;
    Progress pr{done, settings.time_budget_s > 0 ? -1 : settings.iterations, elapsed(), R, T, nbeams, r_s, nphotons};
    last_report = Clock::now();
    if (!progress(pr)) cancel.store(true);
  };

  LightRecords records;
  std::vector<Beam>& beams = records.beams;
  std::vector<SurfacePhoton>& photons = records.photons;
  std::vector<Beam>& specular_beams = records.specular_beams;
  SurfacePhotonGrid photon_grid;
  for (long it = stats.iterations_done; it < max_iterations && !cancel.load(); ++it) {
    if (settings.time_budget_s > 0 && it > 0 && elapsed() >= settings.time_budget_s) break;
    double R, T;
    iteration_bandwidths(film.mode, stats.schedule, it, R, T);
    if (film.mode == FrameMode::Gate) T = std::max(T, 0.0);
    double r_s, T_s;
    surface_bandwidths(film.mode, stats.schedule, it, r_s, T_s);

    // 0. Which media path trace in this iteration (§12). Light paths are needed only where they can
    // leave a record: a beam in a medium that keeps beams, a photon on a diffuse surface, or a
    // specular-delta beam in a medium on paths (a delta light and a dielectric in the scene).
    const std::vector<char> path_media = media_using_paths(cs, settings, R);
    bool beam_media = false, any_path_media = false;
    for (std::size_t m = 0; m < path_media.size(); ++m) {
      beam_media |= cs.scattering(int(m)) && !path_media[m];
      any_path_media |= path_media[m] != 0;
    }
    const std::vector<double> specular_radii =
        specular_beam_radii(cs, settings, path_media, R, stats.schedule.initial_beam_radius);
    double specular_radius = 0.0;
    for (double r : specular_radii) specular_radius = std::max(specular_radius, r);

    // 1. Light paths, in fixed chunks of path indices; beams and photons kept in path order (§9).
    auto t0 = Clock::now();
    const bool light_pass =
        beam_media || cs.has_diffuse_reflectors() || (any_path_media && cs.has_specular_delta_light());
    if (light_pass) {
      trace_light_paths(cs, settings, static_cast<std::uint64_t>(it), records, path_media);
    } else {
      beams.clear();
      photons.clear();
      specular_beams.clear();
    }
    // Beams in space order (a deterministic function of the path-ordered beams): the structure's
    // leaves and the gather then read neighbouring records.
    sort_beams_spatially(beams, settings.threads);
    sort_beams_spatially(specular_beams, settings.threads);
    stats.time_light_s += seconds_since(t0);

    // 2. The beam structure, with this iteration's radius.
    t0 = Clock::now();
    accel->build(beams, R, settings.threads);
    // Specular-delta beams: one structure at the largest of their per-medium radii (§12).
    specular_accel->build(specular_beams, specular_beams.empty() ? R : specular_radius, settings.threads);
    stats.time_build_s += seconds_since(t0);
    t0 = Clock::now();
    photon_grid.build(photons, r_s);
    stats.time_surface_build_s += seconds_since(t0);

    // 3. Camera pass by tiles; each tile owns its pixels.
    t0 = Clock::now();
    if (it >= settings.compensated_sums_from && F > 0 && !settings.keep_sums && state.frames_carry.empty())
      state.frames_carry.assign(frame_values, 0.0f);
    pass.beams = BeamLayer{&beams, accel.get(), accel->radius(), nullptr};
    pass.specular_beams = BeamLayer{&specular_beams, specular_accel.get(), specular_accel->radius(), &specular_radii};
    pass.iteration = static_cast<std::uint64_t>(it);
    pass.time_half_width = T;
    pass.photons = &photons;
    pass.photon_grid = &photon_grid;
    pass.path_media = &path_media;
    pass.surface_radius = photon_grid.radius();
    pass.surface_time_half_width = T_s;
    // Tiles add straight into the sums, so a pass is never left half done: a cancel that arrives
    // during it takes effect after it (DESIGN.md §9; the iteration is kept, not dropped).
    parallel_for_chunks(
        std::size_t(tiles_x) * tiles_y, 1, settings.threads, [&](std::size_t t_begin, std::size_t t_end) {
          std::vector<std::uint32_t> cand;
          std::unique_ptr<TileFilm> tile = tile_films.take();
          for (std::size_t t = t_begin; t < t_end; ++t) {
            TileStats ts;
            const int x0 = int(t % tiles_x) * settings.tile_size, y0 = int(t / tiles_x) * settings.tile_size;
            const int x1 = std::min(W, x0 + settings.tile_size), y1 = std::min(H, y0 + settings.tile_size);
            tile->place(x0, y0, x1 - x0, y1 - y0);
            for (int y = y0; y < y1; ++y)
              for (int x = x0; x < x1; ++x) trace_camera_path(pass, *tile, x, y, cand, ts);
            tile->flush(state);
            {
              std::lock_guard<std::mutex> lock(stats_mutex);
              ts.add_to(stats);
            }
            // Only the calling thread may talk to Python (signals are delivered to the main thread).
            if (std::this_thread::get_id() == caller && seconds_since(last_report) > 0.5)
              report(int(it), R, T, beams.size() + specular_beams.size(), r_s, photons.size());
          }
          tile_films.give_back(std::move(tile));
        });
    stats.time_camera_s += seconds_since(t0);
    stats.iterations_done = int(it + 1);
    if (light_pass) stats.light_paths += M;
    stats.beams += beams.size();
    stats.specular_beams += specular_beams.size();
    stats.final_specular_radius = specular_beams.empty() ? stats.final_specular_radius : specular_radius;
    stats.accel_references += accel->references() + specular_accel->references();
    stats.final_radius = R;
    stats.path_media = int(std::count(path_media.begin(), path_media.end(), char(1)));
    stats.final_time_half_width = T;
    stats.surface_photons += photons.size();
    stats.final_surface_radius = photon_grid.radius();
    stats.final_surface_time_half_width = T_s;
    if (settings.snapshot_every > 0 && (it + 1) % settings.snapshot_every == 0) add_snapshot(state, it + 1, elapsed());
    report(int(it + 1), R, T, beams.size() + specular_beams.size(), r_s, photons.size());
    // No checkpoint after the last planned iteration: the result itself follows at once.
    const bool due =
        (settings.checkpoint_every_iterations > 0 && (it + 1) % settings.checkpoint_every_iterations == 0) ||
        (settings.checkpoint_every_s > 0 && seconds_since(last_checkpoint) >= settings.checkpoint_every_s);
    if (checkpointing && due && it + 1 < max_iterations && !cancel.load() && !save_checkpoint()) cancel.store(true);
  }

  // A cancelled run keeps its completed iterations for a later resume.
  if (checkpointing && cancel.load() && stats.iterations_done > checkpointed_iterations) save_checkpoint();
  stats.cancelled = cancel.load();
  RenderResult result = settings.keep_sums ? sum_state(state) : average_state(state);
  result.stats.time_total_s = elapsed();
  return result;
}

}  // namespace ptpb
