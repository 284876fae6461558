// Walk tables for hops across surface-free balls (DESIGN.md §12, "Hops").
#include "ptpb/hops.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <mutex>
#include <thread>
#include <vector>

#include "ptpb/rng.hpp"
#include "ptpb/sampling.hpp"

namespace ptpb {
namespace {

struct Table {
  std::vector<HopExit> exits;
  double mean_scatterings = 0.0;
};

std::array<Table, kHopTables> g_tables;
std::array<std::once_flag, kHopTables> g_built;

const Table& table(int k);

// Distance along the unit direction d from p (|p| < R) to the sphere of radius R about the origin.
double to_sphere(const Vec3d& p, const Vec3d& d, double R) {
  const double b = dot(p, d);
  const double c = dot(p, p) - R * R;
  return -b + std::sqrt(std::max(0.0, b * b - c));
}

// One walk from the centre of the ball of radius R_k, in scattering lengths. After a scattering event the
// walk takes a hop of the largest smaller table that fits inside what is left of the ball, so a table
// costs a few dozen steps a walk instead of R^2/2; next to the sphere it takes single flights. The inner
// event J is kept by weighted reservoir sampling over items: each single event with w = exp(|z| - R), and
// each smaller hop as one item standing for its own inner events, with w = factor_sub exp(|z_Jsub| - R)
// (an unbiased estimate of their total weight). Picking items in proportion to w and multiplying by
// (sum of w) / w keeps factor * g(z_J) unbiased for the sum over every inner event.
HopExit walk_in_ball(int k, KeyedRng& rng) {
  const double R = hop_radius(k);
  Vec3d pos{};
  double travelled = 0.0, weight_sum = 0.0;
  std::uint64_t scatterings = 0;
  Vec3d kept{};  // z_J in the table's own frame
  double kept_length = 0.0;
  std::uint64_t kept_scatterings = 0;
  double last_start = 0.0;  // path length at the last inner event
  auto offer = [&](double w, const Vec3d& z, double length, std::uint64_t n) {
    weight_sum += w;
    if (w > 0 && rng.next_double() * weight_sum < w) {
      kept = z;
      kept_length = length;
      kept_scatterings = n;
    }
  };
  bool first = true;  // the scattering at the centre is the walk's start, not one of its inner events
  for (;;) {
    // At a scattering event at pos: the direction of the next flight, or a hop to a point further on.
    Vec3d dir;
    if (!first) {
      ++scatterings;
      last_start = travelled;
      offer(std::exp(length(pos) - R), pos, travelled, scatterings);
    }
    first = false;
    const double room = R - length(pos);
    int j = k - 1;
    while (j >= 0 && hop_radius(j) > room) --j;
    if (j >= 0) {
      const HopExit& e = sample_hop(j, rng.next_double());
      const double u1 = rng.next_double(), u2 = rng.next_double(), u3 = rng.next_double();
      const HopFrame frame(u1, u2, u3);
      if (e.scatterings > 0) {
        const Vec3d z = pos + frame.vertex(e);
        offer(e.factor * std::exp(length(z) - R), z, travelled + e.vertex_length, scatterings + e.vertex_scatterings);
        last_start = travelled + e.length - e.last;
      }
      pos = pos + frame.normal * hop_radius(j);
      dir = frame.direction(e);
      travelled += e.length;
      scatterings += e.scatterings;
    } else {
      const double u1 = rng.next_double(), u2 = rng.next_double();
      dir = sample_uniform_sphere(u1, u2);
    }
    const double s = -std::log1p(-rng.next_double());
    const double exit = to_sphere(pos, dir, R);
    if (s >= exit) {
      const Vec3d at = pos + dir * exit;
      const Vec3d e3 = at / R;
      HopExit out;
      out.length = static_cast<float>(travelled + exit);
      out.cosine = static_cast<float>(std::min(1.0, std::max(0.0, dot(dir, e3))));
      out.scatterings = static_cast<std::uint32_t>(std::min<std::uint64_t>(scatterings, 0xFFFFFFFFu));
      out.last = static_cast<float>(travelled + exit - last_start);
      if (scatterings > 0) {
        // The exit frame: e1 along the exit direction's part across the normal.
        Vec3d e1 = dir - e3 * dot(dir, e3);
        const double across = length(e1);
        if (across > 1e-12) {
          e1 = e1 / across;
        } else {
          Vec3d t;
          make_frame(e3, e1, t);
        }
        const Vec3d e2 = cross(e3, e1);
        out.factor = static_cast<float>(weight_sum / std::exp(length(kept) - R));
        out.vertex_length = static_cast<float>(kept_length);
        out.vertex_scatterings = static_cast<std::uint32_t>(std::min<std::uint64_t>(kept_scatterings, 0xFFFFFFFFu));
        out.vertex[0] = static_cast<float>(dot(kept, e1));
        out.vertex[1] = static_cast<float>(dot(kept, e2));
        out.vertex[2] = static_cast<float>(dot(kept, e3));
      }
      return out;
    }
    pos = pos + dir * s;
    travelled += s;
  }
}

const Table& table(int k) {
  std::call_once(g_built[static_cast<std::size_t>(k)], [k] {
    if (k > 0) table(k - 1);  // built first, outside this table's threads
    Table& t = g_tables[static_cast<std::size_t>(k)];
    t.exits.resize(kHopSamples);
    // Every walk has its own keyed stream, so the table is the same whatever the number of threads.
    const unsigned threads = std::max(1u, std::min(8u, std::thread::hardware_concurrency()));
    std::vector<std::thread> pool;
    for (unsigned w = 0; w < threads; ++w)
      pool.emplace_back([&t, k, w, threads] {
        for (std::size_t i = w; i < kHopSamples; i += threads) {
          KeyedRng rng(0x5EED0F5E11ull, static_cast<std::uint64_t>(k), StreamDomain::HopTable, i);
          t.exits[i] = walk_in_ball(k, rng);
        }
      });
    for (std::thread& th : pool) th.join();
    double sum = 0.0;
    for (const HopExit& e : t.exits) sum += e.scatterings;
    t.mean_scatterings = sum / kHopSamples;
  });
  return g_tables[static_cast<std::size_t>(k)];
}

}  // namespace

double hop_radius(int k) { return 2.0 * std::exp2(0.5 * k); }

const HopExit& sample_hop(int k, double u) {
  const auto i = std::min<std::size_t>(static_cast<std::size_t>(u * kHopSamples), kHopSamples - 1);
  return table(k).exits[i];
}

double hop_mean_scatterings(int k) { return table(k).mean_scatterings; }

HopFrame::HopFrame(double u1, double u2, double u3) : normal(sample_uniform_sphere(u1, u2)) {
  Vec3d s, t;
  make_frame(normal, s, t);
  const double phi = 2.0 * kPi * u3;
  e1 = s * std::cos(phi) + t * std::sin(phi);
  e2 = cross(normal, e1);
}

Vec3d HopFrame::direction(const HopExit& e) const {
  const double cosine = e.cosine;
  return normal * cosine + e1 * std::sqrt(std::max(0.0, 1.0 - cosine * cosine));
}

Vec3d HopFrame::vertex(const HopExit& e) const { return e1 * e.vertex[0] + e2 * e.vertex[1] + normal * e.vertex[2]; }

}  // namespace ptpb
