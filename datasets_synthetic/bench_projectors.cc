#include "datasets_synthetic/bench_projectors.h"

#include "projection/projector.h"

namespace procam {

std::vector<Projector> BoxRoomProjectors(int count, int width, int height) {
  const std::vector<double> xs = count == 2 ? std::vector<double>{1.2, 2.8} : std::vector<double>{1.2, 2.0, 2.8};
  const char* names[] = {"left", "centre", "right"};
  std::vector<Projector> projectors;
  for (size_t k = 0; k < xs.size(); ++k) {
    const double x = xs[k];
    Projector projector;
    projector.name = count == 2 ? (k == 0 ? "left" : "right") : names[k];
    projector.geometry = ProjectorGeometry(
        "LENSMODEL_OPENCV4",
        {1.0 * width, 1.0 * width, 0.5 * (width - 1), 0.9 * height, -0.05, 0.01, 0.0, 0.0}, width, height,
        ProjFromWorldLookingAt(Vec3(x, 0.2, 2.2), Vec3(4.0 - x, 3.0, 0.8), Vec3::UnitZ()));
    projector.photometry.black = Vec3::Constant(0.01);
    projector.photometry.max = Vec3(9.0, 10.0, 8.5);
    projectors.push_back(projector);
  }
  return projectors;
}

}  // namespace procam
