#include "datasets_synthetic/true_reflectance.h"

#include <vector>

#include "geometry/ray_scene.h"

namespace procam {

cv::Mat TrueReflectanceMap(const Scene& scene, const ProjectorGeometry& geometry) {
  const RayScene surfaces(scene);
  std::vector<Vec3> directions;
  std::vector<double> densities;
  geometry.UnprojectImage(&directions, &densities);
  const Eigen::Isometry3d world_from_proj = geometry.proj_from_world().inverse();
  cv::Mat map(geometry.height(), geometry.width(), CV_32FC3, cv::Scalar::all(0));
  for (int row = 0; row < geometry.height(); ++row) {
    for (int col = 0; col < geometry.width(); ++col) {
      const Vec3 direction = world_from_proj.linear() * directions[row * geometry.width() + col];
      double t;
      int s;
      if (!surfaces.Intersect(world_from_proj.translation(), direction, 0.0, 1e9, &t, &s)) continue;
      const Surface& surface = scene.surfaces[s];
      const Vec3 d = world_from_proj.translation() + t * direction - surface.quad[0];
      const Vec3 e1 = surface.quad[1] - surface.quad[0], e3 = surface.quad[3] - surface.quad[0];
      const Vec3 rho =
          surface.ReflectanceAt(Vec2(d.dot(e1) / e1.squaredNorm(), d.dot(e3) / e3.squaredNorm()));
      map.at<cv::Vec3f>(row, col) = cv::Vec3f(rho[0], rho[1], rho[2]);
    }
  }
  return map;
}

}  // namespace procam
