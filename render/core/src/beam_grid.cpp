// Uniform grid of diced, R-inflated beam pieces (SmallUPBP style), tested in double (DESIGN.md §8).
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <memory>
#include <stdexcept>
#include <utility>
#include <vector>

#include "beam_accel_shared.hpp"
#include "ptpb/beam_geometry.hpp"
#include "ptpb/parallel.hpp"

namespace ptpb::accel_detail {
namespace {

// The grid's exact test accepts t and s this fraction of the scene scale outside their ranges, and u
// up to R (1 + 1e-9): far above rounding, so the gather never sees fewer pairs than its own test
// accepts. (The BVH's float test has its own margin, kCandidateSlack.)
constexpr double kRangeSlack = 1e-9;

// Segment–box slab test on [t0, t1]; narrows t0/t1 to the overlap.
bool clip_to_box(const Vec3d& o, const Vec3d& d, const Vec3d& lo, const Vec3d& hi, double& t0, double& t1) {
  for (int a = 0; a < 3; ++a) {
    if (d[a] == 0.0) {
      if (o[a] < lo[a] || o[a] > hi[a]) return false;
      continue;
    }
    const double inv = 1.0 / d[a];
    double ta = (lo[a] - o[a]) * inv, tb = (hi[a] - o[a]) * inv;
    if (ta > tb) std::swap(ta, tb);
    t0 = std::max(t0, ta);
    t1 = std::min(t1, tb);
    if (t0 > t1) return false;
  }
  return true;
}

// One query segment as the exact test reads it: accepted t range and R^2, slack included.
struct PairQuery {
  Vec3d origin, direction;
  double t_lo, t_hi, radius2;
};

PairQuery make_pair_query(const Vec3d& o, const Vec3d& d, double t_max, double radius, double slack) {
  const double r = radius * (1.0 + 1e-9);
  return {o, d, -slack, t_max + slack, r * r};
}

// The gather's test of §4 without divisions: near-parallel, or t_b in range and u_b < R. On true,
// `n` holds the numerators for the caller's ownership test on s_b or t_b.
bool pair_candidate(const PairQuery& q, const Vec3d& xb, const Vec3d& wb, ApproachNumerators& n, bool& parallel) {
  n = closest_approach_numerators(q.origin, q.direction, xb, wb);
  parallel = n.sin2 < kParallelKeepSin2;
  if (parallel) return true;
  return n.t_num >= q.t_lo * n.sin2 && n.t_num <= q.t_hi * n.sin2 && n.w_cross * n.w_cross < q.radius2 * n.sin2;
}

// Sorts out[from, end) ascending: the canonical summation order of DESIGN.md §9, on which the gather
// relies, and sequential beam reads there. An LSD radix sort over the bits the beam indices use
// The beam's line in double precision, as the exact test reads it.
struct BeamLine {
  Vec3d origin, direction;
  double length;
};

class BeamGrid final : public BeamAccel {
 public:
  explicit BeamGrid(int resolution) : resolution_(resolution) {
    if (resolution < 1 || resolution > 1024) throw std::invalid_argument("grid_resolution must lie in [1, 1024]");
  }

  void build(const std::vector<Beam>& beams, double radius, int threads) override {
    radius_ = radius;
    offsets_.clear();
    refs_.clear();
    lines_.clear();
    if (beams.empty()) return;
    const Box bounds = beams_bounds(beams);
    const double scale = scene_scale(bounds);
    slack_ = kRangeSlack * scale;
    const double inflate = radius + kBoxMargin * scale;
    const Vec3d r{inflate, inflate, inflate};
    lo_ = bounds.lo - r;
    const Vec3d extent = bounds.hi + r - lo_;
    cell_ = max_component(extent) / resolution_;
    for (int a = 0; a < 3; ++a) dims_[a] = std::clamp(static_cast<int>(std::ceil(extent[a] / cell_)), 1, resolution_);
    lines_.resize(beams.size());
    for (std::size_t i = 0; i < beams.size(); ++i) lines_[i] = {beams[i].origin, beams[i].direction, beams[i].length};
    const std::size_t cell_count = std::size_t(dims_[0]) * dims_[1] * dims_[2];
    const std::size_t chunks = (beams.size() + kBuildChunk - 1) / kBuildChunk;
    std::vector<std::vector<std::uint64_t>> chunk_refs(chunks);  // (cell << 32) | beam
    parallel_for_chunks(chunks, 1, threads, [&](std::size_t c0, std::size_t c1) {
      std::vector<std::uint32_t> cells;
      for (std::size_t c = c0; c < c1; ++c) {
        auto& out = chunk_refs[c];
        const std::size_t b_end = std::min(beams.size(), (c + 1) * kBuildChunk);
        for (std::size_t bi = c * kBuildChunk; bi < b_end; ++bi) {
          const Beam& b = beams[bi];
          const int pieces = std::clamp(static_cast<int>(std::ceil(b.length / cell_)), 1, 4 * resolution_);
          cells.clear();
          for (int k = 0; k < pieces; ++k) {
            const Vec3d p0 = b.origin + b.direction * (b.length * k / pieces);
            const Vec3d p1 = b.origin + b.direction * (b.length * (k + 1) / pieces);
            int i0[3], i1[3];
            for (int a = 0; a < 3; ++a) {
              i0[a] = cell_index(std::min(p0[a], p1[a]) - inflate, a);
              i1[a] = cell_index(std::max(p0[a], p1[a]) + inflate, a);
            }
            for (int z = i0[2]; z <= i1[2]; ++z)
              for (int y = i0[1]; y <= i1[1]; ++y)
                for (int x = i0[0]; x <= i1[0]; ++x)
                  cells.push_back(static_cast<std::uint32_t>((std::size_t(z) * dims_[1] + y) * dims_[0] + x));
          }
          std::sort(cells.begin(), cells.end());
          cells.erase(std::unique(cells.begin(), cells.end()), cells.end());
          for (std::uint32_t cell : cells) out.push_back((std::uint64_t(cell) << 32) | std::uint32_t(bi));
        }
      }
    });
    // Count-then-fill CSR in chunk order: deterministic for any thread count.
    offsets_.assign(cell_count + 1, 0);
    for (const auto& refs : chunk_refs)
      for (std::uint64_t r : refs) ++offsets_[(r >> 32) + 1];
    for (std::size_t i = 0; i < cell_count; ++i) offsets_[i + 1] += offsets_[i];
    refs_.resize(offsets_[cell_count]);
    std::vector<std::uint32_t> cursor(offsets_.begin(), offsets_.end() - 1);
    for (const auto& refs : chunk_refs)
      for (std::uint64_t r : refs) refs_[cursor[r >> 32]++] = static_cast<std::uint32_t>(r);
  }

  // 3D-DDA along the query; a beam is reported by the cell whose t-range holds its t_b (SmallUPBP).
  void query(const Vec3d& o, const Vec3d& d, double t_max, std::vector<std::uint32_t>& out) const override {
    if (refs_.empty()) return;
    const PairQuery q = make_pair_query(o, d, t_max, radius_, slack_);
    const std::size_t first = out.size();
    double t0 = 0.0, t1 = t_max;
    const Vec3d hi = lo_ + Vec3d{dims_[0] * cell_, dims_[1] * cell_, dims_[2] * cell_};
    if (!clip_to_box(o, d, lo_, hi, t0, t1)) return;
    const Vec3d p = o + d * t0;
    int idx[3], step[3];
    double t_next[3], t_delta[3];
    for (int a = 0; a < 3; ++a) {
      idx[a] = cell_index(p[a], a);
      step[a] = d[a] >= 0 ? 1 : -1;
      if (d[a] != 0.0) {
        const double boundary = lo_[a] + (idx[a] + (step[a] > 0 ? 1 : 0)) * cell_;
        t_next[a] = t0 + (boundary - p[a]) / d[a];
        t_delta[a] = cell_ / std::fabs(d[a]);
      } else {
        t_next[a] = t_delta[a] = kInf;
      }
    }
    double t_enter = -kInf;  // the first and last cells own everything before and after them
    for (;;) {
      const int a = t_next[0] < t_next[1] ? (t_next[0] < t_next[2] ? 0 : 2) : (t_next[1] < t_next[2] ? 1 : 2);
      const bool last = t_next[a] > t1 || idx[a] + step[a] < 0 || idx[a] + step[a] >= dims_[a];
      const double t_exit = last ? kInf : t_next[a];
      const std::size_t cell = (std::size_t(idx[2]) * dims_[1] + idx[1]) * dims_[0] + idx[0];
      for (std::uint32_t r = offsets_[cell]; r < offsets_[cell + 1]; ++r) {
        const std::uint32_t bi = refs_[r];
        const BeamLine& line = lines_[bi];
        ApproachNumerators n;
        bool parallel;
        if (!pair_candidate(q, line.origin, line.direction, n, parallel)) continue;
        if (!parallel && !(n.t_num >= t_enter * n.sin2 && n.t_num < t_exit * n.sin2 && n.s_num >= -slack_ * n.sin2 &&
                           n.s_num <= (line.length + slack_) * n.sin2))
          continue;
        out.push_back(bi);
      }
      if (last) break;
      t_enter = t_exit;
      idx[a] += step[a];
      t_next[a] += t_delta[a];
    }
    sort_candidates(out, first);
  }

  std::uint64_t references() const override { return refs_.size(); }
  double radius() const override { return radius_; }

 private:
  int cell_index(double x, int axis) const {
    return std::clamp(static_cast<int>(std::floor((x - lo_[axis]) / cell_)), 0, dims_[axis] - 1);
  }
  int resolution_;
  double radius_ = 0.0, cell_ = 1.0, slack_ = 0.0;
  Vec3d lo_{};
  int dims_[3] = {1, 1, 1};
  std::vector<std::uint32_t> offsets_, refs_;
  std::vector<BeamLine> lines_;
};

// A diced piece is first the builder's primitive itself: its inflated box, geomID = the beam and
// primID = k | n << 16 (piece k of n). After the build its slot holds its PieceLine instead.

}  // namespace

std::unique_ptr<BeamAccel> make_beam_grid(int grid_resolution) { return std::make_unique<BeamGrid>(grid_resolution); }

}  // namespace ptpb::accel_detail
