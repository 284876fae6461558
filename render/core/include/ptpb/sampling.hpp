// Direction warps, the Henyey–Greenstein phase function and dielectric Fresnel (DESIGN.md §3).
#pragma once
#include <algorithm>
#include <cmath>

#include "ptpb/vec.hpp"

namespace ptpb {

constexpr double kPi = 3.14159265358979323846;
constexpr double kInvFourPi = 1.0 / (4.0 * kPi);
constexpr double kInvTwoPi = 1.0 / (2.0 * kPi);

// Orthonormal basis (s, t) completing the unit vector n (Duff et al. 2017).
inline void make_frame(const Vec3d& n, Vec3d& s, Vec3d& t) {
  const double sign = std::copysign(1.0, n.z);
  const double a = -1.0 / (sign + n.z);
  const double b = n.x * n.y * a;
  s = {1.0 + sign * n.x * n.x * a, sign * b, -sign * n.x};
  t = {b, sign + n.y * n.y * a, -n.y};
}

inline Vec3d from_frame(const Vec3d& n, double cos_theta, double phi) {
  Vec3d s, t;
  make_frame(n, s, t);
  const double sin_theta = std::sqrt(std::max(0.0, 1.0 - cos_theta * cos_theta));
  return s * (sin_theta * std::cos(phi)) + t * (sin_theta * std::sin(phi)) + n * cos_theta;
}

inline Vec3d sample_uniform_sphere(double u1, double u2) {
  const double z = 1.0 - 2.0 * u1;
  const double r = std::sqrt(std::max(0.0, 1.0 - z * z));
  const double phi = 2.0 * kPi * u2;
  return {r * std::cos(phi), r * std::sin(phi), z};
}

// Cosine-weighted direction around the unit normal n.
inline Vec3d sample_cosine_hemisphere(const Vec3d& n, double u1, double u2) {
  return from_frame(n, std::sqrt(1.0 - u1), 2.0 * kPi * u2);
}

// HG phase value for the cosine mu between incoming and outgoing propagation directions (1/sr).
inline double hg_eval(double mu, double g) {
  const double denom = 1.0 + g * g - 2.0 * g * mu;
  return kInvFourPi * (1.0 - g * g) / (denom * std::sqrt(denom));
}

// Cosine mu of an HG-distributed deflection; inverts the HG cumulative distribution.
inline double hg_sample_cos(double g, double u) {
  if (std::fabs(g) < 1e-3) return 1.0 - 2.0 * u;
  const double sq = (1.0 - g * g) / (1.0 - g + 2.0 * g * u);
  return std::clamp((1.0 + g * g - sq * sq) / (2.0 * g), -1.0, 1.0);
}

// New propagation direction after scattering from direction `incoming`; weight f/pdf is 1.
inline Vec3d hg_sample(const Vec3d& incoming, double g, double u1, double u2) {
  return normalize(from_frame(incoming, hg_sample_cos(g, u1), 2.0 * kPi * u2));
}

struct FresnelResult {
  double reflectance = 1.0;  // F, 1 under total internal reflection
  double cos_t = 0.0;        // |cos| of the refracted direction (0 under TIR)
};

// Unpolarised Fresnel reflectance for cos_i = |cos θ_i| > 0 and region indices n_i -> n_t.
inline FresnelResult fresnel_dielectric(double cos_i, double n_i, double n_t) {
  cos_i = std::clamp(cos_i, 0.0, 1.0);
  const double sin_t2 = (n_i / n_t) * (n_i / n_t) * std::max(0.0, 1.0 - cos_i * cos_i);
  if (sin_t2 >= 1.0) return {1.0, 0.0};
  const double cos_t = std::sqrt(1.0 - sin_t2);
  const double rs = (n_i * cos_i - n_t * cos_t) / (n_i * cos_i + n_t * cos_t);
  const double rp = (n_t * cos_i - n_i * cos_t) / (n_t * cos_i + n_i * cos_t);
  return {0.5 * (rs * rs + rp * rp), cos_t};
}

inline Vec3d reflect(const Vec3d& d, const Vec3d& n) { return d - n * (2.0 * dot(d, n)); }

// Refraction of unit direction d through a surface with unit normal n facing against d.
inline Vec3d refract(const Vec3d& d, const Vec3d& n_facing, double n_i, double n_t, double cos_t) {
  const double eta = n_i / n_t;
  const double cos_i = -dot(d, n_facing);
  return normalize(d * eta + n_facing * (eta * cos_i - cos_t));
}

// The camera side's stochastic Fresnel branch (§3, §7): reflects `dir` off the interface with
// probability F, or refracts it and scales the radiance `weight` by (n_i/n_t)^2. `u` is the branch's
// uniform draw; returns true when the ray crossed into the far side.
inline bool fresnel_branch(Vec3d& dir, Vec3d& weight, const Vec3d& facing, double n_i, double n_t, double u) {
  const FresnelResult fr = fresnel_dielectric(-dot(dir, facing), n_i, n_t);
  if (u < fr.reflectance) {
    dir = normalize(reflect(dir, facing));
    return false;
  }
  dir = refract(dir, facing, n_i, n_t, fr.cos_t);
  weight = weight * ((n_i / n_t) * (n_i / n_t));
  return true;
}

}  // namespace ptpb
