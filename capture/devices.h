#pragma once
// Registers the device backends this build contains with the camera registry (camera.h):
// "v4l2" when built with PROCAM_WITH_V4L2, "aravis" with PROCAM_WITH_ARAVIS. The test backend is
// always registered. Call once before OpenCamera()/ListCameras(); further calls do nothing.

namespace procam {

void RegisterDeviceBackends();

}  // namespace procam
