// Conversions between optical path length (the core's time axis, metres) and seconds.
#pragma once

namespace ptpb {

constexpr double kSpeedOfLight = 299792458.0;                     // m/s, exact
constexpr double kPicosecondsPerMetreOpl = 1e12 / kSpeedOfLight;  // 3335.640952 ps per metre of OPL

inline double opl_to_seconds(double opl_m) { return opl_m / kSpeedOfLight; }
inline double opl_to_picoseconds(double opl_m) { return opl_m * kPicosecondsPerMetreOpl; }
inline double picoseconds_to_opl(double ps) { return ps / kPicosecondsPerMetreOpl; }

}  // namespace ptpb
