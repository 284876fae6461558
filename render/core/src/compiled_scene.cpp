// Scene validation, the Embree triangle scene and emission sampling.
#include "ptpb/compiled_scene.hpp"

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>

#include "ptpb/sampling.hpp"

namespace ptpb {
namespace {

double mean(const Vec3d& v) { return (v.x + v.y + v.z) / 3.0; }
bool finite_nonneg(const Vec3d& v) { return all_finite(v) && v.x >= 0 && v.y >= 0 && v.z >= 0; }

void require(bool ok, const std::string& what) {
  if (!ok) throw std::invalid_argument(what);
}

void require_medium_id(int id, std::size_t count, const std::string& where) {
  require(
      id == kVacuum || (id >= 0 && static_cast<std::size_t>(id) < count),
      where + ": medium id " + std::to_string(id) + " out of range (" + std::to_string(count) + " media; -1 = vacuum)");
}

Vec3d vertex(const Shape& s, std::uint32_t i) {
  return {s.vertices[3 * i], s.vertices[3 * i + 1], s.vertices[3 * i + 2]};
}

}  // namespace

CompiledScene::CompiledScene(const Scene& scene) : scene_(scene) {
  require(std::isfinite(scene.ambient_ior) && scene.ambient_ior > 0, "ambient_ior must be > 0");
  for (std::size_t i = 0; i < scene.media.size(); ++i) {
    const Medium& m = scene.media[i];
    const std::string where = "media[" + std::to_string(i) + "]";
    require(finite_nonneg(m.sigma_s), where + ".sigma_s must be finite and >= 0");
    require(finite_nonneg(m.sigma_a), where + ".sigma_a must be finite and >= 0");
    require(std::isfinite(m.g) && std::fabs(m.g) < 1.0, where + ".g must lie in (-1, 1)");
    require(std::isfinite(m.ior) && m.ior > 0, where + ".ior must be > 0");
    has_scattering_.push_back(max_component(m.sigma_s) > 0);
    has_extinction_.push_back(max_component(m.sigma_t()) > 0);
  }
  std::size_t mesh_id = 0;
  Vec3d lo{1e300, 1e300, 1e300}, hi{-1e300, -1e300, -1e300};
  for (const Shape& s : scene.shapes) {
    const std::string where = "shapes[" + std::to_string(mesh_id) + "]";
    require(!s.vertices.empty() && !s.faces.empty(), where + ": the mesh is empty (no vertices or no faces)");
    require(s.vertices.size() % 3 == 0, where + ".vertices must be N x 3");
    require(s.faces.size() % 3 == 0, where + ".faces must be M x 3");
    for (std::size_t k = 0; k < s.vertices.size(); ++k)
      require(std::isfinite(s.vertices[k]), where + ".vertices[" + std::to_string(k / 3) + "] is NaN or infinite");
    for (std::size_t k = 0; k < s.faces.size(); ++k)
      require(s.faces[k] < s.vertices.size() / 3, where + ".faces[" + std::to_string(k / 3) + "] refers to vertex " +
                                                      std::to_string(s.faces[k]) + ", but the mesh has " +
                                                      std::to_string(s.vertices.size() / 3) + " vertices");
    require_medium_id(s.interior, scene.media.size(), where + ".interior");
    require_medium_id(s.exterior, scene.media.size(), where + ".exterior");
    require(finite_nonneg(s.radiance), where + ".radiance must be finite and >= 0");
    if (s.kind == SurfaceKind::Diffuse) {
      require(finite_nonneg(s.albedo) && max_component(s.albedo) <= 1.0, where + ".albedo must lie in [0, 1]");
      if (max_component(s.albedo) > 0) has_diffuse_reflectors_ = true;
    }
    Vec3d shape_lo{1e300, 1e300, 1e300}, shape_hi{-1e300, -1e300, -1e300};
    for (std::size_t k = 0; k < s.vertices.size(); k += 3) {
      for (int a = 0; a < 3; ++a) {
        shape_lo[a] = std::min(shape_lo[a], double(s.vertices[k + a]));
        shape_hi[a] = std::max(shape_hi[a], double(s.vertices[k + a]));
      }
    }
    if (s.offsets.empty()) {
      rays_.add_mesh(s.vertices.data(), s.vertices.size() / 3, s.faces.data(), s.faces.size() / 3,
                     static_cast<std::uint32_t>(mesh_id));
      for (int a = 0; a < 3; ++a) lo[a] = std::min(lo[a], shape_lo[a]), hi[a] = std::max(hi[a], shape_hi[a]);
    } else {
      require(s.offsets.size() % 3 == 0, where + ".offsets must be K x 3");
      require(!s.is_emitter(), where + ": an instanced shape (offsets) cannot emit; give the emitter its own mesh");
      rays_.add_instanced_mesh(s.vertices.data(), s.vertices.size() / 3, s.faces.data(), s.faces.size() / 3,
                               s.offsets.data(), s.offsets.size() / 3, static_cast<std::uint32_t>(mesh_id));
      for (std::size_t k = 0; k < s.offsets.size(); k += 3) {
        for (int a = 0; a < 3; ++a) {
          lo[a] = std::min(lo[a], shape_lo[a] + s.offsets[k + a]);
          hi[a] = std::max(hi[a], shape_hi[a] + s.offsets[k + a]);
        }
      }
    }
    // Area emitters: triangle cdf for uniform position sampling.
    std::vector<double> cdf;
    double area = 0.0;
    if (s.is_emitter()) {
      for (std::size_t f = 0; f < s.faces.size(); f += 3) {
        const Vec3d a = vertex(s, s.faces[f]), b = vertex(s, s.faces[f + 1]), c = vertex(s, s.faces[f + 2]);
        area += 0.5 * length(cross(b - a, c - a));
        cdf.push_back(area);
      }
      require(area > 0, where + ": emitter has zero area");
      lights_.push_back({1, mesh_id, kPi * area * mean(s.radiance)});
    }
    triangle_cdf_.push_back(std::move(cdf));
    shape_area_.push_back(area);
    ++mesh_id;
  }
  rays_.commit();
  if (scene.shapes.empty()) {
    lo = hi = Vec3d{0, 0, 0};
  }
  // Mitsuba's bounding sphere of the shapes' bounding box (DESIGN.md §1).
  sphere_center_ = (lo + hi) * 0.5;
  sphere_radius_ = std::max(length(hi - sphere_center_), 1e-4);
  ray_epsilon_ =
      1e-6 * std::max(1.0, std::max(max_component(Vec3d{std::fabs(lo.x), std::fabs(lo.y), std::fabs(lo.z)}),
                                    max_component(Vec3d{std::fabs(hi.x), std::fabs(hi.y), std::fabs(hi.z)})));
  ray_epsilon_ *= 10.0;

  for (std::size_t i = 0; i < scene.point_lights.size(); ++i) {
    const PointLight& l = scene.point_lights[i];
    const std::string where = "point_lights[" + std::to_string(i) + "]";
    require(all_finite(l.position), where + ".position must be finite");
    require(finite_nonneg(l.intensity), where + ".intensity must be finite and >= 0");
    require_medium_id(l.medium, scene.media.size(), where + ".medium");
    lights_.push_back({0, i, 4.0 * kPi * mean(l.intensity)});
  }
  for (std::size_t i = 0; i < scene.directional_lights.size(); ++i) {
    const DirectionalLight& l = scene.directional_lights[i];
    const std::string where = "directional_lights[" + std::to_string(i) + "]";
    require(all_finite(l.to_sun) && length(l.to_sun) > 0, where + ".to_sun must be a non-zero vector");
    require(finite_nonneg(l.irradiance), where + ".irradiance must be finite and >= 0");
    require(!l.has_reference_point || all_finite(l.reference_point), where + ".reference_point must be finite");
    require(std::isfinite(l.beam_radius) && l.beam_radius >= 0 && all_finite(l.beam_center),
            where + ".beam_radius must be >= 0 m (0: a uniform sun) and beam_center finite");
    // A beam's power is the Gaussian's integral, pi w^2 / 2 times its irradiance on the axis.
    const double area =
        l.beam_radius > 0 ? 0.5 * kPi * l.beam_radius * l.beam_radius : kPi * sphere_radius_ * sphere_radius_;
    lights_.push_back({2, i, area * mean(l.irradiance)});
  }
  require(finite_nonneg(scene.environment_radiance), "environment_radiance must be finite and >= 0");
  require(all_finite(scene.environment_up), "environment_up must be finite (zero: sample the whole sky)");
  if (length(scene.environment_up) > 0) sky_up_ = normalize(scene.environment_up);
  if (max_component(scene.environment_radiance) > 0) {
    // Constant sky: flux through the bounding disk from every direction, L * pi R^2 * 4 pi; from the
    // sampled hemisphere only (L * pi R^2 * 2 pi) when it has an up direction (DESIGN.md §12).
    const double solid_angle = length(sky_up_) > 0 ? 2.0 * kPi : 4.0 * kPi;
    lights_.push_back({3, 0, solid_angle * kPi * sphere_radius_ * sphere_radius_ * mean(scene.environment_radiance)});
  }
  for (const LightEntry& e : lights_) {
    total_power_ += e.power;
    light_cdf_.push_back(total_power_);
  }
  bool dielectric = false;
  for (const Shape& s : scene.shapes) dielectric |= s.kind == SurfaceKind::Dielectric;
  for (const LightEntry& e : lights_)
    has_specular_delta_light_ |= dielectric && (e.kind == 0 || e.kind == 2) && e.power > 0;
  area_light_pick_.assign(scene.shapes.size(), 0.0);
  if (total_power_ > 0) {
    for (const LightEntry& e : lights_) {
      if (e.kind == 1) area_light_pick_[e.index] = e.power / total_power_;
      if (e.kind == 3) sky_pick_ = e.power / total_power_;
    }
  }
  const Camera& cam = scene.camera;
  require(cam.width > 0 && cam.height > 0, "camera width and height must be > 0");
  if (cam.projection == Projection::Orthographic)
    require(std::isfinite(cam.ortho_width) && cam.ortho_width > 0,
            "camera ortho_width must be a positive width in metres for an orthographic camera");
  else
    require(cam.fov_deg > 0 && cam.fov_deg < 180, "camera fov must lie in (0, 180) degrees");
  require(cam.fov_axis == "x" || cam.fov_axis == "y" || cam.fov_axis == "diagonal" || cam.fov_axis == "smaller" ||
              cam.fov_axis == "larger",
          "camera fov_axis must be x, y, diagonal, smaller or larger, got '" + cam.fov_axis + "'");
  require(all_finite(cam.origin) && all_finite(cam.target) && all_finite(cam.up), "camera vectors must be finite");
  require(length(cam.target - cam.origin) > 0, "camera target must differ from its origin");
  require(length(cross(cam.up, cam.target - cam.origin)) > 0, "camera up must not be parallel to the view direction");
  require_medium_id(cam.medium, scene.media.size(), "camera.medium");
  const Film& film = scene.film;
  if (film.mode != FrameMode::Steady) {
    require(film.temporal_bins > 0, "film.temporal_bins must be > 0 in bins/gate mode");
    require(std::isfinite(film.bin_width_opl) && film.bin_width_opl > 0, "film.bin_width_opl must be > 0");
    require(std::isfinite(film.start_opl), "film.start_opl must be finite");
    require(film.window_first >= 0 && film.window_first < film.temporal_bins,
            "film.window_first must lie in [0, temporal_bins)");
    require(film.window_count != 0, "film.window_count must be > 0 (or < 0: every frame from window_first on)");
  }
}

SurfaceHit CompiledScene::intersect(const Vec3d& origin, const Vec3d& direction, bool from_medium) const {
  SurfaceHit out;
  const Hit h = rays_.intersect(Vec3f(origin), Vec3f(direction), from_medium ? 0.0f : static_cast<float>(ray_epsilon_));
  if (!h.valid()) return out;
  out.valid = true;
  out.t = h.t;
  out.position = origin + direction * out.t;
  out.normal = Vec3d(h.normal);
  out.entering = dot(direction, out.normal) < 0;
  out.shape = h.mesh_id;
  const Shape& s = scene_.shapes[h.mesh_id];
  out.medium_before = out.entering ? s.exterior : s.interior;
  out.medium_after = out.entering ? s.interior : s.exterior;
  return out;
}

void CompiledScene::sample_area_point(std::size_t shape, KeyedRng& rng, Vec3d& point, Vec3d& normal) const {
  const Shape& s = scene_.shapes[shape];
  const auto& cdf = triangle_cdf_[shape];
  const double ta = rng.next_double() * shape_area_[shape];
  std::size_t f = std::upper_bound(cdf.begin(), cdf.end(), ta) - cdf.begin();
  f = std::min(f, cdf.size() - 1);
  const Vec3d a = vertex(s, s.faces[3 * f]), b = vertex(s, s.faces[3 * f + 1]), c = vertex(s, s.faces[3 * f + 2]);
  const double su = std::sqrt(rng.next_double()), v = rng.next_double();
  point = a * (1.0 - su) + b * (su * (1.0 - v)) + c * (su * v);
  normal = normalize(cross(b - a, c - a));
}

bool CompiledScene::sample_emission(KeyedRng& rng, LightSample& out) const {
  if (lights_.empty() || !(total_power_ > 0)) return false;
  const double target = rng.next_double() * total_power_;
  std::size_t li = std::upper_bound(light_cdf_.begin(), light_cdf_.end(), target) - light_cdf_.begin();
  li = std::min(li, lights_.size() - 1);
  const LightEntry& e = lights_[li];
  if (!(e.power > 0)) return false;
  const double pick = e.power / total_power_;
  const double u1 = rng.next_double(), u2 = rng.next_double();
  if (e.kind == 0) {
    const PointLight& l = scene_.point_lights[e.index];
    out.origin = l.position;
    out.direction = sample_uniform_sphere(u1, u2);
    out.power = l.intensity * (4.0 * kPi / pick);
    out.medium = l.medium;
    out.delta = true;
  } else if (e.kind == 1) {
    const Shape& s = scene_.shapes[e.index];
    Vec3d normal;
    sample_area_point(e.index, rng, out.origin, normal);
    out.direction = sample_cosine_hemisphere(normal, u1, u2);
    out.power = s.radiance * (kPi * shape_area_[e.index] / pick);
    out.medium = s.exterior;
  } else if (e.kind == 3) {
    const Vec3d travel = sample_uniform_sphere(u1, u2);
    Vec3d e1, e2;
    make_frame(travel, e1, e2);
    const double r = sphere_radius_ * std::sqrt(rng.next_double()), phi = 2.0 * kPi * rng.next_double();
    out.origin = sphere_center_ - travel * sphere_radius_ + e1 * (r * std::cos(phi)) + e2 * (r * std::sin(phi));
    out.direction = travel;
    out.power = scene_.environment_radiance * (4.0 * kPi * kPi * sphere_radius_ * sphere_radius_ / pick);
    out.medium = kVacuum;
    out.timeless = true;
  } else {
    const DirectionalLight& l = scene_.directional_lights[e.index];
    const Vec3d s = normalize(l.to_sun);
    // Pi_0 passes through C + R s, or through the pinned reference point.
    const double plane_offset = l.has_reference_point ? dot(l.reference_point - sphere_center_, s) : sphere_radius_;
    const Vec3d disk_center = sphere_center_ + s * plane_offset;
    Vec3d e1, e2;
    make_frame(s, e1, e2);
    if (l.beam_radius > 0) {
      // A Gaussian beam: its profile is a normal distribution of sigma w/2 across the axis (Box-Muller), and
      // every photon carries the beam's power over the number drawn.
      const Vec3d axis_on_plane = l.beam_center + s * dot(disk_center - l.beam_center, s);
      const double r = 0.5 * l.beam_radius * std::sqrt(-2.0 * std::log1p(-u1)), phi = 2.0 * kPi * u2;
      out.origin = axis_on_plane + e1 * (r * std::cos(phi)) + e2 * (r * std::sin(phi));
      out.power = l.irradiance * (0.5 * kPi * l.beam_radius * l.beam_radius / pick);
    } else {
      const double r = sphere_radius_ * std::sqrt(u1), phi = 2.0 * kPi * u2;
      out.origin = disk_center + e1 * (r * std::cos(phi)) + e2 * (r * std::sin(phi));
      out.power = l.irradiance * (kPi * sphere_radius_ * sphere_radius_ / pick);
    }
    out.direction = -s;
    out.medium = kVacuum;
    out.delta = true;
  }
  return true;
}

}  // namespace ptpb
