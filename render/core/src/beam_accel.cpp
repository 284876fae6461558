// Uniform grid and 4-wide BVH (built by Embree's BVH builder, traversed here) over diced,
// R-inflated beam pieces.
//
// Both run the gather's exact closest-approach test (ptpb.md §4) themselves, in a division-free
// form that is looser than the gather's, and report each beam once: from the pieces that own the
// beam parameter s_b of the closest approach (BVH; repeats dropped after the sort), or from the
// grid cell that owns the query parameter t_b (grid). The gather's own test then decides exactly as
// before, so images do not change, while candidates that could never pass (box corners, repeated
// pieces) cost neither a push nor a place in the gather's sort. Near-parallel candidates are always
// reported, so that the gather still counts them in its parallel statistic.
//
// Why not Embree user geometry: its per-primitive callback costs more than the traversal itself;
// here the node test is one 4-wide slab test, and a leaf runs the exact test on up to 8 pieces, four
// at a time in float (SSE). Leaves point into the builder's own primitive array, whose slots are
// overwritten with the pieces' lines after the build: no second copy of the pieces, and the leaf
// test reads 32 contiguous bytes a piece instead of the beam records. Measured on the benchmark
// scene (24 iterations, 1 thread, camera pass): double test reading the beams, leaves of 2, 7.6 s;
// float lines 6.6 s; with the beams in space order (sort_beams_spatially) 6.25 s; four pieces at a
// time with leaves of 8, 4.9 s; SAH piece cost 1 -> 0.25 of a node test, 4.25 s.
#include "ptpb/beam_accel.hpp"

#include <embree3/rtcore.h>
#include <embree3/rtcore_builder.h>

#if defined(__SSE2__)
#include <emmintrin.h>
#endif
#if defined(PTPB_HAVE_TBB)
#include <tbb/task_arena.h>
#endif

#include <algorithm>
#include <cmath>
#include <limits>
#include <mutex>
#include <new>
#include <stdexcept>
#include <string>
#include <utility>

#include "ptpb/beam_geometry.hpp"
#include "ptpb/parallel.hpp"

namespace ptpb {
namespace {

constexpr double kInf = std::numeric_limits<double>::infinity();
// Candidates with sin^2 below this reach the gather untested: its parallel guard (default 1e-5)
// counts them there.
constexpr double kParallelKeepSin2 = 1e-4;
// Boxes grow by this fraction of the scene scale beyond R: it covers the float rounding of the
// boxes, of Embree's float ray and of the piece boundaries, so a pair within R is never missed.
constexpr double kBoxMargin = 4e-6;
// The grid's exact test accepts t and s this fraction of the scene scale outside their ranges, and u
// up to R (1 + 1e-9): far above rounding, so the gather never sees fewer pairs than its own test
// accepts. (The BVH's float test has its own margin, kCandidateSlack.)
constexpr double kRangeSlack = 1e-9;

struct Box {
  Vec3d lo{1e300, 1e300, 1e300}, hi{-1e300, -1e300, -1e300};
  void expand(const Vec3d& p) {
    for (int a = 0; a < 3; ++a) { lo[a] = std::min(lo[a], p[a]); hi[a] = std::max(hi[a], p[a]); }
  }
};

Box beams_bounds(const std::vector<Beam>& beams) {
  Box b;
  for (const Beam& beam : beams) {
    b.expand(beam.origin);
    b.expand(beam.origin + beam.direction * beam.length);
  }
  return b;
}

// A length that bounds every coordinate and distance of the beams' box.
double scene_scale(const Box& b) {
  double s = max_component(b.hi - b.lo);
  for (int a = 0; a < 3; ++a) s = std::max(s, std::max(std::fabs(b.lo[a]), std::fabs(b.hi[a])));
  return std::max(s, 1e-300);
}

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

// Sorts out[from, end) ascending: the canonical summation order of ptpb.md §9, on which the gather
// relies, and sequential beam reads there. An LSD radix sort over the bits the beam indices use
// costs less than a comparison sort.
void sort_candidates(std::vector<std::uint32_t>& out, std::size_t from) {
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

constexpr std::size_t kBuildChunk = 2048;

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

// A 4-wide BVH node: child boxes in float, structure of arrays. A child pointer with bit 0 set is a
// leaf (see kLeafTag); a null child has an empty box.
struct alignas(64) Node4 {
  float box[6][4];  // rows: lower x, y, z, then upper x, y, z; columns: children
  std::uintptr_t child[4];
};
// A leaf child is a pointer to its first primitive with bit 0 set and its count - 1 in bits 1..3:
// primitives are 32 bytes and at least 16-byte aligned, so those bits are free.
constexpr std::uintptr_t kLeafTag = 1;
constexpr std::uintptr_t kLeafCountMask = 0xE;
constexpr unsigned kMaxLeafPieces = 8;
// The builder's largest leaf. With the 4-wide float leaf test, 8 beat 4 and 2 by 3 % and 15 %
// (camera pass); with one double test a piece, 2 had beaten 1, 4 and 8 by 6-15 %.
constexpr unsigned kLeafSize = 8;
static_assert(kLeafSize <= kMaxLeafPieces, "a leaf's count must fit its pointer's tag bits");
// Readable slots past the last piece of a leaf: the 4-wide leaf test reads whole groups of four.
constexpr std::size_t kLeafPad = 3;

void* create_node(RTCThreadLocalAllocator alloc, unsigned int /*children*/, void* /*user*/) {
  auto* node = static_cast<Node4*>(rtcThreadLocalAlloc(alloc, sizeof(Node4), alignof(Node4)));
  for (int i = 0; i < 4; ++i) {
    for (int a = 0; a < 3; ++a) {
      node->box[a][i] = std::numeric_limits<float>::infinity();
      node->box[3 + a][i] = -std::numeric_limits<float>::infinity();
    }
    node->child[i] = 0;
  }
  return node;
}

void set_node_children(void* node_ptr, void** children, unsigned int count, void* /*user*/) {
  auto* node = static_cast<Node4*>(node_ptr);
  for (unsigned i = 0; i < count; ++i) node->child[i] = reinterpret_cast<std::uintptr_t>(children[i]);
}

void set_node_bounds(void* node_ptr, const RTCBounds** bounds, unsigned int count, void* /*user*/) {
  auto* node = static_cast<Node4*>(node_ptr);
  for (unsigned i = 0; i < count; ++i) {
    node->box[0][i] = bounds[i]->lower_x; node->box[1][i] = bounds[i]->lower_y; node->box[2][i] = bounds[i]->lower_z;
    node->box[3][i] = bounds[i]->upper_x; node->box[4][i] = bounds[i]->upper_y; node->box[5][i] = bounds[i]->upper_z;
  }
}

// Boundary j of the n pieces of a beam of length L: the pieces split [0, L] at float-rounded
// boundaries, computed the same way for both neighbours.
inline double piece_boundary(double length, int j, int n) {
  return j == n ? length : static_cast<float>(length * j / n);
}

// The box of piece k of n, inflated by `inflate` and rounded outwards so that the float box still
// contains the double capsule.
RTCBuildPrimitive piece_box(const Beam& b, std::uint32_t beam, int k, int n, double inflate) {
  const Vec3d p0 = b.origin + b.direction * (b.length * k / n);
  const Vec3d p1 = b.origin + b.direction * (b.length * (k + 1) / n);
  const auto lo = [&](int a) { return std::nextafter(static_cast<float>(std::min(p0[a], p1[a]) - inflate), -1e30f); };
  const auto hi = [&](int a) { return std::nextafter(static_cast<float>(std::max(p0[a], p1[a]) + inflate), 1e30f); };
  RTCBuildPrimitive prim;
  prim.lower_x = lo(0); prim.lower_y = lo(1); prim.lower_z = lo(2);
  prim.upper_x = hi(0); prim.upper_y = hi(1); prim.upper_z = hi(2);
  prim.geomID = beam;                                           // the beam ...
  prim.primID = static_cast<unsigned>(k) | (static_cast<unsigned>(n) << 16);  // ... and which of its pieces
  return prim;
}

// After the build, each piece's slot holds the piece's own line in float (PieceLine) instead of
// its build box: the leaf's exact test then reads 32 contiguous bytes instead of the beam record,
// and needs no division for the piece's share of the beam.
struct PieceLine {
  float origin[3];      // the piece's start, relative to the structure's anchor
  float direction[3];   // the beam's direction
  float length;         // the piece's share [0, length) of the beam parameter, from its start
  std::uint32_t beam;
};
static_assert(sizeof(PieceLine) == sizeof(RTCBuildPrimitive) && alignof(PieceLine) <= 16,
              "a piece line must fit the slot of its build primitive");

// The primitive array the builder partitions in place, and the leaves it copied from elsewhere.
struct LeafSource {
  const RTCBuildPrimitive* begin;
  const RTCBuildPrimitive* end;
  std::mutex mutex;
  std::vector<std::pair<RTCBuildPrimitive*, std::size_t>> copies;
};

// A leaf points at its primitives where the builder left them, in the primitive array, which lives
// as long as the BVH: no second copy of the pieces. Should a builder hand over primitives from
// elsewhere, they are copied into the BVH's own memory (and listed, to be turned into lines too).
void* create_leaf(RTCThreadLocalAllocator alloc, const RTCBuildPrimitive* prims, size_t count, void* user) {
  LeafSource& src = *static_cast<LeafSource*>(user);
  if (count == 0 || count > kMaxLeafPieces) return nullptr;  // the build then fails with an error
  const RTCBuildPrimitive* leaf = prims;
  if (prims < src.begin || prims + count > src.end || reinterpret_cast<std::uintptr_t>(prims) & 0xF) {
    auto* copy = static_cast<RTCBuildPrimitive*>(
        rtcThreadLocalAlloc(alloc, (count + kLeafPad) * sizeof(RTCBuildPrimitive), 16));
    std::copy(prims, prims + count, copy);
    std::fill(copy + count, copy + count + kLeafPad, RTCBuildPrimitive{});
    leaf = copy;
    std::lock_guard<std::mutex> lock(src.mutex);
    src.copies.emplace_back(copy, count);
  }
  return reinterpret_cast<void*>(reinterpret_cast<std::uintptr_t>(leaf) | ((count - 1) << 1) | kLeafTag);
}

class BeamBvh final : public BeamAccel {
 public:
  explicit BeamBvh(double dice_length) : dice_length_(dice_length) {}
  ~BeamBvh() override {
    if (bvh_) rtcReleaseBVH(bvh_);
    if (device_) rtcReleaseDevice(device_);
  }

  void build(const std::vector<Beam>& beams, double radius, int threads) override {
    radius_ = radius;
    root_ = 0;
    piece_count_ = 0;
    if (beams.empty()) return;
    if (beams.size() > std::numeric_limits<unsigned>::max()) throw std::invalid_argument("too many beams for the BVH");
    use_device(resolve_thread_count(threads));
    const Box bounds = beams_bounds(beams);
    const double scale = scene_scale(bounds);
    const double inflate = radius + kBoxMargin * scale;
    // Automatic piece length: a few R (tight boxes), but never so short that a beam has more than
    // about two pieces on average. Long beams diced at 4R (the cube of ptpb.md §10 test 4: ~30
    // pieces a beam at R = 1 cm) made the build cost 85 % of a render and deepened every query;
    // at half the mean length the same render ran 3.5x faster (build 2.13 -> 0.17 s, camera pass
    // 1.07 -> 0.60 s). The penitente benchmark's beams are short: there 6R rather than 4R costs
    // ~3 % of the render time and saves 16 % of the pieces, which bring the peak memory of a render
    // whose beams dominate it from 1.53x to 1.46x of frames + beams (make bench).
    double dice = dice_length_;
    if (!(dice > 0)) {
      double total_length = 0.0;
      for (const Beam& b : beams) total_length += b.length;
      dice = std::max({6.0 * radius, max_component(bounds.hi - bounds.lo) / 32.0, 0.5 * total_length / double(beams.size())});
    }
    const std::size_t chunks = (beams.size() + kBuildChunk - 1) / kBuildChunk;
    std::vector<std::size_t> chunk_start(chunks + 1, 0);  // pieces per chunk, then their prefix sum
    // Counted twice rather than stored: no array the size of the beams next to the pieces.
    auto pieces_of = [dice](const Beam& b) { return std::clamp(static_cast<int>(std::ceil(b.length / dice)), 1, 256); };
    for (std::size_t bi = 0; bi < beams.size(); ++bi) chunk_start[bi / kBuildChunk + 1] += pieces_of(beams[bi]);
    for (std::size_t c = 0; c < chunks; ++c) chunk_start[c + 1] += chunk_start[c];
    piece_count_ = chunk_start[chunks];
    // Growing the array frees the old one first: a reallocation would hold both for a moment (the
    // peak of a render whose beams dominate its memory). Capacity beyond the pieces is never
    // written, so the 10 % of room for later iterations costs address space, not memory.
    if (piece_count_ + kLeafPad > prims_.capacity()) {
      std::vector<RTCBuildPrimitive>().swap(prims_);
      prims_.reserve((piece_count_ + kLeafPad) * 11 / 10);
    }
    prims_.resize(piece_count_ + kLeafPad);  // every piece's slot is written below
    std::fill(prims_.end() - kLeafPad, prims_.end(), RTCBuildPrimitive{});  // zeroed padding: see float_candidates4
    parallel_for_chunks(chunks, 1, threads, [&](std::size_t c0, std::size_t c1) {
      for (std::size_t c = c0; c < c1; ++c) {
        std::size_t slot = chunk_start[c];
        const std::size_t b_end = std::min(beams.size(), (c + 1) * kBuildChunk);
        for (std::size_t bi = c * kBuildChunk; bi < b_end; ++bi) {
          const int n = pieces_of(beams[bi]);
          for (int k = 0; k < n; ++k) prims_[slot++] = piece_box(beams[bi], static_cast<std::uint32_t>(bi), k, n, inflate);
        }
      }
    });
    LeafSource source{prims_.data(), prims_.data() + piece_count_, {}, {}};
    // One BVH object for every build: Embree then reuses its node memory instead of allocating anew
    // while the freed blocks of the last build are still resident.
    if (!bvh_) bvh_ = rtcNewBVH(device_);
    RTCBuildArguments args = rtcDefaultBuildArguments();
    args.buildQuality = RTC_BUILD_QUALITY_MEDIUM;
    args.maxBranchingFactor = 4;
    args.maxLeafSize = kLeafSize;
    args.traversalCost = 1.0f;
    args.intersectionCost = kPieceTestCost;
    args.bvh = bvh_;
    args.primitives = prims_.data();
    args.primitiveCount = piece_count_;
    args.primitiveArrayCapacity = piece_count_;
    args.createNode = create_node;
    args.setNodeChildren = set_node_children;
    args.setNodeBounds = set_node_bounds;
    args.createLeaf = create_leaf;
    args.userPtr = &source;
#if defined(PTPB_HAVE_TBB)
    // Embree's scheduler is shared by the process and sized by its first device (every core for
    // the scene's); an arena of the render's thread count keeps the build to it.
    tbb::task_arena arena(resolve_thread_count(threads));
    arena.execute([&] { root_ = reinterpret_cast<std::uintptr_t>(rtcBuildBVH(&args)); });
#else
    root_ = reinterpret_cast<std::uintptr_t>(rtcBuildBVH(&args));
#endif
    if (!root_ || rtcGetDeviceError(device_) != RTC_ERROR_NONE)
      throw std::runtime_error("Embree failed to build the beam BVH");
    anchor_ = (bounds.lo + bounds.hi) * 0.5;
    half_diagonal_ = 0.5 * length(bounds.hi - bounds.lo);
    parallel_for_chunks(piece_count_, 8192, threads, [&](std::size_t i0, std::size_t i1) {
      to_piece_lines(beams, prims_.data() + i0, i1 - i0);
    });
    for (const auto& [copy, count] : source.copies) to_piece_lines(beams, copy, count);
  }

  void query(const Vec3d& o, const Vec3d& d, double t_max, std::vector<std::uint32_t>& out) const override {
    if (!root_) return;
    const FloatQuery fq = float_query(o, d, t_max);
#if defined(__SSE2__)
    const FloatQuery4 fq4 = broadcast(fq);
#endif
    // The float ray of the box tests; the margin of the boxes covers its rounding.
    float org[3], inv[3];
    int near_row[3], far_row[3];  // the box rows of each axis's entry and exit planes
    for (int a = 0; a < 3; ++a) {
      org[a] = static_cast<float>(o[a]);
      const double da = std::fabs(d[a]) < 1e-30 ? std::copysign(1e-30, d[a]) : d[a];
      inv[a] = static_cast<float>(1.0 / da);
      near_row[a] = inv[a] < 0 ? 3 + a : a;
      far_row[a] = inv[a] < 0 ? a : 3 + a;
    }
    const float t_far = std::nextafter(static_cast<float>(t_max), 1e30f);
#if defined(__SSE2__)
    const __m128 org4[3] = {_mm_set1_ps(org[0]), _mm_set1_ps(org[1]), _mm_set1_ps(org[2])};
    const __m128 inv4[3] = {_mm_set1_ps(inv[0]), _mm_set1_ps(inv[1]), _mm_set1_ps(inv[2])};
    const __m128 far4 = _mm_set1_ps(t_far);
#endif
    const std::size_t first = out.size();
    std::uintptr_t stack[kStackSize];
    int top = 0;
    stack[top++] = root_;
    while (top > 0) {
      const std::uintptr_t item = stack[--top];
      if (item & kLeafTag) {
        const auto* piece = reinterpret_cast<const PieceLine*>(item & ~(kLeafTag | kLeafCountMask));
        const int count = int((item & kLeafCountMask) >> 1) + 1;
        // The child box test above has already passed; the pieces' own boxes would pass three in four
        // times, and testing them cost more than it saved (camera pass 2.4-2.5 s against 2.0-2.3 s
        // without). So every piece goes to the exact test.
#if defined(__SSE2__)
        for (int i = 0; i < count; i += 4) {
          int hits = float_candidates4(fq4, piece + i) & ((1 << std::min(4, count - i)) - 1);
          for (; hits; hits &= hits - 1) out.push_back(piece[i + __builtin_ctz(hits)].beam);
        }
#else
        for (int i = 0; i < count; ++i)
          if (float_candidate(fq, piece[i])) out.push_back(piece[i].beam);
#endif
        continue;
      }
      const Node4& node = *reinterpret_cast<const Node4*>(item);
      // Slab test of the four child boxes at once.
      const float *nx = node.box[near_row[0]], *ny = node.box[near_row[1]], *nz = node.box[near_row[2]];
      const float *fx = node.box[far_row[0]], *fy = node.box[far_row[1]], *fz = node.box[far_row[2]];
#if defined(__SSE2__)
      const __m128 t0 = _mm_max_ps(_mm_max_ps(_mm_mul_ps(_mm_sub_ps(_mm_load_ps(nx), org4[0]), inv4[0]),
                                              _mm_mul_ps(_mm_sub_ps(_mm_load_ps(ny), org4[1]), inv4[1])),
                                   _mm_max_ps(_mm_mul_ps(_mm_sub_ps(_mm_load_ps(nz), org4[2]), inv4[2]), _mm_setzero_ps()));
      const __m128 t1 = _mm_min_ps(_mm_min_ps(_mm_mul_ps(_mm_sub_ps(_mm_load_ps(fx), org4[0]), inv4[0]),
                                              _mm_mul_ps(_mm_sub_ps(_mm_load_ps(fy), org4[1]), inv4[1])),
                                   _mm_min_ps(_mm_mul_ps(_mm_sub_ps(_mm_load_ps(fz), org4[2]), inv4[2]), far4));
      const int hits = _mm_movemask_ps(_mm_cmple_ps(t0, t1));
#else
      int hits = 0;
      for (int i = 0; i < 4; ++i) {
        const float t0 = std::max(std::max((nx[i] - org[0]) * inv[0], (ny[i] - org[1]) * inv[1]),
                                  std::max((nz[i] - org[2]) * inv[2], 0.0f));
        const float t1 = std::min(std::min((fx[i] - org[0]) * inv[0], (fy[i] - org[1]) * inv[1]),
                                  std::min((fz[i] - org[2]) * inv[2], t_far));
        hits |= int(t0 <= t1) << i;
      }
#endif
      for (int i = 0; i < 4; ++i)
        if ((hits >> i & 1) && node.child[i]) stack[top++] = node.child[i];
    }
    sort_candidates(out, first);
    // Neighbouring pieces' loose shares of s overlap: a beam near their boundary may come twice.
    out.erase(std::unique(out.begin() + std::ptrdiff_t(first), out.end()), out.end());
  }

  std::uint64_t references() const override { return piece_count_; }
  double radius() const override { return radius_; }

 private:
  // A query in the float frame of the piece lines, with the margin that makes its test looser than
  // the exact one in double: kCandidateSlack (beam_accel.hpp) of `span`, which bounds
  // |origin - piece start|, t_max and 4R. The rounding of the coordinates (relative to the anchor)
  // and of the products that form t_num, s_num, w_cross and the bounds stays below ~3e-6 of it.
  struct FloatQuery {
    float origin[3], direction[3];
    float t_max, radius, margin;
  };

  FloatQuery float_query(const Vec3d& o, const Vec3d& d, double t_max) const {
    FloatQuery f;
    const Vec3d rel = o - anchor_;
    for (int a = 0; a < 3; ++a) {
      f.origin[a] = static_cast<float>(rel[a]);
      f.direction[a] = static_cast<float>(d[a]);
    }
    const double span = length(rel) + half_diagonal_ + t_max + 4.0 * radius_;
    f.t_max = static_cast<float>(t_max);
    f.radius = static_cast<float>(radius_);
    f.margin = static_cast<float>(kCandidateSlack * span);
    return f;
  }

  // The division-free closest-approach test of pair_candidate, in float, with the ownership of the
  // piece's share of s: true for near-parallel pieces, and for pieces whose closest approach has t
  // in [0, t_max], s in [0, length) and u < R, each widened by the margin. Neighbouring pieces may
  // then both report a beam whose s lies near their common boundary; query() drops the repeat.
  static bool float_candidate(const FloatQuery& q, const PieceLine& p) {
    const float wx = q.origin[0] - p.origin[0], wy = q.origin[1] - p.origin[1], wz = q.origin[2] - p.origin[2];
    const float* c = q.direction;
    const float* b = p.direction;
    const float cx = c[1] * b[2] - c[2] * b[1], cy = c[2] * b[0] - c[0] * b[2], cz = c[0] * b[1] - c[1] * b[0];
    const float sin2 = cx * cx + cy * cy + cz * cz;
    if (sin2 < float(kParallelKeepSin2)) return true;
    const float cb = c[0] * b[0] + c[1] * b[1] + c[2] * b[2];
    const float cw = c[0] * wx + c[1] * wy + c[2] * wz;
    const float bw = b[0] * wx + b[1] * wy + b[2] * wz;
    const float t_num = cb * bw - cw, s_num = bw - cb * cw;
    const float w_cross = wx * cx + wy * cy + wz * cz;
    return t_num >= -q.margin && t_num <= q.t_max * sin2 + q.margin && s_num >= -q.margin &&
           s_num <= p.length * sin2 + q.margin && std::fabs(w_cross) <= q.radius * std::sqrt(sin2) + q.margin;
  }

#if defined(__SSE2__)
  struct FloatQuery4 {
    __m128 origin[3], direction[3], t_max, radius, margin, neg_margin, parallel;
  };
  static FloatQuery4 broadcast(const FloatQuery& q) {
    FloatQuery4 f;
    for (int a = 0; a < 3; ++a) {
      f.origin[a] = _mm_set1_ps(q.origin[a]);
      f.direction[a] = _mm_set1_ps(q.direction[a]);
    }
    f.t_max = _mm_set1_ps(q.t_max);
    f.radius = _mm_set1_ps(q.radius);
    f.margin = _mm_set1_ps(q.margin);
    f.neg_margin = _mm_set1_ps(-q.margin);
    f.parallel = _mm_set1_ps(float(kParallelKeepSin2));
    return f;
  }

  // float_candidate on four consecutive piece lines at once; bit i of the result for piece i. The
  // slots past a leaf's last piece must be readable (prims_ is padded); their bits are masked off.
  static int float_candidates4(const FloatQuery4& q, const PieceLine* p) {
    const float* f = reinterpret_cast<const float*>(p);
    __m128 ox = _mm_loadu_ps(f), oy = _mm_loadu_ps(f + 8), oz = _mm_loadu_ps(f + 16), bx = _mm_loadu_ps(f + 24);
    __m128 by = _mm_loadu_ps(f + 4), bz = _mm_loadu_ps(f + 12), len = _mm_loadu_ps(f + 20), beam = _mm_loadu_ps(f + 28);
    _MM_TRANSPOSE4_PS(ox, oy, oz, bx);      // rows: origin x, y, z and direction x of the 4 pieces
    _MM_TRANSPOSE4_PS(by, bz, len, beam);   // rows: direction y, z, length and the beam's bits
    const __m128 wx = _mm_sub_ps(q.origin[0], ox), wy = _mm_sub_ps(q.origin[1], oy), wz = _mm_sub_ps(q.origin[2], oz);
    const __m128 *c = q.direction;
    const __m128 cx = _mm_sub_ps(_mm_mul_ps(c[1], bz), _mm_mul_ps(c[2], by));
    const __m128 cy = _mm_sub_ps(_mm_mul_ps(c[2], bx), _mm_mul_ps(c[0], bz));
    const __m128 cz = _mm_sub_ps(_mm_mul_ps(c[0], by), _mm_mul_ps(c[1], bx));
    const __m128 sin2 = _mm_add_ps(_mm_add_ps(_mm_mul_ps(cx, cx), _mm_mul_ps(cy, cy)), _mm_mul_ps(cz, cz));
    const __m128 cb = _mm_add_ps(_mm_add_ps(_mm_mul_ps(c[0], bx), _mm_mul_ps(c[1], by)), _mm_mul_ps(c[2], bz));
    const __m128 cw = _mm_add_ps(_mm_add_ps(_mm_mul_ps(c[0], wx), _mm_mul_ps(c[1], wy)), _mm_mul_ps(c[2], wz));
    const __m128 bw = _mm_add_ps(_mm_add_ps(_mm_mul_ps(bx, wx), _mm_mul_ps(by, wy)), _mm_mul_ps(bz, wz));
    const __m128 t_num = _mm_sub_ps(_mm_mul_ps(cb, bw), cw), s_num = _mm_sub_ps(bw, _mm_mul_ps(cb, cw));
    const __m128 w_cross = _mm_add_ps(_mm_add_ps(_mm_mul_ps(wx, cx), _mm_mul_ps(wy, cy)), _mm_mul_ps(wz, cz));
    const __m128 abs_cross = _mm_andnot_ps(_mm_set1_ps(-0.0f), w_cross);
    __m128 ok = _mm_and_ps(_mm_cmpge_ps(t_num, q.neg_margin),
                           _mm_cmple_ps(t_num, _mm_add_ps(_mm_mul_ps(q.t_max, sin2), q.margin)));
    ok = _mm_and_ps(ok, _mm_and_ps(_mm_cmpge_ps(s_num, q.neg_margin),
                                   _mm_cmple_ps(s_num, _mm_add_ps(_mm_mul_ps(len, sin2), q.margin))));
    ok = _mm_and_ps(ok, _mm_cmple_ps(abs_cross, _mm_add_ps(_mm_mul_ps(q.radius, _mm_sqrt_ps(sin2)), q.margin)));
    ok = _mm_or_ps(ok, _mm_cmplt_ps(sin2, q.parallel));
    return _mm_movemask_ps(ok);
  }
#endif

  // Overwrites `count` build primitives with their piece lines, in their slots.
  void to_piece_lines(const std::vector<Beam>& beams, RTCBuildPrimitive* prim, std::size_t count) const {
    for (std::size_t i = 0; i < count; ++i) {
      const std::uint32_t beam = prim[i].geomID;
      const int k = int(prim[i].primID & 0xFFFFu), pieces = int(prim[i].primID >> 16);
      const Beam& b = beams[beam];
      const double s0 = piece_boundary(b.length, k, pieces), s1 = piece_boundary(b.length, k + 1, pieces);
      const Vec3d start = b.origin + b.direction * s0 - anchor_;
      PieceLine* line = new (&prim[i]) PieceLine;  // ends the primitive's lifetime in its slot
      for (int a = 0; a < 3; ++a) {
        line->origin[a] = static_cast<float>(start[a]);
        line->direction[a] = static_cast<float>(b.direction[a]);
      }
      line->length = static_cast<float>(s1 - s0);
      line->beam = beam;
    }
  }

  // One piece's share of the 4-wide leaf test against one 4-wide node test (SAH): 0.25 beat 1 by
  // 12 % (camera pass), 0.125 and 0.5 are within noise of it.
  static constexpr float kPieceTestCost = 0.25f;
  static constexpr int kStackSize = 256;           // > 3 * maximal depth + 1

  // Embree builds with its own thread pool, sized here to the render's thread count; Embree's task
  // scheduler is shared by the process, though, and sized by its first device (see the arena).
  void use_device(int threads) {
    if (device_ && threads == device_threads_) return;
    if (bvh_) { rtcReleaseBVH(bvh_); bvh_ = nullptr; }
    if (device_) rtcReleaseDevice(device_);
    const std::string config = "verbose=0,threads=" + std::to_string(threads);
    device_ = rtcNewDevice(config.c_str());
    if (!device_) throw std::runtime_error("Embree device creation failed for the beam BVH");
    device_threads_ = threads;
  }

  double dice_length_;
  double radius_ = 0.0;
  Vec3d anchor_{};              // the beams' box centre: the origin of the piece lines
  double half_diagonal_ = 0.0;  // of the beams' box
  RTCDevice device_ = nullptr;
  int device_threads_ = 0;
  RTCBVH bvh_ = nullptr;
  std::uintptr_t root_ = 0;
  std::size_t piece_count_ = 0;
  std::vector<RTCBuildPrimitive> prims_;  // the pieces, then their lines; leaves point into it
};

}  // namespace

std::unique_ptr<BeamAccel> make_beam_accel(AccelKind kind, int grid_resolution, double dice_length) {
  if (kind == AccelKind::Embree) return std::make_unique<BeamBvh>(dice_length);
  return std::make_unique<BeamGrid>(grid_resolution);
}

}  // namespace ptpb
