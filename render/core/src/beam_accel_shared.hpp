// The beam structures' shared parts (DESIGN.md §8): what the grid (beam_grid.cpp) and the BVH
// (beam_bvh.cpp) both use, and their factories, which make_beam_accel (beam_accel.cpp) calls.
// Private to the core's sources.
//
// Uniform grid and 4-wide BVH (built by Embree's BVH builder, traversed here) over diced,
// R-inflated beam pieces.
//
// Both run the gather's exact closest-approach test (DESIGN.md §4) themselves, in a division-free
// form that is looser than the gather's, and report each beam once: from the pieces that own the
// beam parameter s_b of the closest approach (BVH; repeats dropped after the sort), or from the
// grid cell that owns the query parameter t_b (grid). The gather's own test then decides exactly as
// before, so images do not change, while candidates that could never pass (box corners, repeated
// pieces) cost neither a push nor a place in the gather's sort. Near-parallel candidates are always
// reported, so that the gather still counts them in its parallel statistic.
#pragma once
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <memory>
#include <utility>
#include <vector>

#include "ptpb/beam_accel.hpp"

namespace ptpb::accel_detail {

inline constexpr double kInf = std::numeric_limits<double>::infinity();
// Candidates with sin^2 below this reach the gather untested: its parallel guard (default 1e-5)
// counts them there.
inline constexpr double kParallelKeepSin2 = 1e-4;
// Boxes grow by this fraction of the scene scale beyond R: it covers the float rounding of the
// boxes, of Embree's float ray and of the piece boundaries, so a pair within R is never missed.
inline constexpr double kBoxMargin = 4e-6;

struct Box {
  Vec3d lo{1e300, 1e300, 1e300}, hi{-1e300, -1e300, -1e300};
  void expand(const Vec3d& p) {
    for (int a = 0; a < 3; ++a) {
      lo[a] = std::min(lo[a], p[a]);
      hi[a] = std::max(hi[a], p[a]);
    }
  }
};

inline Box beams_bounds(const std::vector<Beam>& beams) {
  Box b;
  for (const Beam& beam : beams) {
    b.expand(beam.origin);
    b.expand(beam.origin + beam.direction * beam.length);
  }
  return b;
}

// A length that bounds every coordinate and distance of the beams' box.
inline double scene_scale(const Box& b) {
  double s = max_component(b.hi - b.lo);
  for (int a = 0; a < 3; ++a) s = std::max(s, std::max(std::fabs(b.lo[a]), std::fabs(b.hi[a])));
  return std::max(s, 1e-300);
}

// costs less than a comparison sort.
inline void sort_candidates(std::vector<std::uint32_t>& out, std::size_t from) {
  const std::size_t n = out.size() - from;
  if (n < 2) return;
  std::uint32_t* a = out.data() + from;
  if (n <= 32) {
    for (std::size_t i = 1; i < n; ++i)
      for (std::size_t j = i; j > 0 && a[j - 1] > a[j]; --j) std::swap(a[j - 1], a[j]);
    return;
  }
  std::uint32_t used_bits = 0;
  for (std::size_t i = 0; i < n; ++i) used_bits |= a[i];
  thread_local std::vector<std::uint32_t> scratch;
  scratch.resize(n);
  std::uint32_t* src = a;
  std::uint32_t* dst = scratch.data();
  for (int shift = 0; shift < 32 && (used_bits >> shift) != 0; shift += 8) {
    std::size_t count[257] = {};
    for (std::size_t i = 0; i < n; ++i) ++count[((src[i] >> shift) & 0xFFu) + 1];
    for (int b = 0; b < 256; ++b) count[b + 1] += count[b];
    for (std::size_t i = 0; i < n; ++i) dst[count[(src[i] >> shift) & 0xFFu]++] = src[i];
    std::swap(src, dst);
  }
  if (src != a) std::copy(src, src + n, a);
}

inline constexpr std::size_t kBuildChunk = 2048;

// grid_resolution: cells along the longest axis (beam_grid.cpp).
std::unique_ptr<BeamAccel> make_beam_grid(int grid_resolution);
// dice_length: piece length, 0 = automatic (beam_bvh.cpp).
std::unique_ptr<BeamAccel> make_beam_bvh(double dice_length);

}  // namespace ptpb::accel_detail
