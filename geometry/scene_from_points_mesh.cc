#include "geometry/scene_from_points_mesh.h"

#include <CGAL/Advancing_front_surface_reconstruction.h>
#include <CGAL/Exact_predicates_inexact_constructions_kernel.h>
#include <CGAL/grid_simplify_point_set.h>
#include <CGAL/jet_smooth_point_set.h>

namespace procam {

void ReconstructMesh(const std::vector<Vec3>& points, const Vec3& viewpoint, int smoothing_neighbors,
                     double vertex_spacing, double simplify_tolerance, int max_edges, std::vector<Vec3>* vertices,
                     std::vector<std::array<int, 3>>* triangles, double* smoothing_rms) {
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
  double sum_squares = 0;
  for (size_t i = 0; i < points.size(); ++i) {
    sum_squares += (Vec3(cgal_points[i].x(), cgal_points[i].y(), cgal_points[i].z()) - points[i]).squaredNorm();
  }
  *smoothing_rms = std::sqrt(sum_squares / std::max<size_t>(1, points.size()));
  // The mesh need not have a vertex per camera pixel: one per grid cell keeps its triangles (and
  // the patches and files made of them) in proportion to the surface, not to the camera.
  if (vertex_spacing > 0) {
    cgal_points.erase(CGAL::grid_simplify_point_set(cgal_points, vertex_spacing), cgal_points.end());
  }
  std::vector<std::array<std::size_t, 3>> facets;
  CGAL::advancing_front_surface_reconstruction(cgal_points.begin(), cgal_points.end(),
                                               std::back_inserter(facets));
  vertices->clear();
  for (const Point& p : cgal_points) vertices->emplace_back(p.x(), p.y(), p.z());
  triangles->clear();
  for (const std::array<std::size_t, 3>& facet : facets)
    triangles->push_back({int(facet[0]), int(facet[1]), int(facet[2])});
  SimplifyMesh(simplify_tolerance, max_edges, vertices, triangles);
  for (std::array<int, 3>& t : *triangles) {
    const Vec3& a = (*vertices)[t[0]];
    const Vec3 normal = ((*vertices)[t[1]] - a).cross((*vertices)[t[2]] - a);
    // The camera saw every triangle, so its lit side faces the camera.
    if (normal.dot(viewpoint - a) < 0) std::swap(t[1], t[2]);
  }
}

}  // namespace procam
