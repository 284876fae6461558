#include "ptpb/ray_engine.hpp"

#include <embree3/rtcore.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <string>
#include <utility>

#include "ptpb/parallel.hpp"

namespace ptpb {
namespace {

constexpr std::size_t kRayChunk = 4096;

// Squared distance from p to the triangle (a, b, c): the closest point by Voronoi regions
// (Ericson, Real-Time Collision Detection, 5.1.5), in double.
double triangle_distance2(const Vec3d& p, const Vec3d& a, const Vec3d& b, const Vec3d& c) {
  const Vec3d ab = b - a, ac = c - a, ap = p - a;
  const double d1 = dot(ab, ap), d2 = dot(ac, ap);
  if (d1 <= 0 && d2 <= 0) return dot(ap, ap);
  const Vec3d bp = p - b;
  const double d3 = dot(ab, bp), d4 = dot(ac, bp);
  if (d3 >= 0 && d4 <= d3) return dot(bp, bp);
  const double vc = d1 * d4 - d3 * d2;
  if (vc <= 0 && d1 >= 0 && d3 <= 0) {
    const Vec3d q = a + ab * (d1 / (d1 - d3)) - p;
    return dot(q, q);
  }
  const Vec3d cp = p - c;
  const double d5 = dot(ab, cp), d6 = dot(ac, cp);
  if (d6 >= 0 && d5 <= d6) return dot(cp, cp);
  const double vb = d5 * d2 - d1 * d6;
  if (vb <= 0 && d2 >= 0 && d6 <= 0) {
    const Vec3d q = a + ac * (d2 / (d2 - d6)) - p;
    return dot(q, q);
  }
  const double va = d3 * d6 - d5 * d4;
  if (va <= 0 && (d4 - d3) >= 0 && (d5 - d6) >= 0) {
    const Vec3d q = b + (c - b) * ((d4 - d3) / ((d4 - d3) + (d5 - d6))) - p;
    return dot(q, q);
  }
  const double denom = 1.0 / (va + vb + vc);
  const Vec3d q = a + ab * (vb * denom) + ac * (vc * denom) - p;
  return dot(q, q);
}

void throw_device_error(RTCDevice device, const char* what) {
  const RTCError code = rtcGetDeviceError(device);
  if (code != RTC_ERROR_NONE) {
    throw std::runtime_error(std::string("Embree error during ") + what + " (code " +
                             std::to_string(static_cast<int>(code)) + ")");
  }
}

}  // namespace

struct RayScene::Impl {
  RTCDevice device = nullptr;
  RTCScene scene = nullptr;
  // Own copies of the geometry, used for normals (and by later consumers of hits).
  std::vector<std::vector<float>> vertices;
  std::vector<std::vector<std::uint32_t>> faces;
  std::vector<RTCScene> children;  // one per instanced mesh, released with the scene
  // Per top-level Embree geometry: its mesh slot and its translation (zero for a plain mesh).
  std::vector<std::pair<std::uint32_t, Vec3d>> placements;
};

RayScene::RayScene() : impl_(std::make_unique<Impl>()) {
  impl_->device = rtcNewDevice(nullptr);
  if (!impl_->device) throw std::runtime_error("Embree could not create a device");
  impl_->scene = rtcNewScene(impl_->device);
  rtcSetSceneBuildQuality(impl_->scene, RTC_BUILD_QUALITY_HIGH);
  throw_device_error(impl_->device, "scene creation");
}

RayScene::~RayScene() {
  if (impl_->scene) rtcReleaseScene(impl_->scene);
  for (RTCScene child : impl_->children) rtcReleaseScene(child);
  if (impl_->device) rtcReleaseDevice(impl_->device);
}

void RayScene::check_mesh(const float* vertices, std::size_t vertex_count, const std::uint32_t* faces,
                          std::size_t face_count, std::uint32_t mesh_id) const {
  if (committed_) throw std::logic_error("add_mesh called after commit()");
  if (vertex_count < 3 || face_count == 0) {
    throw std::invalid_argument("mesh " + std::to_string(mesh_id) +
                                " is empty: it needs at least 3 vertices and 1 triangle");
  }
  if (mesh_id == kInvalidId) throw std::invalid_argument("mesh id 4294967295 is reserved");
  for (std::size_t i = 0; i < 3 * vertex_count; ++i) {
    if (!std::isfinite(vertices[i])) {
      throw std::invalid_argument("mesh " + std::to_string(mesh_id) + ": vertex " + std::to_string(i / 3) +
                                  " has a non-finite coordinate");
    }
  }
  for (std::size_t i = 0; i < 3 * face_count; ++i) {
    if (faces[i] >= vertex_count) {
      throw std::invalid_argument("mesh " + std::to_string(mesh_id) + ": face " + std::to_string(i / 3) +
                                  " refers to vertex " + std::to_string(faces[i]) + " but the mesh has only " +
                                  std::to_string(vertex_count) + " vertices");
    }
  }
}

namespace {

// A committed Embree triangle geometry holding copies of the caller's buffers (released by the caller).
RTCGeometry triangle_geometry(RTCDevice device, const float* vertices, std::size_t vertex_count,
                              const std::uint32_t* faces, std::size_t face_count, std::uint32_t mesh_id) {
  RTCGeometry geom = rtcNewGeometry(device, RTC_GEOMETRY_TYPE_TRIANGLE);
  auto* vbuf = static_cast<float*>(
      rtcSetNewGeometryBuffer(geom, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3, 3 * sizeof(float), vertex_count));
  auto* ibuf = static_cast<std::uint32_t*>(
      rtcSetNewGeometryBuffer(geom, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3, 3 * sizeof(std::uint32_t), face_count));
  if (!vbuf || !ibuf) {
    rtcReleaseGeometry(geom);
    throw std::runtime_error("Embree could not allocate buffers for mesh " + std::to_string(mesh_id));
  }
  std::copy(vertices, vertices + 3 * vertex_count, vbuf);
  std::copy(faces, faces + 3 * face_count, ibuf);
  rtcCommitGeometry(geom);
  return geom;
}

Bounds3f mesh_bounds(const float* vertices, std::size_t vertex_count) {
  Bounds3f b;
  for (std::size_t i = 0; i < vertex_count; ++i) {
    for (int a = 0; a < 3; ++a) {
      b.lower[a] = std::min(b.lower[a], vertices[3 * i + a]);
      b.upper[a] = std::max(b.upper[a], vertices[3 * i + a]);
    }
  }
  return b;
}

}  // namespace

void RayScene::grow_bounds(const Bounds3f& local, const Vec3d& offset) {
  for (int a = 0; a < 3; ++a) {
    bounds_.lower[a] = std::min(bounds_.lower[a], local.lower[a] + float(offset[a]));
    bounds_.upper[a] = std::max(bounds_.upper[a], local.upper[a] + float(offset[a]));
  }
}

void RayScene::store_mesh(const float* vertices, std::size_t vertex_count, const std::uint32_t* faces,
                          std::size_t face_count, std::uint32_t mesh_id) {
  mesh_ids_.push_back(mesh_id);
  impl_->vertices.emplace_back(vertices, vertices + 3 * vertex_count);
  impl_->faces.emplace_back(faces, faces + 3 * face_count);
  triangle_count_ += face_count;
}

void RayScene::add_mesh(const float* vertices, std::size_t vertex_count, const std::uint32_t* faces,
                        std::size_t face_count, std::uint32_t mesh_id) {
  check_mesh(vertices, vertex_count, faces, face_count, mesh_id);
  RTCGeometry geom = triangle_geometry(impl_->device, vertices, vertex_count, faces, face_count, mesh_id);
  const unsigned geom_id = rtcAttachGeometry(impl_->scene, geom);
  rtcReleaseGeometry(geom);
  throw_device_error(impl_->device, "add_mesh");
  if (geom_id != impl_->placements.size()) throw std::logic_error("unexpected Embree geometry id");
  grow_bounds(mesh_bounds(vertices, vertex_count), Vec3d{0, 0, 0});
  impl_->placements.emplace_back(static_cast<std::uint32_t>(mesh_ids_.size()), Vec3d{0, 0, 0});
  store_mesh(vertices, vertex_count, faces, face_count, mesh_id);
  placed_triangle_count_ += face_count;
}

void RayScene::add_instanced_mesh(const float* vertices, std::size_t vertex_count, const std::uint32_t* faces,
                                  std::size_t face_count, const double* offsets, std::size_t offset_count,
                                  std::uint32_t mesh_id) {
  check_mesh(vertices, vertex_count, faces, face_count, mesh_id);
  if (offset_count == 0) throw std::invalid_argument("mesh " + std::to_string(mesh_id) + " has no instance offsets");
  for (std::size_t i = 0; i < 3 * offset_count; ++i) {
    if (!std::isfinite(offsets[i])) {
      throw std::invalid_argument("mesh " + std::to_string(mesh_id) + ": instance offset " + std::to_string(i / 3) +
                                  " is not finite");
    }
  }
  // One copy of the triangles in a child scene; each offset places it by an instance (translation only).
  RTCScene child = rtcNewScene(impl_->device);
  rtcSetSceneBuildQuality(child, RTC_BUILD_QUALITY_HIGH);
  RTCGeometry geom = triangle_geometry(impl_->device, vertices, vertex_count, faces, face_count, mesh_id);
  rtcAttachGeometry(child, geom);
  rtcReleaseGeometry(geom);
  rtcCommitScene(child);
  impl_->children.push_back(child);
  throw_device_error(impl_->device, "add_instanced_mesh (its mesh)");
  const Bounds3f local = mesh_bounds(vertices, vertex_count);
  const auto slot = static_cast<std::uint32_t>(mesh_ids_.size());
  for (std::size_t k = 0; k < offset_count; ++k) {
    const Vec3d t{offsets[3 * k], offsets[3 * k + 1], offsets[3 * k + 2]};
    RTCGeometry instance = rtcNewGeometry(impl_->device, RTC_GEOMETRY_TYPE_INSTANCE);
    rtcSetGeometryInstancedScene(instance, child);
    // Column-major 3x4: identity rotation, translation t.
    const float xfm[12] = {1, 0, 0, 0, 1, 0, 0, 0, 1, float(t.x), float(t.y), float(t.z)};
    rtcSetGeometryTransform(instance, 0, RTC_FORMAT_FLOAT3X4_COLUMN_MAJOR, xfm);
    rtcCommitGeometry(instance);
    const unsigned geom_id = rtcAttachGeometry(impl_->scene, instance);
    rtcReleaseGeometry(instance);
    if (geom_id != impl_->placements.size()) throw std::logic_error("unexpected Embree geometry id");
    const Vec3d placed(Vec3f(float(t.x), float(t.y), float(t.z)));  // as Embree holds the transform
    impl_->placements.emplace_back(slot, placed);
    grow_bounds(local, placed);
  }
  throw_device_error(impl_->device, "add_instanced_mesh (its instances)");
  store_mesh(vertices, vertex_count, faces, face_count, mesh_id);
  placed_triangle_count_ += face_count * offset_count;
}

void RayScene::commit() {
  rtcCommitScene(impl_->scene);
  throw_device_error(impl_->device, "scene commit (BVH build)");
  committed_ = true;
}

void RayScene::require_committed() const {
  if (!committed_) throw std::logic_error("RayScene must be committed before it is queried");
}

Hit RayScene::intersect(const Vec3f& origin, const Vec3f& direction, float tnear, float tfar) const {
  RTCIntersectContext context;
  rtcInitIntersectContext(&context);
  RTCRayHit rh;
  rh.ray.org_x = origin.x;
  rh.ray.org_y = origin.y;
  rh.ray.org_z = origin.z;
  rh.ray.dir_x = direction.x;
  rh.ray.dir_y = direction.y;
  rh.ray.dir_z = direction.z;
  rh.ray.tnear = tnear;
  rh.ray.tfar = tfar;
  rh.ray.mask = 0xFFFFFFFFu;
  rh.ray.flags = 0;
  rh.ray.time = 0.0f;
  rh.ray.id = 0;
  rh.hit.geomID = RTC_INVALID_GEOMETRY_ID;
  rh.hit.primID = RTC_INVALID_GEOMETRY_ID;
  rh.hit.instID[0] = RTC_INVALID_GEOMETRY_ID;
  rtcIntersect1(impl_->scene, &context, &rh);
  Hit hit;
  if (rh.hit.geomID == RTC_INVALID_GEOMETRY_ID) return hit;
  hit.t = rh.ray.tfar;
  hit.prim_id = rh.hit.primID;
  // An instance's hit names the instance in instID[0] and the child's geometry in geomID.
  const unsigned top = rh.hit.instID[0] != RTC_INVALID_GEOMETRY_ID ? rh.hit.instID[0] : rh.hit.geomID;
  const std::uint32_t slot = impl_->placements[top].first;  // translations leave the winding normal as it is
  hit.mesh_id = mesh_ids_[slot];
  const auto& v = impl_->vertices[slot];
  const auto& f = impl_->faces[slot];
  const std::uint32_t* tri = &f[3 * static_cast<std::size_t>(rh.hit.primID)];
  const Vec3f p0(v[3 * tri[0]], v[3 * tri[0] + 1], v[3 * tri[0] + 2]);
  const Vec3f p1(v[3 * tri[1]], v[3 * tri[1] + 1], v[3 * tri[1] + 2]);
  const Vec3f p2(v[3 * tri[2]], v[3 * tri[2] + 1], v[3 * tri[2] + 2]);
  // Counter-clockwise winding seen from the front gives the normal (right-hand rule).
  const Vec3d n = cross(Vec3d(p1 - p0), Vec3d(p2 - p0));
  const double len = length(n);
  hit.normal = len > 0 ? Vec3f(n / len) : Vec3f(0, 0, 0);
  return hit;
}

bool RayScene::occluded(const Vec3f& origin, const Vec3f& direction, float tnear, float tfar) const {
  RTCIntersectContext context;
  rtcInitIntersectContext(&context);
  RTCRay ray;
  ray.org_x = origin.x;
  ray.org_y = origin.y;
  ray.org_z = origin.z;
  ray.dir_x = direction.x;
  ray.dir_y = direction.y;
  ray.dir_z = direction.z;
  ray.tnear = tnear;
  ray.tfar = tfar;
  ray.mask = 0xFFFFFFFFu;
  ray.flags = 0;
  ray.time = 0.0f;
  ray.id = 0;
  rtcOccluded1(impl_->scene, &context, &ray);
  return ray.tfar == -std::numeric_limits<float>::infinity();
}

namespace {

struct ClosestQuery {
  const std::vector<std::vector<float>>* vertices;
  const std::vector<std::vector<std::uint32_t>>* faces;
  const std::vector<std::pair<std::uint32_t, Vec3d>>* placements;  // top-level geometry -> (slot, offset)
  Vec3d point;
  double distance;
  double slack;  // how far the float query centre may lie from `point`
};

bool closest_triangle(RTCPointQueryFunctionArguments* args) {
  auto* q = static_cast<ClosestQuery*>(args->userPtr);
  // Inside an instance (translation only, so distances are the same there) the query point moves into the
  // mesh's own frame; the query itself stays in world space (Embree 3's convention).
  const unsigned top = args->context->instStackSize > 0 ? args->context->instID[0] : args->geomID;
  const auto& [slot, offset] = (*q->placements)[top];
  const auto& v = (*q->vertices)[slot];
  const std::uint32_t* tri = &(*q->faces)[slot][3 * static_cast<std::size_t>(args->primID)];
  auto corner = [&](int k) { return Vec3d(v[3 * tri[k]], v[3 * tri[k] + 1], v[3 * tri[k] + 2]); };
  const double d = std::sqrt(triangle_distance2(q->point - offset, corner(0), corner(1), corner(2)));
  if (!(d < q->distance)) return false;
  q->distance = d;
  // Embree culls against a float radius around the float centre: keep the slack so that a triangle
  // slightly closer to `point` is never cut off.
  args->query->radius = std::nextafter(static_cast<float>(d + q->slack), std::numeric_limits<float>::infinity());
  return true;
}

}  // namespace

double RayScene::closest_distance(const Vec3d& point, double radius) const {
  require_committed();
  RTCPointQuery query;
  query.x = static_cast<float>(point.x);
  query.y = static_cast<float>(point.y);
  query.z = static_cast<float>(point.z);
  query.time = 0.0f;
  // The float query centre is off by up to half an ulp per axis: widen the search by that much.
  const double slack = 1e-6 * (1.0 + std::max({std::fabs(point.x), std::fabs(point.y), std::fabs(point.z)}));
  query.radius = static_cast<float>(radius + slack);
  RTCPointQueryContext context;
  rtcInitPointQueryContext(&context);
  ClosestQuery q{&impl_->vertices, &impl_->faces, &impl_->placements, point, radius, slack};
  rtcPointQuery(impl_->scene, &query, &context, closest_triangle, &q);
  return q.distance;
}

void RayScene::intersect_batch(const float* origins, const float* directions, std::size_t n, float tnear,
                               const float* tfar, float* t_out, std::uint32_t* prim_out, std::uint32_t* mesh_out,
                               float* normal_out, int threads) const {
  require_committed();
  parallel_for_chunks(n, kRayChunk, threads, [&](std::size_t begin, std::size_t end) {
    for (std::size_t i = begin; i < end; ++i) {
      const Vec3f o(origins[3 * i], origins[3 * i + 1], origins[3 * i + 2]);
      const Vec3f d(directions[3 * i], directions[3 * i + 1], directions[3 * i + 2]);
      const float far = tfar ? tfar[i] : std::numeric_limits<float>::infinity();
      const Hit h = intersect(o, d, tnear, far);
      t_out[i] = h.t;
      prim_out[i] = h.prim_id;
      mesh_out[i] = h.mesh_id;
      normal_out[3 * i] = h.normal.x;
      normal_out[3 * i + 1] = h.normal.y;
      normal_out[3 * i + 2] = h.normal.z;
    }
  });
}

void RayScene::occluded_batch(const float* origins, const float* directions, std::size_t n, float tnear,
                              const float* tfar, bool* occluded_out, int threads) const {
  require_committed();
  parallel_for_chunks(n, kRayChunk, threads, [&](std::size_t begin, std::size_t end) {
    for (std::size_t i = begin; i < end; ++i) {
      const Vec3f o(origins[3 * i], origins[3 * i + 1], origins[3 * i + 2]);
      const Vec3f d(directions[3 * i], directions[3 * i + 1], directions[3 * i + 2]);
      const float far = tfar ? tfar[i] : std::numeric_limits<float>::infinity();
      occluded_out[i] = occluded(o, d, tnear, far);
    }
  });
}

}  // namespace ptpb
