// Uniform grid and Embree user-geometry BVH over diced, R-inflated beam pieces.
#include "ptpb/beam_accel.hpp"

#include <embree3/rtcore.h>

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>

#include "ptpb/parallel.hpp"

namespace ptpb {
namespace {

struct Box {
  Vec3d lo{1e300, 1e300, 1e300}, hi{-1e300, -1e300, -1e300};
  void expand(const Vec3d& p) {
    for (int a = 0; a < 3; ++a) { lo[a] = std::min(lo[a], p[a]); hi[a] = std::max(hi[a], p[a]); }
  }
};

Box beams_bounds(const std::vector<Beam>& beams, double radius) {
  Box b;
  for (const Beam& beam : beams) {
    b.expand(beam.origin);
    b.expand(beam.origin + beam.direction * beam.length);
  }
  const Vec3d r{radius, radius, radius};
  b.lo = b.lo - r;
  b.hi = b.hi + r;
  return b;
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

constexpr std::size_t kBuildChunk = 2048;

class BeamGrid final : public BeamAccel {
 public:
  explicit BeamGrid(int resolution) : resolution_(resolution) {
    if (resolution < 1 || resolution > 1024) throw std::invalid_argument("grid_resolution must lie in [1, 1024]");
  }

  void build(const std::vector<Beam>& beams, double radius, int threads) override {
    radius_ = radius;
    offsets_.clear();
    refs_.clear();
    if (beams.empty()) return;
    const Box box = beams_bounds(beams, radius);
    lo_ = box.lo;
    const Vec3d extent = box.hi - box.lo;
    cell_ = max_component(extent) / resolution_;
    for (int a = 0; a < 3; ++a) dims_[a] = std::clamp(static_cast<int>(std::ceil(extent[a] / cell_)), 1, resolution_);
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
              i0[a] = cell_index(std::min(p0[a], p1[a]) - radius, a);
              i1[a] = cell_index(std::max(p0[a], p1[a]) + radius, a);
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

  void query(const Vec3d& o, const Vec3d& d, double t_max, std::vector<std::uint32_t>& out) const override {
    if (refs_.empty()) return;
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
        t_next[a] = t_delta[a] = std::numeric_limits<double>::infinity();
      }
    }
    for (;;) {
      const std::size_t cell = (std::size_t(idx[2]) * dims_[1] + idx[1]) * dims_[0] + idx[0];
      out.insert(out.end(), refs_.begin() + offsets_[cell], refs_.begin() + offsets_[cell + 1]);
      const int a = t_next[0] < t_next[1] ? (t_next[0] < t_next[2] ? 0 : 2) : (t_next[1] < t_next[2] ? 1 : 2);
      if (t_next[a] > t1) break;
      idx[a] += step[a];
      if (idx[a] < 0 || idx[a] >= dims_[a]) break;
      t_next[a] += t_delta[a];
    }
  }

  std::uint64_t references() const override { return refs_.size(); }
  double radius() const override { return radius_; }

 private:
  int cell_index(double x, int axis) const {
    return std::clamp(static_cast<int>(std::floor((x - lo_[axis]) / cell_)), 0, dims_[axis] - 1);
  }
  int resolution_;
  double radius_ = 0.0, cell_ = 1.0;
  Vec3d lo_{};
  int dims_[3] = {1, 1, 1};
  std::vector<std::uint32_t> offsets_, refs_;
};

struct Piece {
  std::uint32_t beam;
  float lo[3], hi[3];
};

struct BvhQueryContext {
  RTCIntersectContext context;  // first member: Embree hands this pointer back to the callback
  const std::vector<Piece>* pieces;
  std::vector<std::uint32_t>* out;
};

void piece_bounds(const RTCBoundsFunctionArguments* args) {
  const auto& p = (*static_cast<const std::vector<Piece>*>(args->geometryUserPtr))[args->primID];
  RTCBounds* b = args->bounds_o;
  b->lower_x = p.lo[0]; b->lower_y = p.lo[1]; b->lower_z = p.lo[2];
  b->upper_x = p.hi[0]; b->upper_y = p.hi[1]; b->upper_z = p.hi[2];
}

// Records the piece's beam if the ray segment crosses its box, and never reports a hit, so
// traversal visits every overlapping piece (all-hits query).
void piece_intersect(const RTCIntersectFunctionNArguments* args) {
  if (!args->valid[0]) return;
  auto* ctx = reinterpret_cast<BvhQueryContext*>(args->context);
  const Piece& p = (*ctx->pieces)[args->primID];
  const RTCRay& ray = reinterpret_cast<RTCRayHit*>(args->rayhit)->ray;
  double t0 = ray.tnear, t1 = ray.tfar;
  if (clip_to_box({ray.org_x, ray.org_y, ray.org_z}, {ray.dir_x, ray.dir_y, ray.dir_z},
                  {p.lo[0], p.lo[1], p.lo[2]}, {p.hi[0], p.hi[1], p.hi[2]}, t0, t1)) {
    ctx->out->push_back(p.beam);
  }
}

class BeamBvh final : public BeamAccel {
 public:
  explicit BeamBvh(double dice_length) : dice_length_(dice_length) {
    device_ = rtcNewDevice("verbose=0");
    if (!device_) throw std::runtime_error("Embree device creation failed for the beam BVH");
  }
  ~BeamBvh() override {
    if (scene_) rtcReleaseScene(scene_);
    rtcReleaseDevice(device_);
  }

  void build(const std::vector<Beam>& beams, double radius, int threads) override {
    radius_ = radius;
    pieces_.clear();
    if (scene_) { rtcReleaseScene(scene_); scene_ = nullptr; }
    if (beams.empty()) return;
    const Box box = beams_bounds(beams, radius);
    const double dice = dice_length_ > 0 ? dice_length_ : std::max(4.0 * radius, max_component(box.hi - box.lo) / 32.0);
    const std::size_t chunks = (beams.size() + kBuildChunk - 1) / kBuildChunk;
    std::vector<std::vector<Piece>> chunk_pieces(chunks);
    parallel_for_chunks(chunks, 1, threads, [&](std::size_t c0, std::size_t c1) {
      for (std::size_t c = c0; c < c1; ++c) {
        const std::size_t b_end = std::min(beams.size(), (c + 1) * kBuildChunk);
        for (std::size_t bi = c * kBuildChunk; bi < b_end; ++bi) {
          const Beam& b = beams[bi];
          const int n = std::clamp(static_cast<int>(std::ceil(b.length / dice)), 1, 256);
          for (int k = 0; k < n; ++k) {
            const Vec3d p0 = b.origin + b.direction * (b.length * k / n);
            const Vec3d p1 = b.origin + b.direction * (b.length * (k + 1) / n);
            Piece p;
            p.beam = static_cast<std::uint32_t>(bi);
            for (int a = 0; a < 3; ++a) {
              // Rounded outwards so the float box still contains the double capsule.
              p.lo[a] = std::nextafter(static_cast<float>(std::min(p0[a], p1[a]) - radius), -1e30f);
              p.hi[a] = std::nextafter(static_cast<float>(std::max(p0[a], p1[a]) + radius), 1e30f);
            }
            chunk_pieces[c].push_back(p);
          }
        }
      }
    });
    for (auto& v : chunk_pieces) pieces_.insert(pieces_.end(), v.begin(), v.end());
    scene_ = rtcNewScene(device_);
    rtcSetSceneBuildQuality(scene_, RTC_BUILD_QUALITY_LOW);
    RTCGeometry geom = rtcNewGeometry(device_, RTC_GEOMETRY_TYPE_USER);
    rtcSetGeometryUserPrimitiveCount(geom, static_cast<unsigned>(pieces_.size()));
    rtcSetGeometryUserData(geom, &pieces_);
    rtcSetGeometryBoundsFunction(geom, piece_bounds, &pieces_);
    rtcSetGeometryIntersectFunction(geom, piece_intersect);
    rtcCommitGeometry(geom);
    rtcAttachGeometry(scene_, geom);
    rtcReleaseGeometry(geom);
    rtcCommitScene(scene_);
    if (rtcGetDeviceError(device_) != RTC_ERROR_NONE) throw std::runtime_error("Embree failed to build the beam BVH");
  }

  void query(const Vec3d& o, const Vec3d& d, double t_max, std::vector<std::uint32_t>& out) const override {
    if (!scene_) return;
    BvhQueryContext ctx;
    rtcInitIntersectContext(&ctx.context);
    ctx.pieces = &pieces_;
    ctx.out = &out;
    RTCRayHit rh{};
    rh.ray.org_x = float(o.x); rh.ray.org_y = float(o.y); rh.ray.org_z = float(o.z);
    rh.ray.dir_x = float(d.x); rh.ray.dir_y = float(d.y); rh.ray.dir_z = float(d.z);
    rh.ray.tnear = 0.0f;
    rh.ray.tfar = std::nextafter(float(t_max), 1e30f);
    rh.ray.mask = 0xFFFFFFFFu;
    rh.hit.geomID = RTC_INVALID_GEOMETRY_ID;
    rtcIntersect1(scene_, &ctx.context, &rh);
  }

  std::uint64_t references() const override { return pieces_.size(); }
  double radius() const override { return radius_; }

 private:
  double dice_length_;
  double radius_ = 0.0;
  RTCDevice device_ = nullptr;
  RTCScene scene_ = nullptr;
  std::vector<Piece> pieces_;
};

}  // namespace

std::unique_ptr<BeamAccel> make_beam_accel(AccelKind kind, int grid_resolution, double dice_length) {
  if (kind == AccelKind::Embree) return std::make_unique<BeamBvh>(dice_length);
  return std::make_unique<BeamGrid>(grid_resolution);
}

}  // namespace ptpb
