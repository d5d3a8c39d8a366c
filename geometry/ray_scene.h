#pragma once
// Ray casting against a scene's surfaces through Embree (visibility for form factors; later
// projector and camera views). Thread-safe for queries once built.

#include <memory>

#include "geometry/scene.h"

namespace procam {

class RayScene {
 public:
  // Builds an Embree BVH over every surface (quads as two triangles, meshes as they are).
  // Throws IoError if Embree cannot be initialised.
  explicit RayScene(const Scene& scene);
  ~RayScene();
  RayScene(const RayScene&) = delete;
  RayScene& operator=(const RayScene&) = delete;

  // True when the open segment from `from` to `to`, shortened by `margin` metres at both ends,
  // hits a surface.
  bool Occluded(const Vec3& from, const Vec3& to, double margin) const;

  // Nearest hit along a ray (direction need not be unit) within (t_near, t_far):
  // returns false if none; otherwise the distance parameter and the surface index.
  bool Intersect(const Vec3& origin, const Vec3& direction, double t_near, double t_far,
                 double* t_hit, int* surface) const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace procam
