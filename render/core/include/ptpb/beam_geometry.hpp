// Closest approach between a query ray and a photon beam (DESIGN.md §4).
#pragma once
#include <cmath>

#include "ptpb/vec.hpp"

namespace ptpb {

struct ClosestApproach {
  double t = 0.0;     // query-ray parameter of the closest point, m
  double s = 0.0;     // beam parameter of the closest point, m
  double u = 0.0;     // distance between the two lines, m
  double sin2 = 0.0;  // sin^2 of the angle between the directions
};

// The closest approach before its divisions: t = t_num / sin2, s = s_num / sin2 and
// u = |w_cross| / sqrt(sin2). The beam structures test candidates with these (no division, no root).
struct ApproachNumerators {
  double sin2 = 0.0;
  double t_num = 0.0, s_num = 0.0;
  double w_cross = 0.0;  // w . (wc x wb), signed
};

inline ApproachNumerators closest_approach_numerators(const Vec3d& xc, const Vec3d& wc, const Vec3d& xb,
                                                      const Vec3d& wb) {
  ApproachNumerators n;
  const Vec3d w = xc - xb;
  const Vec3d cr = cross(wc, wb);
  n.sin2 = dot(cr, cr);
  const double b = dot(wc, wb), d = dot(wc, w), e = dot(wb, w);
  n.t_num = b * e - d;
  n.s_num = e - b * d;
  n.w_cross = dot(w, cr);
  return n;
}

// Unit directions; returns the infinite-line closest approach (sin2 == 0 means parallel).
inline ClosestApproach closest_approach(const Vec3d& xc, const Vec3d& wc, const Vec3d& xb, const Vec3d& wb) {
  ClosestApproach r;
  const ApproachNumerators n = closest_approach_numerators(xc, wc, xb, wb);
  r.sin2 = n.sin2;
  if (r.sin2 <= 0.0) return r;
  r.t = n.t_num / r.sin2;
  r.s = n.s_num / r.sin2;
  r.u = std::fabs(n.w_cross) / std::sqrt(r.sin2);
  return r;
}

}  // namespace ptpb
