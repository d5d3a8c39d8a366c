#pragma once
// Internal to scene_from_points.cc: the meshing step (6) of SceneFromPoints, in its own file so
// that the advancing-front reconstruction (a slow CGAL compile) builds apart from the rest.

#include <array>
#include <vector>

#include "base/vector.h"

namespace procam {

// Smooths `points` by jet fitting over `smoothing_neighbors` neighbours (0: not at all) and
// meshes them by advancing-front surface reconstruction. `vertices` gets the smoothed points (same
// order as `points`), `triangles` indices into them, each turned to face `viewpoint`.
void ReconstructMesh(const std::vector<Vec3>& points, const Vec3& viewpoint,
                     int smoothing_neighbors, std::vector<Vec3>* vertices,
                     std::vector<std::array<int, 3>>* triangles);

}  // namespace procam
