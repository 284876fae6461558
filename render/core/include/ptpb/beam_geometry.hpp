// Closest approach between a query ray and a photon beam (ptpb.md §4).
#pragma once
#include <cmath>

#include "ptpb/vec.hpp"

namespace ptpb {

struct ClosestApproach {
  double t = 0.0;       // query-ray parameter of the closest point, m
  double s = 0.0;       // beam parameter of the closest point, m
  double u = 0.0;       // distance between the two lines, m
  double sin2 = 0.0;    // sin^2 of the angle between the directions
};

// Unit directions; returns the infinite-line closest approach (sin2 == 0 means parallel).
inline ClosestApproach closest_approach(const Vec3d& xc, const Vec3d& wc, const Vec3d& xb,
                                        const Vec3d& wb) {
  ClosestApproach r;
  const Vec3d w = xc - xb;
  const Vec3d cr = cross(wc, wb);
  r.sin2 = dot(cr, cr);
  if (r.sin2 <= 0.0) return r;
  const double b = dot(wc, wb), d = dot(wc, w), e = dot(wb, w);
  r.t = (b * e - d) / r.sin2;
  r.s = (e - b * d) / r.sin2;
  r.u = std::fabs(dot(w, cr)) / std::sqrt(r.sin2);
  return r;
}

}  // namespace ptpb
