// Exit tables of the scattering-only random walk in a ball (DESIGN.md §12, "Hops").
#include "ptpb/hops.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <mutex>
#include <thread>
#include <vector>

#include "ptpb/rng.hpp"
#include "ptpb/sampling.hpp"
#include "ptpb/vec.hpp"

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
// costs a few dozen steps an exit instead of R^2/2; next to the sphere it takes single flights.
HopExit walk_in_ball(int k, KeyedRng& rng) {
  const double R = hop_radius(k);
  Vec3d pos{};
  double travelled = 0.0;
  std::uint64_t scatterings = 0;
  bool first = true;  // the scattering at the centre is the walk's start, not one of its inner events
  for (;;) {
    // At a scattering event at pos: the direction of the next flight, or a hop to a point further on.
    Vec3d dir;
    const double room = R - length(pos);
    int j = k - 1;
    while (j >= 0 && hop_radius(j) > room) --j;
    if (!first) ++scatterings;
    first = false;
    if (j >= 0) {
      const Table& t = table(j);
      const HopExit& e = t.exits[static_cast<std::size_t>(rng.next_double() * kHopSamples)];
      const Vec3d normal = sample_uniform_sphere(rng.next_double(), rng.next_double());
      pos = pos + normal * hop_radius(j);
      dir = from_frame(normal, e.cosine, 2.0 * kPi * rng.next_double());
      travelled += e.length;
      scatterings += e.scatterings;
    } else {
      dir = sample_uniform_sphere(rng.next_double(), rng.next_double());
    }
    const double s = -std::log1p(-rng.next_double());
    const double exit = to_sphere(pos, dir, R);
    if (s >= exit) {
      const Vec3d at = pos + dir * exit;
      HopExit out;
      out.length = static_cast<float>(travelled + exit);
      out.cosine = static_cast<float>(std::min(1.0, std::max(0.0, dot(dir, at) / R)));
      out.scatterings = static_cast<std::uint32_t>(std::min<std::uint64_t>(scatterings, 0xFFFFFFFFu));
      return out;
    }
    pos = pos + dir * s;
    travelled += s;
  }
}

const Table& table(int k) {
  std::call_once(g_built[static_cast<std::size_t>(k)], [k] {
    Table& t = g_tables[static_cast<std::size_t>(k)];
    if (k > 0) table(k - 1);  // built first, outside this table's threads
    t.exits.resize(kHopSamples);
    // Every exit has its own keyed stream, so the table is the same whatever the number of threads.
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

HopExit sample_hop(int k, double u) {
  const auto i = std::min<std::size_t>(static_cast<std::size_t>(u * kHopSamples), kHopSamples - 1);
  return table(k).exits[i];
}

double hop_mean_scatterings(int k) { return table(k).mean_scatterings; }

}  // namespace ptpb
