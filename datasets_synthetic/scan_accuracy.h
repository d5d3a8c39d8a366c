#pragma once
// A scanned room against the true one (the scan's accuracy): how far each scanned surface lies
// from the true room and which true surface it lies on. Used by the demo's scan stage and the
// scan tests.

#include <Eigen/Geometry>
#include <vector>

#include "calibration/registration.h"
#include "geometry/ray_scene.h"
#include "projection/projector.h"

namespace procam {

struct ScannedSurfaceAccuracy {
  // Distances to the true room of every facet's corners and centroid, metres.
  std::vector<double> distances;
  double area_m2 = 0.0;    // of the surface's facets
  int facets = 0;
  std::vector<int> votes;  // per true surface: the facets whose centroid lies nearest to it
  double RmsMetres() const;
  int TrueSurface() const;  // the true surface with the most votes
};

// Scanned surface `surface` of `scanned` (room frame) taken to the true world by
// `world_from_room` (the true camera pose after the scan's own: true cam_from_world⁻¹ ·
// scanned cam_from_room) and measured against `truth`.
ScannedSurfaceAccuracy MeasureScannedSurface(const RoomModel& truth, const RoomModel& scanned,
                                             int surface,
                                             const Eigen::Isometry3d& world_from_room);

// `world_from_room` refined by the rigid motion that best lays the whole scanned room on the true
// one (iterative closest points: every scanned facet's corners and centroid to their nearest
// true points, Umeyama's fit without scale, `iterations` rounds). Measuring with it separates
// the scanned room's shape from where its frame was placed: the camera's pose in the scanned
// room, carried to every point in proportion to its distance.
Eigen::Isometry3d FitScannedRoom(const RoomModel& truth, const RoomModel& scanned,
                                 const Eigen::Isometry3d& world_from_room, int iterations = 100);

// What of true surface `surface` a scan can rebuild: the area of its facets whose points the
// camera sees and at least one projector lights, both unoccluded (`rays` is the true room),
// sampled at the centres of cells about `cell` metres wide; m². The scanned area of that surface
// is compared with this, not with the whole surface: a scan rebuilds only what it saw.
double SeenAndLitArea(const RoomModel& truth, const RayScene& rays, int surface,
                      const ProjectorGeometry& camera,
                      const std::vector<ProjectorGeometry>& projectors, double cell = 0.01);

}  // namespace procam
