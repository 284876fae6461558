// The progressive PTPB loop (ptpb.md §4–§7, §9): per iteration, trace M light paths into beams
// and surface photons, build the beam structure with R_i and the photon grid with r_i, trace one
// jittered camera path per pixel, evaluate every ray–beam pair and every photon at a diffuse
// camera hit once, and splat it into the steady image and every frame its kernel covers.
#include "ptpb/render.hpp"

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <limits>
#include <memory>
#include <mutex>
#include <stdexcept>
#include <string>
#include <thread>

#include "ptpb/beam_accel.hpp"
#include "ptpb/beam_geometry.hpp"
#include "ptpb/beams.hpp"
#include "ptpb/compiled_scene.hpp"
#include "ptpb/parallel.hpp"
#include "ptpb/rng.hpp"
#include "ptpb/sampling.hpp"
#include "ptpb/surface_photons.hpp"

namespace ptpb {
namespace {

using Clock = std::chrono::steady_clock;
double seconds_since(Clock::time_point t0) {
  return std::chrono::duration<double>(Clock::now() - t0).count();
}

void validate(const RenderSettings& s) {
  auto require = [](bool ok, const std::string& what) { if (!ok) throw std::invalid_argument(what); };
  require(s.iterations > 0 || s.time_budget_s > 0, "iterations must be > 0 (or give time_budget_s > 0)");
  require(std::isfinite(s.time_budget_s) && s.time_budget_s >= 0, "time_budget_s must be >= 0");
  require(s.light_paths_per_iteration > 0 && s.light_paths_per_iteration < (1ull << 32),
          "light_paths_per_iteration must lie in [1, 2^32)");
  require(s.alpha > 0 && s.alpha <= 1, "alpha must lie in (0, 1]");
  require(std::isfinite(s.initial_beam_radius) && s.initial_beam_radius > 0, "initial_beam_radius must be > 0 (m)");
  require(std::isfinite(s.initial_time_half_width) && s.initial_time_half_width > 0,
          "initial_time_half_width must be > 0 (m of OPL)");
  require(s.parallel_guard_sin2 >= 0 && s.parallel_guard_sin2 < 1, "parallel_guard_sin2 must lie in [0, 1)");
  require(s.max_depth == -1 || s.max_depth >= 1, "max_depth must be -1 or >= 1");
  require(s.rr_depth >= 1, "rr_depth must be >= 1");
  require(s.threads >= 0, "threads must be >= 0");
  require(s.tile_size >= 1, "tile_size must be >= 1");
  require(s.snapshot_every >= 0, "snapshot_every must be >= 0");
  require(s.transmittance_cutoff > 0 && s.transmittance_cutoff < 1, "transmittance_cutoff must lie in (0, 1)");
  require(s.dice_length >= 0, "dice_length must be >= 0");
  require(std::isfinite(s.initial_surface_radius) && s.initial_surface_radius > 0,
          "initial_surface_radius must be > 0 (m)");
  require(!s.initial_surface_time_half_width ||
              (std::isfinite(*s.initial_surface_time_half_width) && *s.initial_surface_time_half_width > 0),
          "initial_surface_time_half_width must be > 0 (m of OPL)");
  require(!s.surface_alpha || (*s.surface_alpha > 0 && *s.surface_alpha <= 1), "surface_alpha must lie in (0, 1]");
  require(s.surface_normal_cos > 0 && s.surface_normal_cos <= 1, "surface_normal_cos must lie in (0, 1]");
  require(s.checkpoint_every_iterations >= 0, "checkpoint_every_iterations must be >= 0");
  require(std::isfinite(s.checkpoint_every_s) && s.checkpoint_every_s >= 0, "checkpoint_every_s must be >= 0 (s)");
  require(s.compensated_sums_from >= 0, "compensated_sums_from must be >= 0");
  require(std::isfinite(s.memory_budget_gib) && s.memory_budget_gib >= 0, "memory_budget_gib must be >= 0 (0: no limit)");
}

int film_frame_count(const Film& film) { return film.mode == FrameMode::Steady ? 0 : std::max(0, film.temporal_bins); }

std::string gib_text(double bytes) {
  char text[32];
  std::snprintf(text, sizeof text, "%.2f GiB", bytes / double(1ull << 30));
  return text;
}

RenderState fresh_state(int W, int H, int F, std::uint64_t seed) {
  RenderState st;
  st.width = W;
  st.height = H;
  st.frame_count = F;
  st.seed = seed;
  const std::size_t px3 = std::size_t(W) * H * 3;
  st.steady.assign(px3, 0.0);
  st.early.assign(px3, 0.0);
  st.late.assign(px3, 0.0);
  st.frames.assign(std::size_t(F) * px3, 0.0f);
  return st;
}

template <typename T>
bool all_finite(const std::vector<T>& v) {
  for (T x : v)
    if (!std::isfinite(x)) return false;
  return true;
}

// A resume state must belong to this film, seed and bandwidth schedule: the bandwidths of its last
// iteration are recomputed and compared bit for bit, which catches changed R_0, T_0, alpha or mode.
void validate_resume(const RenderState& st, const Scene& scene, const RenderSettings& s, int W, int H, int F) {
  auto require = [](bool ok, const std::string& what) { if (!ok) throw std::invalid_argument("resume state: " + what); };
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
  require(st.frames_carry.empty() == (st.stats.iterations_done <= s.compensated_sums_from || F == 0),
          st.frames_carry.empty() ? "it lacks the frame remainders a state past iteration " +
                                        std::to_string(s.compensated_sums_from) + " holds"
                                  : "it holds frame remainders before iteration " +
                                        std::to_string(s.compensated_sums_from));
  require(st.seed == s.seed, "it was rendered with seed " + std::to_string(st.seed) + ", the settings have seed " +
                                 std::to_string(s.seed));
  const int done = st.stats.iterations_done;
  require(done >= 0, "iterations_done must be >= 0");
  require(s.time_budget_s > 0 || done <= s.iterations,
          "it already holds " + std::to_string(done) + " iterations, more than settings.iterations = " +
              std::to_string(s.iterations));
  require(st.snapshot_iterations.size() == st.snapshots.size() && st.snapshot_seconds.size() == st.snapshots.size(),
          "its snapshot lists differ in length");
  for (const auto& snap : st.snapshots) require(snap.size() == px3, "a snapshot does not have the film's size");
  require(all_finite(st.steady) && all_finite(st.early) && all_finite(st.late) && all_finite(st.frames) &&
              all_finite(st.frames_carry),
          "its sums hold NaN or infinite values (a damaged checkpoint)");
  if (done == 0) return;
  double R, T, r_s, T_s;
  iteration_bandwidths(scene.film.mode, s, done - 1, R, T);
  surface_bandwidths(scene.film.mode, s, done - 1, r_s, T_s);
  require(R == st.stats.final_radius && T == st.stats.final_time_half_width && r_s == st.stats.final_surface_radius &&
              T_s == st.stats.final_surface_time_half_width,
          "its bandwidths after " + std::to_string(done) +
              " iterations differ from this schedule's (initial radii, time half-widths, alpha or frame mode changed)");
}

// Everything one iteration's camera pass needs, read-only.
struct CameraPass {
  const CompiledScene* cs;
  const RenderSettings* st;
  const std::vector<Beam>* beams;
  const BeamAccel* accel;
  const std::vector<SurfacePhoton>* photons;
  const SurfacePhotonGrid* photon_grid;
  std::uint64_t iteration;
  double radius, time_half_width, inv_paths;
  double surface_radius, surface_time_half_width;
  Vec3d cam_origin, cam_left, cam_up, cam_forward;
  double tan_x, tan_y, far_length;
};

// One tile's share of one iteration's film, in double (ptpb.md §9 "Memory"): planes of
// tile_size^2 pixels x 3 for steady, early, late and then frame 0 .. F-1. The tile's owner splats
// into it and then adds it to the shared sums (TileFilm::flush), which leaves it zeroed for the next
// tile. Only frames [kmin, kmax] can be non-zero.
struct TileFilm {
  int side = 0;
  std::size_t plane = 0;  // values per plane
  std::vector<double> values;
  int kmin = std::numeric_limits<int>::max(), kmax = -1;
  int x0 = 0, y0 = 0, w = 0, h = 0;  // the film pixels the tile holds now

  TileFilm(int tile_size, int frame_count)
      : side(tile_size), plane(std::size_t(tile_size) * tile_size * 3),
        values(plane * (3 + std::size_t(frame_count)), 0.0) {}
  void place(int x, int y, int width, int height) { x0 = x; y0 = y; w = width; h = height; }
  double* steady(std::size_t local) { return values.data() + 3 * local; }
  double* early(std::size_t local) { return values.data() + plane + 3 * local; }
  double* late(std::size_t local) { return values.data() + 2 * plane + 3 * local; }
  double* frame(int k, std::size_t local) {
    kmin = std::min(kmin, k);
    kmax = std::max(kmax, k);
    return values.data() + (3 + std::size_t(k)) * plane + 3 * local;
  }

  // Adds the tile's pixels to the sums and zeroes them. The double sums take a plain add; the float
  // frame sums take one rounding of (sum + value), or, with remainders, the new (sum, remainder)
  // pair of sum + remainder + value.
  void flush(RenderState& st) {
    const int W = st.width;
    const std::size_t px3 = std::size_t(W) * st.height * 3;
    double* planes[3] = {st.steady.data(), st.early.data(), st.late.data()};
    for (int q = 0; q < 3; ++q)
      for (int ly = 0; ly < h; ++ly) {
        double* src = values.data() + q * plane + std::size_t(ly) * side * 3;
        double* dst = planes[q] + (std::size_t(y0 + ly) * W + x0) * 3;
        for (int i = 0; i < 3 * w; ++i) { dst[i] += src[i]; src[i] = 0.0; }
      }
    const bool carry = !st.frames_carry.empty();
    for (int k = kmin; k <= kmax; ++k)
      for (int ly = 0; ly < h; ++ly) {
        double* src = values.data() + (3 + std::size_t(k)) * plane + std::size_t(ly) * side * 3;
        const std::size_t offset = std::size_t(k) * px3 + (std::size_t(y0 + ly) * W + x0) * 3;
        float* dst = st.frames.data() + offset;
        if (carry) {
          float* rem = st.frames_carry.data() + offset;
          for (int i = 0; i < 3 * w; ++i) {
            const double total = double(dst[i]) + double(rem[i]) + src[i];
            dst[i] = float(total);
            rem[i] = float(total - double(dst[i]));
            src[i] = 0.0;
          }
        } else {
          for (int i = 0; i < 3 * w; ++i) { dst[i] = float(double(dst[i]) + src[i]); src[i] = 0.0; }
        }
      }
    kmin = std::numeric_limits<int>::max();
    kmax = -1;
  }
};

// Tile films for the threads of a camera pass: a tile takes a free one and gives it back zeroed,
// so which film a tile gets does not change any sum.
class TileFilmPool {
 public:
  TileFilmPool(int tile_size, int frames) : tile_size_(tile_size), frames_(frames) {}
  std::unique_ptr<TileFilm> take() {
    std::lock_guard<std::mutex> lock(mutex_);
    if (free_.empty()) return std::make_unique<TileFilm>(tile_size_, frames_);
    auto film = std::move(free_.back());
    free_.pop_back();
    return film;
  }
  void give_back(std::unique_ptr<TileFilm> film) {
    std::lock_guard<std::mutex> lock(mutex_);
    free_.push_back(std::move(film));
  }

 private:
  int tile_size_, frames_;
  std::mutex mutex_;
  std::vector<std::unique_ptr<TileFilm>> free_;
};

struct PixelSplat {
  const CameraPass& p;
  TileFilm& tile;
  std::size_t local;  // the pixel's index within its tile

  // T: the temporal half-width of gate mode; beams and surfaces each pass their own T_i.
  void add(double tau, const Vec3d& v, bool timeless, double T) const {
    double* s = tile.steady(local);
    s[0] += v.x; s[1] += v.y; s[2] += v.z;
    const Film& film = p.cs->scene().film;
    if (film.mode == FrameMode::Steady || timeless) return;
    const double rel = (tau - film.start_opl) / film.bin_width_opl;
    const int F = film.temporal_bins;
    double* side = rel < 0 ? tile.early(local) : (rel >= F ? tile.late(local) : nullptr);
    if (side) { side[0] += v.x; side[1] += v.y; side[2] += v.z; }
    if (film.mode == FrameMode::Bins) {
      if (side) return;
      const int k = std::min(F - 1, static_cast<int>(std::floor(rel)));
      double* f = tile.frame(k, local);
      f[0] += v.x; f[1] += v.y; f[2] += v.z;
      return;
    }
    // Gate: every frame centre within T of tau gets the temporal kernel's weight (§5).
    const double dt = film.bin_width_opl;
    const double kmin_real = std::ceil((tau - T - film.start_opl) / dt - 0.5);
    const double kmax_real = std::floor((tau + T - film.start_opl) / dt - 0.5);
    if (kmax_real < 0 || kmin_real >= F) return;
    const int kmin = static_cast<int>(std::max(0.0, kmin_real));
    const int kmax = static_cast<int>(std::min(double(F - 1), kmax_real));
    for (int k = kmin; k <= kmax; ++k) {
      const double tk = film.start_opl + (k + 0.5) * dt;
      const double w = temporal_kernel(p.st->temporal_kernel, tk - tau, T);
      if (w == 0.0) continue;
      double* f = tile.frame(k, local);
      f[0] += w * v.x; f[1] += w * v.y; f[2] += w * v.z;
    }
  }
};

struct TileStats {
  std::uint64_t queries = 0, candidates = 0, pairs = 0, parallel = 0, false_positives = 0;
  std::uint64_t surface_queries = 0, surface_pairs = 0;

  // Integer totals: the order in which tiles add them does not matter.
  void add_to(RenderStats& s) const {
    s.queries += queries;
    s.candidates += candidates;
    s.pair_evaluations += pairs;
    s.parallel_rejected += parallel;
    s.false_positives += false_positives;
    s.surface_queries += surface_queries;
    s.surface_pairs += surface_pairs;
  }
};

// Beam×beam estimate along the query segment [0, t_q] of one camera segment (§4, §5).
void gather(const CameraPass& p, const PixelSplat& splat, const Vec3d& pos, const Vec3d& dir, double t_q,
            int medium, const Vec3d& weight, double tau_c, int depth_c, std::vector<std::uint32_t>& cand,
            TileStats& ts) {
  const Scene& scene = p.cs->scene();
  const RenderSettings& st = *p.st;
  const Medium& m = scene.media[medium];
  const Vec3d sigma_t = m.sigma_t();
  const double n = m.ior;
  cand.clear();
  p.accel->query(pos, dir, t_q, cand);
  ++ts.queries;
  // Canonical order makes the sum independent of traversal and thread count (§9): the structures
  // hand their candidates over sorted (BeamAccel::query), and only near-parallel ones can repeat.
  cand.erase(std::unique(cand.begin(), cand.end()), cand.end());
  ts.candidates += cand.size();
  const std::vector<Beam>& beams = *p.beams;
  const bool short_query = st.query_beam_kind == BeamKind::Short;
  const Vec3d query_weight = weight * m.sigma_s * p.inv_paths;
  for (std::uint32_t bi : cand) {
    const Beam& b = beams[bi];
    if (b.medium != medium) { ++ts.false_positives; continue; }
    if (st.max_depth >= 0 && b.light_depth + depth_c + 2 > st.max_depth) continue;
    const ClosestApproach ca = closest_approach(pos, dir, b.origin, b.direction);
    if (ca.sin2 < st.parallel_guard_sin2) { ++ts.parallel; continue; }
    if (!(ca.t >= 0 && ca.t <= t_q && ca.s >= 0 && ca.s <= b.length && ca.u < p.radius)) {
      ++ts.false_positives;
      continue;
    }
    const double k_r = spatial_kernel_1d(st.spatial_kernel, ca.u, p.radius);
    const double phase = hg_eval(dot(b.direction, -dir), m.g);
    // Tr(t_c) Tr(s_b) in one exponential per channel; short beams divide by their survival.
    const Vec3d tr = transmittance(sigma_t, ca.t + ca.s);
    double survival = 1.0;
    if (short_query) survival = survival_mixture(sigma_t, ca.t);
    if (b.kind == BeamKind::Short) survival *= survival_mixture(sigma_t, ca.s);
    const double scalar = k_r * phase / (std::sqrt(ca.sin2) * survival);
    const Vec3d value = query_weight * tr * b.power * scalar;
    const double tau = b.tau0 + n * ca.s + (st.camera_unwarp ? 0.0 : n * ca.t + tau_c);
    splat.add(tau, value, b.timeless, p.time_half_width);
    ++ts.pairs;
  }
}

// Surface photon estimate at a diffuse camera hit x (§7):
//   L(x, tau_f) = (1/M) sum_p k_r(|x - x_p|) K_T(tau_f - (tau_p + tau_c)) f_r Phi_p,
// with f_r = albedo/pi (Lambert, so no dependence on the photon's direction). `normal` faces the
// camera side; `weight` is the camera throughput W_c up to x and tau_c the camera OPL to x.
//
// Depth: Mitsuba's max_depth counts the segments of the emitter-to-camera path, i.e. its non-null
// interactions + 1 (§3). A photon of light depth d has met d interactions before arriving at x,
// the camera path has met d_c specular events before reaching x, and the reflection at x is one
// more interaction: d + d_c + 1 interactions, depth d + d_c + 2, the same count as a beam x query
// pair where the gather scattering plays the reflection's part. Direct light on a diffuse plane
// (d = d_c = 0) is depth 2, which Mitsuba renders at max_depth = 2 ("direct illumination").
void gather_surface(const CameraPass& p, const PixelSplat& splat, const Vec3d& x, const Vec3d& normal,
                    const Vec3d& albedo, const Vec3d& weight, double tau_c, int depth_c,
                    std::vector<std::uint32_t>& cand, TileStats& ts) {
  const RenderSettings& st = *p.st;
  p.photon_grid->query(x, cand);  // ascending photon indices: a canonical summation order (§9)
  ++ts.surface_queries;
  const Vec3d common = weight * albedo * (p.inv_paths / kPi);
  const std::vector<SurfacePhoton>& photons = *p.photons;
  for (std::uint32_t index : cand) {
    const SurfacePhoton& ph = photons[index];
    if (st.max_depth >= 0 && ph.light_depth + depth_c + 2 > st.max_depth) continue;
    const double k = surface_photon_weight(ph, x, normal, p.surface_radius, st.spatial_kernel, st.surface_normal_cos);
    if (k == 0.0) continue;
    // Unwarped: the time the light reached the surface, without the camera leg (§1).
    const double tau = ph.tau + (st.camera_unwarp ? 0.0 : tau_c);
    splat.add(tau, common * ph.power * k, ph.timeless, p.surface_time_half_width);
    ++ts.surface_pairs;
  }
}

void trace_camera_path(const CameraPass& p, TileFilm& tile, int px, int py, std::vector<std::uint32_t>& cand,
                       TileStats& ts) {
  const CompiledScene& cs = *p.cs;
  const Scene& scene = cs.scene();
  const RenderSettings& st = *p.st;
  const int W = scene.camera.width, H = scene.camera.height;
  const std::size_t pixel = std::size_t(py) * W + px;
  KeyedRng rng(st.seed, p.iteration, StreamDomain::CameraPixel, pixel);
  const double jx = st.jitter ? rng.next_double() : 0.5, jy = st.jitter ? rng.next_double() : 0.5;
  const double sx = (px + jx) / W, sy = (py + jy) / H;
  // Mitsuba's perspective sensor: +x of camera space is "left", film y points down.
  Vec3d dir = normalize(p.cam_left * ((1.0 - 2.0 * sx) * p.tan_x) + p.cam_up * ((1.0 - 2.0 * sy) * p.tan_y) +
                        p.cam_forward);
  const PixelSplat splat{p, tile, std::size_t(py - tile.y0) * tile.side + std::size_t(px - tile.x0)};
  Vec3d pos = p.cam_origin, weight{1, 1, 1};
  int medium = scene.camera.medium, depth_c = 0;
  double tau_c = 0.0;
  for (int guard = 0; guard < 100000; ++guard) {
    const SurfaceHit hit = cs.intersect(pos, dir);
    const double dist = hit.valid ? hit.t : std::numeric_limits<double>::infinity();
    if (cs.scattering(medium)) {
      const Vec3d sigma_t = scene.media[medium].sigma_t();
      double t_q;
      bool stop_inside = false;
      if (st.query_beam_kind == BeamKind::Long) {
        t_q = std::min(dist, cutoff_distance(sigma_t, st.transmittance_cutoff));
      } else {
        const int channel = std::min(2, static_cast<int>(rng.next_double() * 3.0));
        const double ts_sample = sigma_t[channel] > 0 ? -std::log1p(-rng.next_double()) / sigma_t[channel]
                                                      : std::numeric_limits<double>::infinity();
        stop_inside = ts_sample < dist;
        t_q = std::min(ts_sample, dist);
      }
      if (!std::isfinite(t_q)) t_q = p.far_length;
      if (st.max_depth < 0 || depth_c + 2 <= st.max_depth)
        gather(p, splat, pos, dir, t_q, medium, weight, tau_c, depth_c, cand, ts);
      if (stop_inside || !hit.valid) return;
      weight = weight * transmittance(sigma_t, dist);
      if (st.query_beam_kind == BeamKind::Short) weight = weight / survival_mixture(sigma_t, dist);
    } else if (cs.attenuating(medium) && hit.valid) {
      weight = weight * transmittance(scene.media[medium].sigma_t(), dist);
    }
    if (!hit.valid) {
      // Sky seen directly: no time origin, so it only enters the steady image (§1).
      if (max_component(scene.environment_radiance) > 0 && (st.max_depth < 0 || depth_c + 1 <= st.max_depth))
        splat.add(0.0, weight * scene.environment_radiance, true, p.time_half_width);
      return;
    }
    if (!(max_component(weight) > 0)) return;
    tau_c += cs.ior(medium) * dist;
    const Shape& shape = scene.shapes[hit.shape];
    if (shape.is_emitter() && hit.entering && (st.max_depth < 0 || depth_c + 1 <= st.max_depth)) {
      splat.add(st.camera_unwarp ? 0.0 : tau_c, weight * shape.radiance, false, p.time_half_width);
    }
    pos = hit.position;
    const Vec3d facing = hit.entering ? hit.normal : -hit.normal;
    if (shape.kind == SurfaceKind::Null) {
      medium = hit.medium_after;
      continue;
    }
    if (shape.kind == SurfaceKind::Diffuse) {
      // The camera path ends here (§7); depth d_c + 2 is the shallowest path a photon can close.
      if (max_component(shape.albedo) > 0 && p.photon_grid->size() > 0 &&
          (st.max_depth < 0 || depth_c + 2 <= st.max_depth))
        gather_surface(p, splat, pos, facing, shape.albedo, weight, tau_c, depth_c, cand, ts);
      return;
    }
    ++depth_c;
    if (st.max_depth >= 0 && depth_c + 1 > st.max_depth) return;
    const double n_i = cs.ior(medium), n_t = cs.ior(hit.medium_after);
    const FresnelResult fr = fresnel_dielectric(-dot(dir, facing), n_i, n_t);
    if (rng.next_double() < fr.reflectance) {
      dir = normalize(reflect(dir, facing));
    } else {
      dir = refract(dir, facing, n_i, n_t, fr.cos_t);
      weight = weight * ((n_i / n_t) * (n_i / n_t));  // radiance scaling at refraction (§3)
      medium = hit.medium_after;
    }
    if (depth_c >= st.rr_depth) {
      const double q = std::min(kMaxSurvival, max_component(weight));
      if (!(rng.next_double() < q)) return;
      weight = weight / q;
    }
  }
}

}  // namespace

void iteration_bandwidths(FrameMode mode, const RenderSettings& s, long iteration, double& radius,
                          double& time_half_width) {
  const double gamma = schedule_gamma(iteration, s.alpha);
  if (mode == FrameMode::Gate) {
    radius = s.initial_beam_radius * std::sqrt(gamma);
    time_half_width = s.initial_time_half_width * std::sqrt(gamma);
  } else {
    radius = s.initial_beam_radius * gamma;
    time_half_width = s.initial_time_half_width;
  }
}

double surface_schedule_alpha(FrameMode mode, const RenderSettings& s) {
  if (s.surface_alpha) return *s.surface_alpha;
  return mode == FrameMode::Gate ? 4.0 / 7.0 : 2.0 / 3.0;
}

void surface_bandwidths(FrameMode mode, const RenderSettings& s, long iteration, double& radius,
                        double& time_half_width) {
  const double gamma = schedule_gamma(iteration, surface_schedule_alpha(mode, s));
  const double t0 = s.initial_surface_time_half_width.value_or(s.initial_time_half_width);
  if (mode == FrameMode::Gate) {
    const double shrink = std::cbrt(gamma);
    radius = s.initial_surface_radius * shrink;
    time_half_width = t0 * shrink;
  } else {
    radius = s.initial_surface_radius * std::sqrt(gamma);
    time_half_width = t0;
  }
}

bool uses_frame_remainders(const RenderSettings& s) {
  return s.time_budget_s > 0 || s.iterations > s.compensated_sums_from;
}

double render_memory_bytes(const Scene& scene, const RenderSettings& s, bool state_copy) {
  const double px3 = double(std::max(0, scene.camera.width)) * double(std::max(0, scene.camera.height)) * 3.0;
  const double F = film_frame_count(scene.film);
  const double snapshots = s.snapshot_every > 0 && s.time_budget_s <= 0 ? double(s.iterations / s.snapshot_every) : 0.0;
  const double snapshot_bytes = snapshots * px3 * sizeof(float);
  // Double sums of steady, early, late and their float32 results; float32 frame sums (scaled in
  // place into the result), with as many remainders in a long run; a double tile film per thread.
  const double planes = 3.0 * px3 * (sizeof(double) + sizeof(float));
  const double frames = F * px3 * sizeof(float) * (uses_frame_remainders(s) ? 2.0 : 1.0);
  const double tiles = double(resolve_thread_count(s.threads)) * double(s.tile_size) * s.tile_size * 3.0 * (3.0 + F) *
                       sizeof(double);
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
      " px, summed in float32), more than render.memory_budget_gib = " + budget +
      "; lower scene.film.temporal_bins or scene.camera.width/height, or raise render.memory_budget_gib "
      "(frames are not split into chunks: every pair splats into all its frames in one pass)");
}

RenderResult render(const Scene& scene, const RenderSettings& settings, const ProgressCallback& progress,
                    std::optional<RenderState> resume, const CheckpointCallback& checkpoint) {
  validate(settings);
  check_memory_budget(scene, settings, resume.has_value() || (checkpoint && (settings.checkpoint_every_iterations > 0 ||
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
  RenderState state = resume ? std::move(*resume) : fresh_state(W, H, F, settings.seed);
  resume.reset();
  RenderStats& stats = state.stats;
  stats.cancelled = false;
  const double time_before = stats.time_total_s;  // render time of the runs this one continues
  auto elapsed = [&] { return time_before + seconds_since(t_start); };

  CameraPass pass{};
  pass.cs = &cs;
  pass.st = &settings;
  // Mitsuba's look_at frame: columns (left, up, forward).
  pass.cam_forward = normalize(cam.target - cam.origin);
  pass.cam_left = normalize(cross(cam.up, pass.cam_forward));
  pass.cam_up = cross(pass.cam_forward, pass.cam_left);
  pass.cam_origin = cam.origin;
  const double aspect = double(W) / H;
  const double tan_half = std::tan(cam.fov_deg * kPi / 360.0);
  std::string axis = cam.fov_axis;
  if (axis == "smaller") axis = W <= H ? "x" : "y";
  if (axis == "larger") axis = W >= H ? "x" : "y";
  if (axis == "x") pass.tan_x = tan_half;
  else if (axis == "y") pass.tan_x = tan_half * aspect;
  else pass.tan_x = tan_half * aspect / std::sqrt(1.0 + aspect * aspect);
  pass.tan_y = pass.tan_x / aspect;
  pass.far_length = 4.0 * cs.sphere_radius() + length(cam.origin - cs.sphere_center());
  pass.inv_paths = 1.0 / double(settings.light_paths_per_iteration);
  TileFilmPool tile_films(settings.tile_size, F);

  auto accel = make_beam_accel(settings.accel, settings.grid_resolution, settings.dice_length);
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
  constexpr std::size_t kPathChunk = 256;
  constexpr int kChunksPerThread = 16;  // light-path chunks per thread in one group

  auto report = [&](int done, double R, double T, std::uint64_t nbeams, double r_s, std::uint64_t nphotons) {
    if (!progress) return;
    Progress pr{done, settings.time_budget_s > 0 ? -1 : settings.iterations, elapsed(), R, T, nbeams, r_s, nphotons};
    last_report = Clock::now();
    if (!progress(pr)) cancel.store(true);
  };

  std::vector<Beam> beams;
  std::vector<SurfacePhoton> photons;
  SurfacePhotonGrid photon_grid;
  for (long it = stats.iterations_done; it < max_iterations && !cancel.load(); ++it) {
    if (settings.time_budget_s > 0 && it > 0 && elapsed() >= settings.time_budget_s) break;
    double R, T;
    iteration_bandwidths(film.mode, settings, it, R, T);
    if (film.mode == FrameMode::Gate) T = std::max(T, 0.0);
    double r_s, T_s;
    surface_bandwidths(film.mode, settings, it, r_s, T_s);

    // 1. Light paths, in fixed chunks of path indices; beams and photons kept in path order (§9).
    auto t0 = Clock::now();
    // Traced a group of chunks at a time and appended in chunk order, so that at most one group's
    // records exist twice (ptpb.md §9 "Memory").
    const std::size_t path_chunks = (M + kPathChunk - 1) / kPathChunk;
    const std::size_t group = std::size_t(kChunksPerThread) * resolve_thread_count(settings.threads);
    beams.clear();
    photons.clear();
    for (std::size_t g0 = 0; g0 < path_chunks; g0 += group) {
      const std::size_t g1 = std::min(path_chunks, g0 + group);
      std::vector<LightRecords> chunk_records(g1 - g0);
      parallel_for_chunks(g1 - g0, 1, settings.threads, [&](std::size_t c0, std::size_t c1) {
        for (std::size_t c = c0; c < c1; ++c) {
          const std::uint64_t end = std::min<std::uint64_t>(M, (g0 + c + 1) * kPathChunk);
          for (std::uint64_t j = (g0 + c) * kPathChunk; j < end; ++j)
            trace_light_path(cs, settings, it, j, chunk_records[c]);
        }
      });
      if (g0 == 0 && beams.capacity() == 0) {
        // Room for the whole iteration at the first group's rate, with a margin: capacity that is
        // never written costs address space, not memory, while a vector grown by doubling leaves
        // freed buffers behind (16 frames with 400k paths: peak 50 MiB with this, 56 MiB without).
        std::size_t first_beams = 0, first_photons = 0;
        for (const auto& rec : chunk_records) {
          first_beams += rec.beams.size();
          first_photons += rec.photons.size();
        }
        const double scale = 1.25 * double(M) / double(std::min<std::uint64_t>(M, g1 * kPathChunk));
        beams.reserve(std::size_t(scale * double(first_beams)) + 1024);
        photons.reserve(std::size_t(scale * double(first_photons)) + 1024);
      }
      for (auto& rec : chunk_records) {
        beams.insert(beams.end(), rec.beams.begin(), rec.beams.end());
        photons.insert(photons.end(), rec.photons.begin(), rec.photons.end());
        std::vector<Beam>().swap(rec.beams);
        std::vector<SurfacePhoton>().swap(rec.photons);
      }
    }
    // Beams in space order (a deterministic function of the path-ordered beams): the structure's
    // leaves and the gather then read neighbouring records.
    sort_beams_spatially(beams, settings.threads);
    stats.time_light_s += seconds_since(t0);

    // 2. The beam structure, with this iteration's radius.
    t0 = Clock::now();
    accel->build(beams, R, settings.threads);
    stats.time_build_s += seconds_since(t0);
    t0 = Clock::now();
    photon_grid.build(photons, r_s);
    stats.time_surface_build_s += seconds_since(t0);

    // 3. Camera pass by tiles; each tile owns its pixels.
    t0 = Clock::now();
    if (it >= settings.compensated_sums_from && F > 0 && state.frames_carry.empty()) state.frames_carry.assign(frame_values, 0.0f);
    pass.beams = &beams;
    pass.accel = accel.get();
    pass.iteration = static_cast<std::uint64_t>(it);
    pass.radius = accel->radius();
    pass.time_half_width = T;
    pass.photons = &photons;
    pass.photon_grid = &photon_grid;
    pass.surface_radius = photon_grid.radius();
    pass.surface_time_half_width = T_s;
    // Tiles add straight into the sums, so a pass is never left half done: a cancel that arrives
    // during it takes effect after it (ptpb.md §9; the iteration is kept, not dropped).
    parallel_for_chunks(std::size_t(tiles_x) * tiles_y, 1, settings.threads, [&](std::size_t t_begin, std::size_t t_end) {
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
          report(int(it), R, T, beams.size(), r_s, photons.size());
      }
      tile_films.give_back(std::move(tile));
    });
    stats.time_camera_s += seconds_since(t0);
    stats.iterations_done = int(it + 1);
    stats.light_paths += M;
    stats.beams += beams.size();
    stats.accel_references += accel->references();
    stats.final_radius = R;
    stats.final_time_half_width = T;
    stats.surface_photons += photons.size();
    stats.final_surface_radius = photon_grid.radius();
    stats.final_surface_time_half_width = T_s;
    if (settings.snapshot_every > 0 && (it + 1) % settings.snapshot_every == 0) {
      std::vector<float> snap(state.steady.size());
      for (std::size_t i = 0; i < snap.size(); ++i) snap[i] = float(state.steady[i] / double(it + 1));
      state.snapshots.push_back(std::move(snap));
      state.snapshot_iterations.push_back(int(it + 1));
      state.snapshot_seconds.push_back(elapsed());
    }
    report(int(it + 1), R, T, beams.size(), r_s, photons.size());
    // No checkpoint after the last planned iteration: the result itself follows at once.
    const bool due = (settings.checkpoint_every_iterations > 0 && (it + 1) % settings.checkpoint_every_iterations == 0) ||
                     (settings.checkpoint_every_s > 0 && seconds_since(last_checkpoint) >= settings.checkpoint_every_s);
    if (checkpointing && due && it + 1 < max_iterations && !cancel.load() && !save_checkpoint()) cancel.store(true);
  }

  // A cancelled run keeps its completed iterations for a later resume.
  if (checkpointing && cancel.load() && stats.iterations_done > checkpointed_iterations) save_checkpoint();
  stats.cancelled = cancel.load();
  RenderResult result;
  result.width = W;
  result.height = H;
  result.frame_count = F;
  const double inv_n = stats.iterations_done > 0 ? 1.0 / stats.iterations_done : 0.0;
  auto to_float = [&](const std::vector<double>& src, std::vector<float>& dst, double* total) {
    dst.resize(src.size());
    double sum = 0.0;
    for (std::size_t i = 0; i < src.size(); ++i) { dst[i] = float(src[i] * inv_n); sum += src[i] * inv_n; }
    if (total) *total = sum;
  };
  to_float(state.steady, result.steady, &stats.steady_total);
  to_float(state.early, result.early, &stats.early_total);
  to_float(state.late, result.late, &stats.late_total);
  // The frame sums become the averages in place: no second film at the end.
  result.frames = std::move(state.frames);
  if (state.frames_carry.empty()) {
    for (float& f : result.frames) f = float(double(f) * inv_n);
  } else {
    for (std::size_t i = 0; i < result.frames.size(); ++i)
      result.frames[i] = float((double(result.frames[i]) + double(state.frames_carry[i])) * inv_n);
    std::vector<float>().swap(state.frames_carry);
  }
  stats.time_total_s = elapsed();
  result.stats = stats;
  result.snapshot_iterations = std::move(state.snapshot_iterations);
  result.snapshot_seconds = std::move(state.snapshot_seconds);
  result.snapshots = std::move(state.snapshots);
  return result;
}

}  // namespace ptpb
