#pragma once
// Small planar-polygon geometry shared by scenes, patches and form factors.

#include <cstdint>
#include <string>
#include <unordered_map>
#include <vector>

#include <Eigen/Core>
#include <Eigen/Geometry>

namespace procam {

// Newell's normal of a polygon: direction = lit-side normal (counter-clockwise corners),
// length = 2 × area for a planar polygon.
Eigen::Vector3d NewellNormal(const Eigen::Vector3d* corners, int count);
double PolygonArea(const Eigen::Vector3d* corners, int count);
Eigen::Vector3d PolygonCentroid(const Eigen::Vector3d* corners, int count);

// True when the polygon is planar (every corner within `tolerance` metres of the plane),
// convex, wound consistently and not degenerate (no edge shorter than `tolerance`, area above
// tolerance²). Otherwise sets `why` to a one-line reason.
bool CheckPlanarConvexPolygon(const Eigen::Vector3d* corners, int count, double tolerance,
                              std::string* why);

// Merges points closer than a tolerance into one index (a hash grid with cells of the
// tolerance's size, so each lookup inspects the 27 cells around the point).
class PointWelder {
 public:
  explicit PointWelder(double tolerance) : tolerance_(tolerance) {}
  // Index of the point: an earlier point within the tolerance, or a new index.
  int Weld(const Eigen::Vector3d& point);
  const std::vector<Eigen::Vector3d>& points() const { return points_; }

 private:
  int64_t CellKey(int64_t x, int64_t y, int64_t z) const;
  double tolerance_;
  std::vector<Eigen::Vector3d> points_;
  std::unordered_multimap<int64_t, int> cells_;
};

}  // namespace procam
