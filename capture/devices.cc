#include "capture/devices.h"

#include <mutex>

#include "capture/camera.h"
#include "procam/config.h"
#if PROCAM_WITH_V4L2
#include "capture/v4l2_camera.h"
#endif
#if PROCAM_WITH_ARAVIS
#include "capture/aravis_camera.h"
#endif

namespace procam {

void RegisterDeviceBackends() {
  static std::once_flag once;
  std::call_once(once, [] {
#if PROCAM_WITH_V4L2
    RegisterCameraBackend(V4l2CameraBackend());
#endif
#if PROCAM_WITH_ARAVIS
    RegisterCameraBackend(AravisCameraBackend());
#endif
  });
}

}  // namespace procam
