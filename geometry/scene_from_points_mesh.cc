#include "geometry/scene_from_points_mesh.h"

#include <CGAL/Advancing_front_surface_reconstruction.h>
#include <CGAL/Exact_predicates_inexact_constructions_kernel.h>
#include <CGAL/jet_smooth_point_set.h>

namespace procam {

void ReconstructMesh(const std::vector<Vec3>& points, const Vec3& viewpoint,
                     int smoothing_neighbors, std::vector<Vec3>* vertices,
                     std::vector<std::array<int, 3>>* triangles) {
  using Kernel = CGAL::Exact_predicates_inexact_constructions_kernel;
  using Point = Kernel::Point_3;
  std::vector<Point> cgal_points;
  cgal_points.reserve(points.size());
  for (const Vec3& p : points) cgal_points.emplace_back(p.x(), p.y(), p.z());
  // Jet smoothing moves each point onto the quadric fitted to its neighbours: the mesh then
  // follows the surface, not the noise (advancing front keeps every input point as a vertex).
  if (smoothing_neighbors > 0 && static_cast<int>(points.size()) > smoothing_neighbors) {
    CGAL::jet_smooth_point_set<CGAL::Sequential_tag>(cgal_points, smoothing_neighbors);
  }
  std::vector<std::array<std::size_t, 3>> facets;
  CGAL::advancing_front_surface_reconstruction(cgal_points.begin(), cgal_points.end(),
                                               std::back_inserter(facets));
  vertices->clear();
  for (const Point& p : cgal_points) vertices->emplace_back(p.x(), p.y(), p.z());
  triangles->clear();
  for (const std::array<std::size_t, 3>& facet : facets) {
    std::array<int, 3> t = {int(facet[0]), int(facet[1]), int(facet[2])};
    const Vec3& a = (*vertices)[t[0]];
    const Vec3 normal = ((*vertices)[t[1]] - a).cross((*vertices)[t[2]] - a);
    // The camera saw every triangle, so its lit side faces the camera.
    if (normal.dot(viewpoint - a) < 0) std::swap(t[1], t[2]);
    triangles->push_back(t);
  }
}

}  // namespace procam
