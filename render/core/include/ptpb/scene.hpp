// Plain scene description consumed by the PTPB renderer: media, shapes, lights, camera, film.
// Everything is in metres; colours are linear RGB. Built by the Python face or by tests.
#pragma once
#include <cmath>
#include <cstdint>
#include <string>
#include <vector>

#include "ptpb/vec.hpp"

namespace ptpb {

constexpr int kVacuum = -1;  // medium id of the empty surroundings

// Homogeneous medium with a Henyey–Greenstein phase function; `ior` is its group/region index.
struct Medium {
  Vec3d sigma_s{0, 0, 0};  // 1/m per channel
  Vec3d sigma_a{0, 0, 0};  // 1/m per channel
  double g = 0.0;
  double ior = 1.0;
  Vec3d sigma_t() const { return sigma_s + sigma_a; }
};

enum class SurfaceKind {
  Null,        // index-matched boundary: only the current medium changes
  Dielectric,  // smooth Fresnel interface between the region indices of the two sides
  Diffuse,     // Lambertian reflector with `albedo`
};

// Closed (or open, for emitters) triangle mesh. The CCW winding gives the outward normal;
// `interior`/`exterior` are medium ids on the two sides (kVacuum for none).
struct Shape {
  std::vector<float> vertices;       // N x 3
  std::vector<std::uint32_t> faces;  // M x 3
  SurfaceKind kind = SurfaceKind::Null;
  int interior = kVacuum;
  int exterior = kVacuum;
  Vec3d albedo{0, 0, 0};    // Diffuse only
  Vec3d radiance{0, 0, 0};  // area emission, one-sided along the outward normal (W m^-2 sr^-1)
  // K x 3 translations (m): the mesh stands at each of them, traced as instances of one copy (DESIGN.md §13);
  // empty: once, where its vertices are. Together the copies (with any other shapes) must close the medium.
  std::vector<double> offsets;
  bool is_emitter() const { return radiance.x > 0 || radiance.y > 0 || radiance.z > 0; }
};

struct PointLight {
  Vec3d position{0, 0, 0};
  Vec3d intensity{0, 0, 0};  // W/sr
  int medium = kVacuum;
};

// Plane wave from direction `to_sun`; the time origin is the plane Pi_0 of DESIGN.md §1. With a
// `beam_radius` w > 0 it is a collimated Gaussian beam, a laser: irradiance exp(-2 r^2 / w^2) times
// `irradiance` at the distance r from the axis through `beam_center` along to_sun.
struct DirectionalLight {
  Vec3d to_sun{0, 0, 1};
  Vec3d irradiance{0, 0, 0};  // W/m^2 on a plane perpendicular to to_sun (on the axis for a beam)
  bool has_reference_point = false;
  Vec3d reference_point{0, 0, 0};
  double beam_radius = 0.0;  // 1/e^2 radius of a Gaussian beam [m]; 0: uniform
  Vec3d beam_center{0, 0, 0};
  // The beam's profile at p: 1 for a uniform plane wave.
  double profile(const Vec3d& p) const {
    if (!(beam_radius > 0)) return 1.0;
    const Vec3d s = normalize(to_sun), d = p - beam_center;
    const Vec3d across = d - s * dot(d, s);
    return std::exp(-2.0 * dot(across, across) / (beam_radius * beam_radius));
  }
};

enum class Projection { Perspective, Orthographic };

// Mitsuba-compatible camera (look-at frame, film y downward): a pinhole, or an orthographic receiver
// whose parallel rays leave the plane through `origin` facing `target`; that plane is its time origin
// (DESIGN.md §1).
struct Camera {
  Vec3d origin{0, 0, 0}, target{0, 0, 1}, up{0, 1, 0};
  Projection projection = Projection::Perspective;
  double fov_deg = 40.0;
  std::string fov_axis = "x";  // x | y | diagonal | smaller | larger
  double ortho_width = 0.0;    // orthographic: the film's width in metres (its height follows the aspect)
  int width = 64, height = 64;
  int medium = kVacuum;  // medium containing the pinhole
};

enum class FrameMode { Steady, Bins, Gate };

struct Film {
  FrameMode mode = FrameMode::Steady;
  int temporal_bins = 0;
  double start_opl = 0.0;        // m
  double bin_width_opl = 0.003;  // m
  // The frames one pass holds (DESIGN.md §9 "Windows"): [window_first, window_first + window_count) of
  // the temporal_bins, the rest dropped; window_count < 0 holds all from window_first on. Early and late
  // stay relative to the whole film, so windows rendered in turn join into the single-pass film.
  int window_first = 0;
  int window_count = -1;
};

struct Scene {
  std::vector<Medium> media;
  std::vector<Shape> shapes;
  std::vector<PointLight> point_lights;
  std::vector<DirectionalLight> directional_lights;
  Vec3d environment_radiance{0, 0, 0};  // constant sky; steady image only (no time origin)
  // Next-event estimation samples the sky over the hemisphere around this unit vector (zero: the whole
  // sphere); the rest of the sky is still reached by sampled directions (DESIGN.md §12).
  Vec3d environment_up{0, 0, 0};
  double ambient_ior = 1.0;  // region index of the surroundings (kVacuum)
  Camera camera;
  Film film;
};

}  // namespace ptpb
