// The BVH's leaf test (beam_bvh.cpp, DESIGN.md §8): the pieces' lines in float, and the closest-approach
// test on them without divisions, one piece or four at a time (SSE). Private to the core's sources.
#pragma once
#if defined(__SSE2__)
#include <emmintrin.h>
#endif

#include <algorithm>
#include <cmath>
#include <cstdint>

#include "beam_accel_shared.hpp"

namespace ptpb::accel_detail {

// After the build, each piece's slot holds the piece's own line in float (PieceLine) instead of
// its build box: the leaf's exact test then reads 32 contiguous bytes instead of the beam record,
// and needs no division for the piece's share of the beam.
struct PieceLine {
  float origin[3];     // the piece's start, relative to the structure's anchor
  float direction[3];  // the beam's direction
  float length;        // the piece's share [0, length) of the beam parameter, from its start
  std::uint32_t beam;
};

// A query in the float frame of the piece lines, with the margin that makes its test looser than
// the exact one in double: kCandidateSlack (beam_accel.hpp) of `span`, which bounds
// |origin - piece start|, t_max and 4R. The rounding of the coordinates (relative to the anchor)
// and of the products that form t_num, s_num, w_cross and the bounds stays below ~3e-6 of it.
struct FloatQuery {
  float origin[3], direction[3];
  float t_max, radius, margin;
};

// The division-free closest-approach test (the grid's pair_candidate) in float, with the ownership of the
// piece's share of s: true for near-parallel pieces, and for pieces whose closest approach has t
// in [0, t_max], s in [0, length) and u < R, each widened by the margin. Neighbouring pieces may
// then both report a beam whose s lies near their common boundary; BeamBvh::query drops the repeat.
inline bool float_candidate(const FloatQuery& q, const PieceLine& p) {
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
inline FloatQuery4 broadcast(const FloatQuery& q) {
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
inline int float_candidates4(const FloatQuery4& q, const PieceLine* p) {
  const float* f = reinterpret_cast<const float*>(p);
  __m128 ox = _mm_loadu_ps(f), oy = _mm_loadu_ps(f + 8), oz = _mm_loadu_ps(f + 16), bx = _mm_loadu_ps(f + 24);
  __m128 by = _mm_loadu_ps(f + 4), bz = _mm_loadu_ps(f + 12), len = _mm_loadu_ps(f + 20), beam = _mm_loadu_ps(f + 28);
  _MM_TRANSPOSE4_PS(ox, oy, oz, bx);     // rows: origin x, y, z and direction x of the 4 pieces
  _MM_TRANSPOSE4_PS(by, bz, len, beam);  // rows: direction y, z, length and the beam's bits
  const __m128 wx = _mm_sub_ps(q.origin[0], ox), wy = _mm_sub_ps(q.origin[1], oy), wz = _mm_sub_ps(q.origin[2], oz);
  const __m128* c = q.direction;
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

}  // namespace ptpb::accel_detail
