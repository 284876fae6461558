// 4-wide BVH over diced, R-inflated beam pieces (DESIGN.md §8), built by Embree's BVH builder and
// traversed here.
//
// Why not Embree user geometry: its per-primitive callback costs more than the traversal itself;
// here the node test is one 4-wide slab test, and a leaf runs the exact test on up to 8 pieces, four
// at a time in float (SSE). Leaves point into the builder's own primitive array, whose slots are
// overwritten with the pieces' lines after the build: no second copy of the pieces, and the leaf
// test reads 32 contiguous bytes a piece instead of the beam records. Each of these choices was
// timed on the benchmark scene's camera pass (benchmarks/bench_ptpb.py writes the current figures).
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
#include <memory>
#include <mutex>
#include <new>
#include <stdexcept>
#include <string>
#include <utility>

#include "beam_accel_shared.hpp"
#include "piece_lines.hpp"
#include "ptpb/parallel.hpp"

namespace ptpb::accel_detail {
namespace {

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
// The builder's largest leaf: with the 4-wide float leaf test, 8 timed faster than 4 and 2
// (benchmarks/bench_ptpb.py times the camera pass).
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
    node->box[0][i] = bounds[i]->lower_x;
    node->box[1][i] = bounds[i]->lower_y;
    node->box[2][i] = bounds[i]->lower_z;
    node->box[3][i] = bounds[i]->upper_x;
    node->box[4][i] = bounds[i]->upper_y;
    node->box[5][i] = bounds[i]->upper_z;
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
  prim.lower_x = lo(0);
  prim.lower_y = lo(1);
  prim.lower_z = lo(2);
  prim.upper_x = hi(0);
  prim.upper_y = hi(1);
  prim.upper_z = hi(2);
  prim.geomID = beam;                                                         // the beam ...
  prim.primID = static_cast<unsigned>(k) | (static_cast<unsigned>(n) << 16);  // ... and which of its pieces
  return prim;
}

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
    auto* copy =
        static_cast<RTCBuildPrimitive*>(rtcThreadLocalAlloc(alloc, (count + kLeafPad) * sizeof(RTCBuildPrimitive), 16));
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
    // about two pieces on average. Long beams diced at a few R (the cube of DESIGN.md §10 test 4:
    // tens of pieces a beam at R = 1 cm) let the build dominate a render and deepened every query.
    // For short beams 6R rather than 4R trades a little render time for fewer pieces, and so less
    // peak memory when beams dominate it (benchmarks/bench_ptpb.py reports it).
    double dice = dice_length_;
    if (!(dice > 0)) {
      double total_length = 0.0;
      for (const Beam& b : beams) total_length += b.length;
      dice = std::max(
          {6.0 * radius, max_component(bounds.hi - bounds.lo) / 32.0, 0.5 * total_length / double(beams.size())});
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
    prims_.resize(piece_count_ + kLeafPad);                                 // every piece's slot is written below
    std::fill(prims_.end() - kLeafPad, prims_.end(), RTCBuildPrimitive{});  // zeroed padding: see float_candidates4
    parallel_for_chunks(chunks, 1, threads, [&](std::size_t c0, std::size_t c1) {
      for (std::size_t c = c0; c < c1; ++c) {
        std::size_t slot = chunk_start[c];
        const std::size_t b_end = std::min(beams.size(), (c + 1) * kBuildChunk);
        for (std::size_t bi = c * kBuildChunk; bi < b_end; ++bi) {
          const int n = pieces_of(beams[bi]);
          for (int k = 0; k < n; ++k)
            prims_[slot++] = piece_box(beams[bi], static_cast<std::uint32_t>(bi), k, n, inflate);
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
    parallel_for_chunks(piece_count_, 8192, threads,
                        [&](std::size_t i0, std::size_t i1) { to_piece_lines(beams, prims_.data() + i0, i1 - i0); });
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
        // times, and testing them cost more than it saved (timed on the camera pass). So every piece
        // goes to the exact test.
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
      const __m128 t0 =
          _mm_max_ps(_mm_max_ps(_mm_mul_ps(_mm_sub_ps(_mm_load_ps(nx), org4[0]), inv4[0]),
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
  // The query in the float frame of the piece lines, relative to the anchor (piece_lines.hpp).
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

  // One piece's share of the 4-wide leaf test against one 4-wide node test (SAH): 0.25 measured
  // fastest on the camera pass; 0.125 and 0.5 are within noise of it.
  static constexpr float kPieceTestCost = 0.25f;
  static constexpr int kStackSize = 256;  // > 3 * maximal depth + 1

  // Embree builds with its own thread pool, sized here to the render's thread count; Embree's task
  // scheduler is shared by the process, though, and sized by its first device (see the arena).
  void use_device(int threads) {
    if (device_ && threads == device_threads_) return;
    if (bvh_) {
      rtcReleaseBVH(bvh_);
      bvh_ = nullptr;
    }
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

std::unique_ptr<BeamAccel> make_beam_bvh(double dice_length) { return std::make_unique<BeamBvh>(dice_length); }

}  // namespace ptpb::accel_detail
