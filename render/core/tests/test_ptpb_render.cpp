// Render-level tests of the PTPB core: analytic single scattering, energy bookkeeping of bins,
// thread invariance, grid/BVH agreement, the schedule actually reaching the structure, input
// validation, checkpoints and resume, and the memory budget.
#include <cmath>
#include <cstring>
#include <optional>
#include <string>

#include "check.hpp"
#include "ptpb/kernels.hpp"
#include "ptpb/render.hpp"
#include "ptpb/sampling.hpp"
#include "ptpb/validation.hpp"

using namespace ptpb;

namespace {

Shape box(double h, SurfaceKind kind, int interior) {
  Shape s;
  s.kind = kind;
  s.interior = interior;
  for (int i = 0; i < 8; ++i)
    for (int a = 0; a < 3; ++a) s.vertices.push_back(float(((i >> a) & 1) ? h : -h));
  const int quads[6][4] = {{0, 2, 3, 1}, {4, 5, 7, 6}, {0, 1, 5, 4}, {2, 6, 7, 3}, {0, 4, 6, 2}, {1, 3, 7, 5}};
  for (auto& q : quads) {
    for (int k : {q[0], q[1], q[2], q[0], q[2], q[3]}) s.faces.push_back(std::uint32_t(k));
  }
  return s;
}

// DESIGN.md §10 test 3: camera at the centre of a 10 m index-matched cube, light at (0, -3, 0).
Scene single_scattering_scene(double ior) {
  Scene sc;
  Medium m;
  m.sigma_s = {0.1, 0.1, 0.1};
  m.ior = ior;
  sc.media.push_back(m);
  sc.shapes.push_back(box(10.0, SurfaceKind::Null, 0));
  sc.point_lights.push_back({{0, -3, 0}, {1, 1, 1}, 0});
  sc.camera.origin = {0, 0, 0};
  sc.camera.target = {1, 0, 0};
  sc.camera.up = {0, 0, 1};
  sc.camera.width = sc.camera.height = 1;
  sc.camera.fov_deg = 1.0;
  sc.camera.medium = 0;
  return sc;
}

// Numerical quadrature of the closed form of §10 test 3 (ray along +x, t_p = 0, h = 3).
double single_scattering_reference(double sigma_s, double sigma_t, double h, double t_exit) {
  const int n = 200000;
  const double u0 = 0.0, u1 = std::atan(t_exit / h);
  double sum = 0.0;
  for (int i = 0; i < n; ++i) {
    const double u = u0 + (u1 - u0) * (i + 0.5) / n;
    sum += hg_eval(-std::sin(u), 0.0) * std::exp(-sigma_t * (h * std::tan(u) + h / std::cos(u)));
  }
  return sigma_s / h * sum * (u1 - u0) / n;
}

Scene cube_scene() {
  Scene sc;
  Medium m;
  m.sigma_s = {3.6, 5.4, 7.2};
  m.sigma_a = {0.4, 0.6, 0.8};
  m.g = 0.7;
  sc.media.push_back(m);
  sc.shapes.push_back(box(0.5, SurfaceKind::Null, 0));
  Shape light;
  light.kind = SurfaceKind::Diffuse;
  light.radiance = {20, 20, 20};
  light.vertices = {-0.25f, 2.0f, -0.25f, 0.25f, 2.0f, -0.25f, 0.25f, 2.0f, 0.25f, -0.25f, 2.0f, 0.25f};
  light.faces = {0, 1, 2, 0, 2, 3};  // wound so the normal points down (-y)
  sc.shapes.push_back(light);
  sc.camera.origin = {0, 1.0, 3.0};
  sc.camera.target = {0, 0, 0};
  sc.camera.width = 24;
  sc.camera.height = 20;
  sc.camera.fov_deg = 40;
  sc.film.mode = FrameMode::Bins;
  sc.film.temporal_bins = 40;
  sc.film.start_opl = 3.0;
  sc.film.bin_width_opl = 0.05;
  return sc;
}

RenderSettings small_settings() {
  RenderSettings s;
  s.iterations = 3;
  s.light_paths_per_iteration = 3000;
  s.initial_beam_radius = 0.03;
  s.max_depth = 16;
  s.seed = 5;
  s.threads = 1;
  s.medium_estimator = MediumEstimator::Beams;  // these tests check the beam estimator (DESIGN.md §12)
  return s;
}

// The message render() refuses with (std::invalid_argument), or "" when it renders.
std::string refusal(const Scene& sc, const RenderSettings& s, std::optional<RenderState> resume = std::nullopt) {
  try {
    render(sc, s, nullptr, std::move(resume));
  } catch (const std::invalid_argument& e) {
    return e.what();
  }
  return "";
}

bool contains(const std::string& text, const char* part) { return text.find(part) != std::string::npos; }

}  // namespace

TEST_CASE("single scattering from a point light matches the analytic radiance (4%, smoke level)") {
  const double ref = single_scattering_reference(0.1, 0.1, 3.0, 10.0);
  CHECK_NEAR(ref, 1.74043e-3, 2e-8);
  RenderSettings s;
  s.iterations = 8;
  s.light_paths_per_iteration = 100000;
  s.initial_beam_radius = 0.02;
  s.alpha = 0.8;
  s.max_depth = 2;
  s.jitter = false;
  s.threads = 2;
  const RenderResult r = render(single_scattering_scene(1.0), s);
  for (int c = 0; c < 3; ++c) CHECK_CLOSE(r.steady[c], ref, 0.04);
  std::printf("single scattering: %.6e vs %.6e (%.2f%%)\n", r.steady[0], ref, 100.0 * (r.steady[0] / ref - 1.0));
}

TEST_CASE("bins: frames + early + late equal the steady image; threads and structures agree") {
  const Scene sc = cube_scene();
  RenderSettings s = small_settings();
  const RenderResult a = render(sc, s);
  const int P = a.width * a.height;
  double total = 0.0, worst = 0.0;
  for (int i = 0; i < P * 3; ++i) {
    double sum = a.early[i] + a.late[i];
    for (int k = 0; k < a.frame_count; ++k) sum += a.frames[std::size_t(k) * P * 3 + i];
    worst = std::max(worst, std::fabs(sum - a.steady[i]) / std::max(1e-12, double(a.steady[i])));
    total += a.steady[i];
  }
  CHECK(total > 0);
  CHECK(worst < 1e-4);
  CHECK(a.stats.pair_evaluations > 0);
  s.threads = 2;
  const RenderResult b = render(sc, s);
  CHECK(std::memcmp(a.steady.data(), b.steady.data(), a.steady.size() * 4) == 0);
  CHECK(std::memcmp(a.frames.data(), b.frames.data(), a.frames.size() * 4) == 0);
  s.tile_size = 7;
  const RenderResult c = render(sc, s);
  CHECK(std::memcmp(a.frames.data(), c.frames.data(), a.frames.size() * 4) == 0);
  s.accel = AccelKind::Embree;
  const RenderResult d = render(sc, s);
  double max_rel = 0.0;
  for (std::size_t i = 0; i < a.steady.size(); ++i)
    max_rel = std::max(max_rel, std::fabs(a.steady[i] - d.steady[i]) / std::max(1e-9, double(a.steady[i])));
  CHECK(max_rel < 1e-5);
  CHECK(a.stats.pair_evaluations == d.stats.pair_evaluations);
}

TEST_CASE("a frame window holds exactly those frames of the whole film; early and late stay the film's") {
  for (FrameMode mode : {FrameMode::Bins, FrameMode::Gate}) {
    Scene sc = cube_scene();
    sc.film.mode = mode;
    const RenderSettings s = small_settings();
    const RenderResult whole = render(sc, s);
    sc.film.window_first = 7;
    sc.film.window_count = 9;
    const RenderResult window = render(sc, s);
    CHECK(window.frame_count == 9);
    const std::size_t px3 = std::size_t(whole.width) * whole.height * 3;
    bool same = window.early == whole.early && window.late == whole.late && window.steady == whole.steady;
    for (std::size_t i = 0; i < window.frames.size(); ++i) same = same && window.frames[i] == whole.frames[7 * px3 + i];
    CHECK(same);
  }
}

TEST_CASE("shards: iterations [a, b) in double sums add up to the whole run") {
  Scene sc = cube_scene();
  sc.film.mode = FrameMode::Gate;
  RenderSettings s = small_settings();
  s.iterations = 4;
  const RenderResult whole = render(sc, s);
  s.keep_sums = true;
  s.iterations = 1;
  const RenderResult first = render(sc, s);
  s.first_iteration = 1;
  s.iterations = 4;
  const RenderResult rest = render(sc, s);
  CHECK(first.frames.empty() && first.frames_sum.size() == whole.frames.size());
  CHECK(rest.stats.iterations_done == 4);
  double worst = 0.0;
  for (std::size_t i = 0; i < whole.frames.size(); ++i) {
    const double merged = (first.frames_sum[i] + rest.frames_sum[i]) / 4.0;
    if (whole.frames[i] > 0) worst = std::max(worst, std::abs(merged - whole.frames[i]) / whole.frames[i]);
  }
  CHECK(worst < 1e-6);
  s.time_budget_s = 1.0;
  CHECK_THROWS(render(sc, s));  // shards do not take a time budget
}

TEST_CASE("the structure is built with the scheduled radius R_i") {
  RenderSettings s = small_settings();
  s.iterations = 11;
  s.light_paths_per_iteration = 200;
  Scene sc = cube_scene();
  sc.film.mode = FrameMode::Gate;
  s.alpha = 2.0 / 3.0;
  s.initial_time_half_width = 0.01;
  const RenderResult r = render(sc, s);
  CHECK_CLOSE(r.stats.final_radius, s.initial_beam_radius * std::sqrt(0.493106), 1e-5);
  CHECK_CLOSE(r.stats.final_time_half_width, 0.01 * std::sqrt(0.493106), 1e-5);
  sc.film.mode = FrameMode::Bins;
  s.alpha = 0.8;
  const RenderResult q = render(sc, s);
  CHECK_CLOSE(q.stats.final_radius, s.initial_beam_radius * 0.659878, 1e-5);
}

TEST_CASE("the core resolves every schedule default and reports it in stats") {
  RenderSettings s = small_settings();  // R_0 = 3 cm, nothing else of the schedule set
  s.iterations = 1;
  s.light_paths_per_iteration = 100;
  Scene sc = cube_scene();
  for (FrameMode mode : {FrameMode::Steady, FrameMode::Bins, FrameMode::Gate}) {
    sc.film.mode = mode;
    const Schedule resolved = render(sc, s).stats.schedule;
    CHECK(resolved.alpha == (mode == FrameMode::Gate ? 2.0 / 3.0 : 0.8));
    CHECK(resolved.surface_alpha == (mode == FrameMode::Gate ? 4.0 / 7.0 : 2.0 / 3.0));
    CHECK(resolved.initial_beam_radius == 0.03);
    CHECK(resolved.initial_time_half_width == 0.03);  // T_0, r_0 and the surfaces' T_0 fall back to R_0
    CHECK(resolved.initial_surface_radius == 0.03);
    CHECK(resolved.initial_surface_time_half_width == 0.03);
  }
  s.alpha = 0.7;
  s.surface_alpha = 0.6;
  s.initial_time_half_width = 0.02;
  s.initial_surface_radius = 0.05;
  Schedule resolved = render(sc, s).stats.schedule;
  CHECK(resolved.alpha == 0.7 && resolved.surface_alpha == 0.6);
  CHECK(resolved.initial_time_half_width == 0.02 && resolved.initial_surface_radius == 0.05);
  CHECK(resolved.initial_surface_time_half_width == 0.02);  // the beams' T_0
  s.initial_surface_time_half_width = 0.04;
  resolved = render(sc, s).stats.schedule;
  CHECK(resolved.initial_surface_time_half_width == 0.04);
}

TEST_CASE("bad input throws with the parameter's name") {
  RenderSettings s = small_settings();
  Scene sc = cube_scene();
  s.alpha = 1.5;
  CHECK_THROWS(render(sc, s));
  s = small_settings();
  s.initial_beam_radius = -1;
  CHECK_THROWS(render(sc, s));
  s = small_settings();
  sc.media[0].g = 1.0;
  CHECK_THROWS(render(sc, s));
  sc = cube_scene();
  sc.shapes[0].interior = 4;
  CHECK_THROWS(render(sc, s));
  sc = cube_scene();
  sc.film.temporal_bins = 0;
  CHECK_THROWS(render(sc, s));
  sc = cube_scene();
  sc.camera.fov_axis = "z";
  CHECK(contains(refusal(sc, s), "fov_axis"));
}

TEST_CASE("cancellation keeps the completed iterations") {
  RenderSettings s = small_settings();
  s.iterations = 10;
  int calls = 0;
  const RenderResult r = render(cube_scene(), s, [&](const Progress& p) {
    ++calls;
    return p.iteration < 2;
  });
  CHECK(r.stats.cancelled);
  CHECK(r.stats.iterations_done == 2);
  CHECK(calls >= 2);
}

bool same_bits(const std::vector<float>& a, const std::vector<float>& b) {
  return a.size() == b.size() && std::memcmp(a.data(), b.data(), a.size() * sizeof(float)) == 0;
}

TEST_CASE("frame sums with rounding remainders: same averages, resumed bit-identically across the switch") {
  const Scene sc = cube_scene();
  RenderSettings s = small_settings();
  s.iterations = 6;
  const RenderResult plain = render(sc, s);
  s.compensated_sums_from = 3;  // iterations 3..5 add into (sum, remainder) pairs
  s.checkpoint_every_iterations = 2;
  std::vector<RenderState> states;
  const RenderResult whole = render(sc, s, nullptr, std::nullopt, [&](const RenderState& st) {
    states.push_back(st);
    return true;
  });
  CHECK(states.size() == 2);
  if (states.size() != 2) return;
  CHECK(states[0].frames_carry.empty() && states[1].frames_carry.size() == states[1].frames.size());
  // The pairs only change rounding: the averages agree with the plain float sums to float accuracy.
  double worst = 0.0, peak = 0.0;
  for (float v : plain.frames) peak = std::max(peak, double(v));
  for (std::size_t i = 0; i < plain.frames.size(); ++i)
    worst = std::max(worst, std::fabs(double(plain.frames[i]) - double(whole.frames[i])));
  CHECK(peak > 0 && worst <= 1e-6 * peak);
  CHECK(same_bits(plain.steady, whole.steady));  // the double sums are untouched
  for (const RenderState& st : states) {
    const RenderResult resumed = render(sc, s, nullptr, st);
    CHECK(same_bits(whole.frames, resumed.frames) && same_bits(whole.steady, resumed.steady));
  }
  // A state past the switch without its remainders is refused, naming them.
  RenderState damaged = states[1];
  damaged.frames_carry.clear();
  CHECK(contains(refusal(sc, s, damaged), "remainders"));
}

TEST_CASE("a render resumed from a checkpoint has the bits of an uninterrupted one") {
  for (FrameMode mode : {FrameMode::Bins, FrameMode::Gate}) {
    Scene sc = cube_scene();
    sc.film.mode = mode;
    RenderSettings s = small_settings();
    s.iterations = 5;
    s.alpha = mode == FrameMode::Gate ? 2.0 / 3.0 : 0.8;
    s.snapshot_every = 2;
    s.checkpoint_every_iterations = 2;
    std::vector<RenderState> states;
    const RenderResult whole = render(sc, s, nullptr, std::nullopt, [&](const RenderState& st) {
      states.push_back(st);
      return true;
    });
    CHECK(states.size() == 2);  // after iterations 2 and 4; none after the last
    if (states.size() != 2) continue;
    CHECK(states[0].stats.iterations_done == 2 && states[1].stats.iterations_done == 4);
    s.threads = 2;  // thread invariance carries over to a resumed run
    const RenderResult resumed = render(sc, s, nullptr, states[0]);
    CHECK(resumed.stats.iterations_done == 5);
    CHECK(same_bits(whole.steady, resumed.steady) && same_bits(whole.frames, resumed.frames));
    CHECK(same_bits(whole.early, resumed.early) && same_bits(whole.late, resumed.late));
    CHECK(resumed.stats.pair_evaluations == whole.stats.pair_evaluations);
    CHECK(resumed.stats.light_paths == whole.stats.light_paths && resumed.stats.beams == whole.stats.beams);
    CHECK(resumed.snapshot_iterations == whole.snapshot_iterations);
    CHECK(resumed.snapshots.size() == 2 && same_bits(resumed.snapshots[1], whole.snapshots[1]));
    // Nothing left to do: the state of iteration 4 of 4 gives the average of its 4 iterations.
    s.iterations = 4;
    const RenderResult done = render(sc, s, nullptr, states[1]);
    CHECK(done.stats.iterations_done == 4 && done.stats.steady_total > 0);
  }
}

TEST_CASE("a resume state from other settings or another film is refused with the reason") {
  const Scene sc = cube_scene();
  RenderSettings s = small_settings();
  s.checkpoint_every_iterations = 1;
  std::vector<RenderState> states;
  render(sc, s, nullptr, std::nullopt, [&](const RenderState& st) {
    states.push_back(st);
    return true;
  });
  CHECK(states.size() == 2);
  if (states.empty()) return;
  RenderSettings other = s;
  other.initial_beam_radius *= 1.5;
  CHECK(contains(refusal(sc, other, states[0]), "bandwidths"));
  other = s;
  other.seed += 1;
  CHECK(contains(refusal(sc, other, states[0]), "seed"));
  other = s;
  other.iterations = 1;  // fewer than the state of iteration 2 holds
  CHECK(contains(refusal(sc, other, states[1]), "more than settings.iterations"));
  Scene wide = sc;
  wide.camera.width += 1;
  CHECK(contains(refusal(wide, s, states[0]), "film"));
  RenderState damaged = states[0];
  damaged.frames[7] = std::nan("");
  CHECK(contains(refusal(sc, s, damaged), "damaged"));
}

TEST_CASE("a cancelled render hands its completed iterations to the checkpoint callback") {
  RenderSettings s = small_settings();
  s.iterations = 10;
  s.checkpoint_every_iterations = 100;  // never due: only the cancellation checkpoints
  std::vector<int> saved;
  const RenderResult r = render(
      cube_scene(), s, [](const Progress& p) { return p.iteration < 2; }, std::nullopt,
      [&](const RenderState& st) {
        saved.push_back(st.stats.iterations_done);
        return true;
      });
  CHECK(r.stats.cancelled && r.stats.iterations_done == 2);
  CHECK(saved.size() == 1 && saved[0] == 2);
  // A false return from the checkpoint callback cancels like the progress callback.
  s.checkpoint_every_iterations = 1;
  saved.clear();
  const RenderResult c = render(cube_scene(), s, nullptr, std::nullopt, [&](const RenderState& st) {
    saved.push_back(st.stats.iterations_done);
    return false;
  });
  CHECK(c.stats.cancelled && c.stats.iterations_done == 1 && saved.size() == 1);
}

TEST_CASE("a film over the memory budget is refused before it is allocated") {
  Scene sc = cube_scene();  // 24 x 20 px, 40 bins
  RenderSettings s = small_settings();
  const double px3 = 24.0 * 20 * 3, F = 40;
  // Double steady/early/late sums with their float32 results, float32 frame sums scaled in place,
  // and one double tile film (tile_size^2 x 3 x (3 + F)) per thread.
  const double tiles = s.threads * double(s.tile_size) * s.tile_size * 3 * (3 + F) * 8;
  const double base = px3 * 3 * (8 + 4) + px3 * F * 4 + tiles;
  CHECK(render_memory_bytes(sc, s, false) == base);
  CHECK(render_memory_bytes(sc, s, true) == base + px3 * 3 * 8 + px3 * F * 4);  // the state's copy
  s.snapshot_every = 1;
  CHECK(render_memory_bytes(sc, s, false) == base + s.iterations * px3 * 4);
  s.snapshot_every = 0;
  s.iterations = s.compensated_sums_from + 1;  // past 10^4 iterations the frame sums carry remainders
  CHECK(render_memory_bytes(sc, s, false) == base + px3 * F * 4);
  s = small_settings();
  sc.film.temporal_bins = 100000;
  sc.camera.width = sc.camera.height = 4096;  // 18 TiB of float32 frames
  const std::string what = refusal(sc, s);
  CHECK(contains(what, "render.memory_budget_gib = 8"));
  CHECK(contains(what, "scene.film.temporal_bins"));
  CHECK(contains(what, "scene.camera.width/height"));
  sc = cube_scene();
  s.memory_budget_gib = 1e-4;  // 105 kB < 0.55 MB
  CHECK_THROWS(render(sc, s));
  s.memory_budget_gib = 0;  // no limit
  CHECK(render(sc, s).stats.iterations_done == 3);
}

TEST_CASE("a lossless medium with unbounded depth terminates: roulette survival is capped") {
  Scene sc = cube_scene();
  sc.media[0].sigma_s = {1e4, 1e4, 1e4};  // optical depth 1e4 across the cube, albedo exactly 1
  sc.media[0].sigma_a = {0, 0, 0};
  sc.film.mode = FrameMode::Steady;
  RenderSettings s = small_settings();
  s.iterations = 1;
  s.light_paths_per_iteration = 500;
  s.max_depth = -1;
  const RenderResult r = render(sc, s);
  bool finite = true;
  for (float v : r.steady) finite = finite && std::isfinite(v);
  CHECK(finite && r.stats.beams > 0);
  CHECK(double(r.stats.beams) / r.stats.light_paths < 100);  // ~rr_depth + 1/(1 - 0.95) beams per path
}

PTPB_TEST_MAIN()
