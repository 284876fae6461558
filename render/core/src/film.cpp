// The film (DESIGN.md §5, §9): sums, tile buffers and the averages a render returns.
#include "ptpb/film.hpp"

#include <utility>

namespace ptpb {

RenderState empty_state(int W, int H, int F, const RenderSettings& settings) {
  RenderState st;
  st.width = W;
  st.height = H;
  st.frame_count = F;
  st.seed = settings.seed;
  st.stats.iterations_done = settings.first_iteration;
  const std::size_t px3 = std::size_t(W) * H * 3;
  st.steady.assign(px3, 0.0);
  st.early.assign(px3, 0.0);
  st.late.assign(px3, 0.0);
  if (settings.keep_sums)
    st.frames_double.assign(std::size_t(F) * px3, 0.0);
  else
    st.frames.assign(std::size_t(F) * px3, 0.0f);
  return st;
}

void add_snapshot(RenderState& state, long iterations, double seconds) {
  std::vector<float> snap(state.steady.size());
  for (std::size_t i = 0; i < snap.size(); ++i) snap[i] = float(state.steady[i] / double(iterations));
  state.snapshots.push_back(std::move(snap));
  state.snapshot_iterations.push_back(int(iterations));
  state.snapshot_seconds.push_back(seconds);
}

RenderResult average_state(RenderState& state) {
  RenderStats& stats = state.stats;
  RenderResult result;
  result.width = state.width;
  result.height = state.height;
  result.frame_count = state.frame_count;
  const double inv_n = stats.iterations_done > 0 ? 1.0 / stats.iterations_done : 0.0;
  auto to_float = [&](const std::vector<double>& src, std::vector<float>& dst, double* total) {
    dst.resize(src.size());
    double sum = 0.0;
    for (std::size_t i = 0; i < src.size(); ++i) {
      dst[i] = float(src[i] * inv_n);
      sum += src[i] * inv_n;
    }
    if (total) *total = sum;
  };
  to_float(state.steady, result.steady, &stats.steady_total);
  to_float(state.early, result.early, &stats.early_total);
  to_float(state.late, result.late, &stats.late_total);
  result.frames = std::move(state.frames);
  if (state.frames_carry.empty()) {
    for (float& f : result.frames) f = float(double(f) * inv_n);
  } else {
    for (std::size_t i = 0; i < result.frames.size(); ++i)
      result.frames[i] = float((double(result.frames[i]) + double(state.frames_carry[i])) * inv_n);
    std::vector<float>().swap(state.frames_carry);
  }
  result.stats = stats;
  result.snapshot_iterations = std::move(state.snapshot_iterations);
  result.snapshot_seconds = std::move(state.snapshot_seconds);
  result.snapshots = std::move(state.snapshots);
  return result;
}

RenderResult sum_state(RenderState& state) {
  RenderResult result;
  result.width = state.width;
  result.height = state.height;
  result.frame_count = state.frame_count;
  auto total = [](const std::vector<double>& v) {
    double sum = 0.0;
    for (double x : v) sum += x;
    return sum;
  };
  state.stats.steady_total = total(state.steady);
  state.stats.early_total = total(state.early);
  state.stats.late_total = total(state.late);
  result.steady_sum = std::move(state.steady);
  result.early_sum = std::move(state.early);
  result.late_sum = std::move(state.late);
  result.frames_sum = std::move(state.frames_double);
  result.stats = state.stats;
  return result;
}

void TileFilm::flush(RenderState& st) {
  const int W = st.width;
  const std::size_t px3 = std::size_t(W) * st.height * 3;
  double* planes[3] = {st.steady.data(), st.early.data(), st.late.data()};
  for (int q = 0; q < 3; ++q)
    for (int ly = 0; ly < h; ++ly) {
      double* src = values.data() + q * plane + std::size_t(ly) * side * 3;
      double* dst = planes[q] + (std::size_t(y0 + ly) * W + x0) * 3;
      for (int i = 0; i < 3 * w; ++i) {
        dst[i] += src[i];
        src[i] = 0.0;
      }
    }
  const bool carry = !st.frames_carry.empty();
  const bool in_double = !st.frames_double.empty();
  for (int k = kmin; k <= kmax; ++k)
    for (int ly = 0; ly < h; ++ly) {
      double* src = values.data() + (3 + std::size_t(k)) * plane + std::size_t(ly) * side * 3;
      const std::size_t offset = std::size_t(k) * px3 + (std::size_t(y0 + ly) * W + x0) * 3;
      if (in_double) {
        double* dst = st.frames_double.data() + offset;
        for (int i = 0; i < 3 * w; ++i) {
          dst[i] += src[i];
          src[i] = 0.0;
        }
        continue;
      }
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
        for (int i = 0; i < 3 * w; ++i) {
          dst[i] = float(double(dst[i]) + src[i]);
          src[i] = 0.0;
        }
      }
    }
  kmin = std::numeric_limits<int>::max();
  kmax = -1;
}

std::unique_ptr<TileFilm> TileFilmPool::take() {
  std::lock_guard<std::mutex> lock(mutex_);
  if (free_.empty()) return std::make_unique<TileFilm>(tile_size_, frames_);
  auto film = std::move(free_.back());
  free_.pop_back();
  return film;
}

void TileFilmPool::give_back(std::unique_ptr<TileFilm> film) {
  std::lock_guard<std::mutex> lock(mutex_);
  free_.push_back(std::move(film));
}

}  // namespace ptpb
