#include "geometry/polygon.h"

#include <cmath>
#include <sstream>

namespace procam {

Eigen::Vector3d NewellNormal(const Eigen::Vector3d* corners, int count) {
  Eigen::Vector3d normal = Eigen::Vector3d::Zero();
  for (int k = 0; k < count; ++k) normal += corners[k].cross(corners[(k + 1) % count]);
  return normal;
}

double PolygonArea(const Eigen::Vector3d* corners, int count) {
  return 0.5 * NewellNormal(corners, count).norm();
}

Eigen::Vector3d PolygonCentroid(const Eigen::Vector3d* corners, int count) {
  // Area-weighted centroid of the fan triangles (exact for planar polygons).
  Eigen::Vector3d weighted = Eigen::Vector3d::Zero();
  double total = 0.0;
  for (int k = 1; k + 1 < count; ++k) {
    const double area = 0.5 * (corners[k] - corners[0]).cross(corners[k + 1] - corners[0]).norm();
    weighted += area * (corners[0] + corners[k] + corners[k + 1]) / 3.0;
    total += area;
  }
  if (total <= 0.0) {
    Eigen::Vector3d mean = Eigen::Vector3d::Zero();
    for (int k = 0; k < count; ++k) mean += corners[k];
    return mean / count;
  }
  return weighted / total;
}

bool CheckPlanarConvexPolygon(const Eigen::Vector3d* corners, int count, double tolerance,
                              std::string* why) {
  for (int k = 0; k < count; ++k) {
    if (!corners[k].allFinite()) {
      *why = "corner " + std::to_string(k) + " is not finite";
      return false;
    }
    if ((corners[(k + 1) % count] - corners[k]).norm() < tolerance) {
      *why = "degenerate: corners " + std::to_string(k) + " and " + std::to_string((k + 1) % count) +
             " coincide";
      return false;
    }
  }
  const Eigen::Vector3d newell = NewellNormal(corners, count);
  const double area = 0.5 * newell.norm();
  if (area <= tolerance * tolerance) {
    *why = "degenerate: zero area";
    return false;
  }
  const Eigen::Vector3d normal = newell.normalized();
  const Eigen::Vector3d centroid = PolygonCentroid(corners, count);
  for (int k = 0; k < count; ++k) {
    const double offset = std::abs(normal.dot(corners[k] - centroid));
    if (offset > tolerance) {
      std::ostringstream text;
      text << "not planar: corner " << k << " is " << offset << " m off the plane (tolerance "
           << tolerance << " m)";
      *why = text.str();
      return false;
    }
  }
  for (int k = 0; k < count; ++k) {
    const Eigen::Vector3d& a = corners[k];
    const Eigen::Vector3d& b = corners[(k + 1) % count];
    const Eigen::Vector3d& c = corners[(k + 2) % count];
    if ((b - a).cross(c - b).dot(normal) <= 0.0) {
      *why = "not convex (or corners out of order) at corner " + std::to_string((k + 1) % count);
      return false;
    }
  }
  return true;
}

int64_t PointWelder::CellKey(int64_t x, int64_t y, int64_t z) const {
  // Unsigned, so that the hash wraps as intended: cell indices reach 10^11 and more (coordinates
  // of 10^5 m at a tolerance of 10^-6 m), where the signed products overflowed (fuzz_obj).
  const auto mix = [](int64_t cell, uint64_t prime) { return static_cast<uint64_t>(cell) * prime; };
  return static_cast<int64_t>(mix(x, 73856093u) ^ mix(y, 19349663u) ^ mix(z, 83492791u));
}

int PointWelder::Weld(const Eigen::Vector3d& point) {
  const Eigen::Vector3d scaled = point / tolerance_;
  const int64_t cx = static_cast<int64_t>(std::floor(scaled.x()));
  const int64_t cy = static_cast<int64_t>(std::floor(scaled.y()));
  const int64_t cz = static_cast<int64_t>(std::floor(scaled.z()));
  for (int64_t dx = -1; dx <= 1; ++dx) {
    for (int64_t dy = -1; dy <= 1; ++dy) {
      for (int64_t dz = -1; dz <= 1; ++dz) {
        auto range = cells_.equal_range(CellKey(cx + dx, cy + dy, cz + dz));
        for (auto it = range.first; it != range.second; ++it) {
          if ((points_[it->second] - point).norm() <= tolerance_) return it->second;
        }
      }
    }
  }
  const int index = static_cast<int>(points_.size());
  points_.push_back(point);
  cells_.emplace(CellKey(cx, cy, cz), index);
  return index;
}

}  // namespace procam
