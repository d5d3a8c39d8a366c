#include "geometry/ray_scene.h"

#include <embree3/rtcore.h>

#include <limits>
#include <string>

#include "base/io.h"

namespace procam {

struct RayScene::Impl {
  RTCDevice device = nullptr;
  RTCScene scene = nullptr;
};

RayScene::RayScene(const Scene& scene) : impl_(std::make_unique<Impl>()) {
  impl_->device = rtcNewDevice("threads=1");
  if (impl_->device == nullptr) {
    throw IoError("embree: cannot create device (error " +
                  std::to_string(static_cast<int>(rtcGetDeviceError(nullptr))) + ")");
  }
  impl_->scene = rtcNewScene(impl_->device);
  rtcSetSceneBuildQuality(impl_->scene, RTC_BUILD_QUALITY_HIGH);
  for (const Surface& surface : scene.surfaces) {
    std::vector<Vec3> points;
    std::vector<std::array<int, 3>> triangles;
    if (surface.kind == Surface::Kind::kQuad) {
      points.assign(surface.quad.begin(), surface.quad.end());
      triangles = {{0, 1, 2}, {0, 2, 3}};
    } else {
      points = surface.mesh_vertices;
      for (const MeshTriangle& triangle : surface.mesh_triangles) triangles.push_back(triangle.vertex);
    }
    RTCGeometry geometry = rtcNewGeometry(impl_->device, RTC_GEOMETRY_TYPE_TRIANGLE);
    auto* vertices = static_cast<float*>(rtcSetNewGeometryBuffer(
        geometry, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3, 3 * sizeof(float), points.size()));
    for (size_t k = 0; k < points.size(); ++k) {
      for (int c = 0; c < 3; ++c) vertices[3 * k + c] = static_cast<float>(points[k][c]);
    }
    auto* indices = static_cast<unsigned*>(rtcSetNewGeometryBuffer(
        geometry, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3, 3 * sizeof(unsigned), triangles.size()));
    for (size_t k = 0; k < triangles.size(); ++k) {
      for (int c = 0; c < 3; ++c) indices[3 * k + c] = static_cast<unsigned>(triangles[k][c]);
    }
    rtcCommitGeometry(geometry);
    rtcAttachGeometry(impl_->scene, geometry);  // geometry IDs follow surface indices
    rtcReleaseGeometry(geometry);
  }
  rtcCommitScene(impl_->scene);
}

RayScene::~RayScene() {
  if (impl_->scene != nullptr) rtcReleaseScene(impl_->scene);
  if (impl_->device != nullptr) rtcReleaseDevice(impl_->device);
}

bool RayScene::Occluded(const Vec3& from, const Vec3& to, double margin) const {
  const Vec3 delta = to - from;
  const double length = delta.norm();
  if (length <= 2 * margin) return false;
  const Vec3 direction = delta / length;
  RTCIntersectContext context;
  rtcInitIntersectContext(&context);
  RTCRay ray;
  ray.org_x = static_cast<float>(from.x());
  ray.org_y = static_cast<float>(from.y());
  ray.org_z = static_cast<float>(from.z());
  ray.dir_x = static_cast<float>(direction.x());
  ray.dir_y = static_cast<float>(direction.y());
  ray.dir_z = static_cast<float>(direction.z());
  ray.tnear = static_cast<float>(margin);
  ray.tfar = static_cast<float>(length - margin);
  ray.time = 0.0f;
  ray.mask = 0xffffffffu;
  ray.id = 0;
  ray.flags = 0;
  rtcOccluded1(impl_->scene, &context, &ray);
  return ray.tfar < 0.0f;  // Embree sets tfar to -inf on a hit
}

bool RayScene::Intersect(const Vec3& origin, const Vec3& direction, double t_near, double t_far,
                         double* t_hit, int* surface) const {
  RTCIntersectContext context;
  rtcInitIntersectContext(&context);
  RTCRayHit hit;
  hit.ray.org_x = static_cast<float>(origin.x());
  hit.ray.org_y = static_cast<float>(origin.y());
  hit.ray.org_z = static_cast<float>(origin.z());
  hit.ray.dir_x = static_cast<float>(direction.x());
  hit.ray.dir_y = static_cast<float>(direction.y());
  hit.ray.dir_z = static_cast<float>(direction.z());
  hit.ray.tnear = static_cast<float>(t_near);
  hit.ray.tfar = t_far == std::numeric_limits<double>::infinity() ? std::numeric_limits<float>::infinity()
                                                                   : static_cast<float>(t_far);
  hit.ray.time = 0.0f;
  hit.ray.mask = 0xffffffffu;
  hit.ray.id = 0;
  hit.ray.flags = 0;
  hit.hit.geomID = RTC_INVALID_GEOMETRY_ID;
  hit.hit.instID[0] = RTC_INVALID_GEOMETRY_ID;
  rtcIntersect1(impl_->scene, &context, &hit);
  if (hit.hit.geomID == RTC_INVALID_GEOMETRY_ID) return false;
  *t_hit = hit.ray.tfar;
  *surface = static_cast<int>(hit.hit.geomID);
  return true;
}

}  // namespace procam
