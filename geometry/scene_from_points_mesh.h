#pragma once
// Internal to scene_from_points.cc: the meshing step (6) of SceneFromPoints, in its own file so
// that the advancing-front reconstruction (a slow CGAL compile) builds apart from the rest.

#include <array>
#include <vector>

#include "base/vector.h"

namespace procam {

// Smooths `points` by jet fitting over `smoothing_neighbors` neighbours (0: not at all), keeps
// one point per cell of a grid of `vertex_spacing` metres (CGAL grid_simplify_point_set; 0: all)
// and meshes those by advancing-front surface reconstruction, then coarsens the mesh within
// `simplify_tolerance` metres of itself and to fewer than `max_edges` edges (SimplifyMesh; 0:
// not). `vertices` gets the mesh's
// vertices, `triangles` indices into them, each turned to face `viewpoint`; `smoothing_rms` the
// RMS distance the smoothing moved the points by (metres).
void ReconstructMesh(const std::vector<Vec3>& points, const Vec3& viewpoint, int smoothing_neighbors,
                     double vertex_spacing, double simplify_tolerance, int max_edges, std::vector<Vec3>* vertices,
                     std::vector<std::array<int, 3>>* triangles, double* smoothing_rms);

// Collapses edges of the mesh (`vertices`, `triangles`, as ReconstructMesh gives them) for as
// long as the result stays within `tolerance` metres of the input (CGAL's edge collapse with
// Lindstrom–Turk cost and placement, each collapse checked at sample points of its new
// triangles), its border edges kept as they are, until fewer than `max_edges` edges remain (0:
// no cap; CGAL counts edges, and a mesh has fewer triangles than edges); then, while it still
// has more than `max_edges` triangles, goes on collapsing whatever the tolerance. Returns the edges collapsed; 0 and the
// mesh unchanged where there is nothing to do or the triangles do not form an orientable
// manifold. The triangles' orientation is CGAL's: turn them afterwards.
int SimplifyMesh(double tolerance, int max_edges, std::vector<Vec3>* vertices,
                 std::vector<std::array<int, 3>>* triangles);

}  // namespace procam
