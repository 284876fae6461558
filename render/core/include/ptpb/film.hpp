// The film (DESIGN.md §5, §9): the sums a render accumulates, the tile buffers the threads splat
// into, the splat of one estimate into the steady image, early, late and the frames its time
// covers, and the averages a render returns.
#pragma once
#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <limits>
#include <memory>
#include <mutex>
#include <vector>

#include "ptpb/kernels.hpp"
#include "ptpb/render.hpp"
#include "ptpb/scene.hpp"
#include "ptpb/settings.hpp"
#include "ptpb/vec.hpp"

namespace ptpb {

// Frames a film (or its window) holds: none in steady mode.
inline int film_frame_count(const Film& film) {
  if (film.mode == FrameMode::Steady) return 0;
  const int rest = std::max(0, film.temporal_bins - std::max(0, film.window_first));
  return film.window_count < 0 ? rest : std::min(rest, film.window_count);
}

// The zeroed sums of a render that has not started: at settings.first_iteration (a shard), with the
// frame sums in double under settings.keep_sums.
RenderState empty_state(int W, int H, int F, const RenderSettings& settings);

// Keeps the steady average after `iterations` iterations, taken `seconds` into the render.
void add_snapshot(RenderState& state, long iterations, double seconds);

// The averages of the state's sums, with their totals in stats (for the window check). The frame
// sums become the averages in place, so the state gives up its buffers: no second film at the end.
RenderResult average_state(RenderState& state);

// The state's double sums, undivided, for a shard's merge (settings.keep_sums); the state gives them up.
RenderResult sum_state(RenderState& state);

// One tile's share of one iteration's film, in double (DESIGN.md §9 "Memory"): planes of
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
      : side(tile_size),
        plane(std::size_t(tile_size) * tile_size * 3),
        values(plane * (3 + std::size_t(frame_count)), 0.0) {}
  void place(int x, int y, int width, int height) {
    x0 = x;
    y0 = y;
    w = width;
    h = height;
  }
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
  void flush(RenderState& st);
};

// Tile films for the threads of a camera pass: a tile takes a free one and gives it back zeroed,
// so which film a tile gets does not change any sum.
class TileFilmPool {
 public:
  TileFilmPool(int tile_size, int frames) : tile_size_(tile_size), frames_(frames) {}
  std::unique_ptr<TileFilm> take();
  void give_back(std::unique_ptr<TileFilm> film);

 private:
  int tile_size_, frames_;
  std::mutex mutex_;
  std::vector<std::unique_ptr<TileFilm>> free_;
};

// Splats the estimates of one pixel into its tile.
struct PixelSplat {
  const Film& film;
  TemporalKernel kernel;  // the temporal kernel of gate mode
  TileFilm& tile;
  std::size_t local;  // the pixel's index within its tile

  // T: the temporal half-width of gate mode; beams and surfaces each pass their own T_i.
  void add(double tau, const Vec3d& v, bool timeless, double T) const {
    double* s = tile.steady(local);
    s[0] += v.x;
    s[1] += v.y;
    s[2] += v.z;
    if (film.mode == FrameMode::Steady || timeless) return;
    const double rel = (tau - film.start_opl) / film.bin_width_opl;
    const int F = film.temporal_bins;  // early and late are outside the whole film, not the window
    const int first = film.window_first, end = first + film_frame_count(film);
    double* side = rel < 0 ? tile.early(local) : (rel >= F ? tile.late(local) : nullptr);
    if (side) {
      side[0] += v.x;
      side[1] += v.y;
      side[2] += v.z;
    }
    if (film.mode == FrameMode::Bins) {
      if (side) return;
      const int k = std::min(F - 1, static_cast<int>(std::floor(rel)));
      if (k < first || k >= end) return;
      double* f = tile.frame(k - first, local);
      f[0] += v.x;
      f[1] += v.y;
      f[2] += v.z;
      return;
    }
    // Gate: every frame centre within T of tau gets the temporal kernel's weight (§5).
    const double dt = film.bin_width_opl;
    const double kmin_real = std::ceil((tau - T - film.start_opl) / dt - 0.5);
    const double kmax_real = std::floor((tau + T - film.start_opl) / dt - 0.5);
    if (kmax_real < first || kmin_real >= end) return;
    const int kmin = static_cast<int>(std::max(double(first), kmin_real));
    const int kmax = static_cast<int>(std::min(double(end - 1), kmax_real));
    for (int k = kmin; k <= kmax; ++k) {
      const double tk = film.start_opl + (k + 0.5) * dt;
      const double w = temporal_kernel(kernel, tk - tau, T);
      if (w == 0.0) continue;
      double* f = tile.frame(k - first, local);
      f[0] += w * v.x;
      f[1] += w * v.y;
      f[2] += w * v.z;
    }
  }
};

}  // namespace ptpb
