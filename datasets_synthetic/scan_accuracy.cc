#include "datasets_synthetic/scan_accuracy.h"

#include <algorithm>
#include <cmath>

#include <Eigen/Geometry>

namespace procam {
namespace {

// Where a scanned facet is measured: its corners, then its centroid.
std::vector<Vec3> CornersAndCentroid(const ModelFacet& facet) {
  std::vector<Vec3> samples = facet.corners;
  Vec3 centroid = Vec3::Zero();
  for (const Vec3& corner : facet.corners) centroid += corner / facet.corners.size();
  samples.push_back(centroid);
  return samples;
}

}  // namespace

double ScannedSurfaceAccuracy::RmsMetres() const {
  double squares = 0.0;
  for (double d : distances) squares += d * d;
  return std::sqrt(squares / std::max<size_t>(1, distances.size()));
}

int ScannedSurfaceAccuracy::TrueSurface() const {
  return static_cast<int>(std::max_element(votes.begin(), votes.end()) - votes.begin());
}

ScannedSurfaceAccuracy MeasureScannedSurface(const RoomModel& truth, const RoomModel& scanned,
                                             int surface,
                                             const Eigen::Isometry3d& world_from_room) {
  ScannedSurfaceAccuracy accuracy;
  accuracy.votes.assign(truth.scene().surfaces.size(), 0);
  for (const ModelFacet& facet : scanned.facets()) {
    if (facet.surface != surface) continue;
    ++accuracy.facets;
    for (size_t k = 1; k + 1 < facet.corners.size(); ++k)
      accuracy.area_m2 += 0.5 * (facet.corners[k] - facet.corners[0])
                                    .cross(facet.corners[k + 1] - facet.corners[0])
                                    .norm();
    const std::vector<Vec3> samples = CornersAndCentroid(facet);
    Vec3 nearest;
    double distance = 0.0;
    for (const Vec3& p : samples) {
      truth.Closest(world_from_room * p, &nearest, &distance);
      accuracy.distances.push_back(distance);
    }
    ++accuracy.votes[truth.facets()[truth.Closest(world_from_room * samples.back(), &nearest, &distance)]
                         .surface];
  }
  return accuracy;
}

Eigen::Isometry3d FitScannedRoom(const RoomModel& truth, const RoomModel& scanned,
                                 const Eigen::Isometry3d& world_from_room, int iterations) {
  std::vector<Vec3> samples;
  for (const ModelFacet& facet : scanned.facets()) {
    const std::vector<Vec3> facet_samples = CornersAndCentroid(facet);
    samples.insert(samples.end(), facet_samples.begin(), facet_samples.end());
  }
  Eigen::Isometry3d fit = world_from_room;
  if (samples.size() < 3) return fit;
  Eigen::Matrix3Xd from(3, samples.size()), to(3, samples.size());
  for (size_t i = 0; i < samples.size(); ++i) from.col(i) = samples[i];
  for (int round = 0; round < iterations; ++round) {
    for (size_t i = 0; i < samples.size(); ++i) {
      Vec3 nearest;
      double distance = 0.0;
      truth.Closest(fit * samples[i], &nearest, &distance);
      to.col(i) = nearest;
    }
    fit.matrix() = Eigen::umeyama(from, to, false);
  }
  return fit;
}

double SeenAndLitArea(const RoomModel& truth, const RayScene& rays, int surface,
                      const ProjectorGeometry& camera,
                      const std::vector<ProjectorGeometry>& projectors, double cell) {
  const Vec3 camera_centre = camera.CentreInWorld();
  const auto visible = [&](const ProjectorGeometry& device, const Vec3& centre, const Vec3& p) {
    Vec2 pixel;
    return device.Project(p, &pixel) && device.InImage(pixel) && !rays.Occluded(centre, p, 1e-4);
  };
  double area = 0.0;
  for (const ModelFacet& facet : truth.facets()) {
    if (facet.surface != surface) continue;
    // The convex facet as a fan of triangles, each cut into m² congruent sub-triangles whose
    // sides are at most `cell`, counted at their centroids.
    for (size_t k = 1; k + 1 < facet.corners.size(); ++k) {
      const Vec3 &a = facet.corners[0], e1 = facet.corners[k] - a, e2 = facet.corners[k + 1] - a;
      const double longest = std::max({e1.norm(), e2.norm(), (e2 - e1).norm()});
      const int m = std::max(1, static_cast<int>(std::ceil(longest / cell)));
      const double weight = 0.5 * e1.cross(e2).norm() / (static_cast<double>(m) * m);
      const auto count = [&](const Vec3& p) {
        if (!visible(camera, camera_centre, p)) return;
        for (const ProjectorGeometry& projector : projectors)
          if (visible(projector, projector.CentreInWorld(), p)) {
            area += weight;
            return;
          }
      };
      for (int i = 0; i < m; ++i)
        for (int j = 0; i + j < m; ++j) {
          count(a + ((3 * i + 1) * e1 + (3 * j + 1) * e2) / (3.0 * m));
          if (i + j < m - 1) count(a + ((3 * i + 2) * e1 + (3 * j + 2) * e2) / (3.0 * m));
        }
    }
  }
  return area;
}

}  // namespace procam
