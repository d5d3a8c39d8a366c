#pragma once
// Internal to scene_from_points.cc: the meshing step (6) of SceneFromPoints, in its own file so
// that the advancing-front reconstruction (a slow CGAL compile) builds apart from the rest.

#include <array>
#include <vector>

#include "base/vector.h"

namespace procam {

// Smooths `points` by jet fitting over `smoothing_neighbors` neighbours (0: not at all), keeps
// one point per cell of a grid of `vertex_spacing` metres (CGAL grid_simplify_point_set; 0: all)
// and meshes those by advancing-front surface reconstruction. `vertices` gets the kept smoothed
// points, `triangles` indices into them, each turned to face `viewpoint`; `smoothing_rms` the RMS
// distance the smoothing moved the points by (metres).
void ReconstructMesh(const std::vector<Vec3>& points, const Vec3& viewpoint, int smoothing_neighbors,
                     double vertex_spacing, std::vector<Vec3>* vertices,
                     std::vector<std::array<int, 3>>* triangles, double* smoothing_rms);

}  // namespace procam
