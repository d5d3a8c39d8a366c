#pragma once
// The reflectance map a projector's calibration measures (projection/reflectance_map.h), made
// from a scene's truth instead: for tests that need the map without calibration's errors.

#include <opencv2/core.hpp>

#include "geometry/scene.h"
#include "projection/projector.h"

namespace procam {

// The reflectance of the point each projector pixel lights (CV_32FC3, R, G, B; 0 where the pixel
// lights nothing), cast against the scene's surfaces, read from a printed surface's texture where
// it is printed. Surfaces are taken as rectangles: their UV comes from the first, second and
// fourth corners.
cv::Mat TrueReflectanceMap(const Scene& scene, const ProjectorGeometry& geometry);

}  // namespace procam
