#pragma once
// The cameras of a scene file: its "cameras" array (docs/scene_format.md, section Cameras). A
// camera entry names the camera's mrcal .cameramodel (lens, image size and pose in the room)
// and, for a simulated rig built from the scene (`synthetic:ROOM.json`), the camera's
// photometric settings in the test camera's model (test_camera.h): the pixel format and every
// key of TestCameraSettings() — exposure, gain, black level, read noise, response, frame rate,
// display latency, projector and camera defocus, ambient light and JPEG quality.
//
//   "cameras": [
//     {"name": "camera", "model": "camera.cameramodel", "format": "BGR8",
//      "exposure_us": 10000, "gain_db": 0, "black": 0, "noise": 1.5, "response_gamma": 1}
//   ]

#include <filesystem>
#include <string>
#include <vector>

#include "base/camera_model.h"
#include "capture/test_camera.h"

namespace procam {

struct SceneCamera {
  std::string name;                  // letters, digits, '_', '-', '.' (default cameraN)
  std::filesystem::path model_path;  // the .cameramodel, resolved against the scene file
  CameraModel model;                 // cam_from_ref: the camera from the room (ref = world)
  // The simulated camera's settings: TestCameraOptions' defaults, then the entry's keys; width
  // and height are the model's image size, the pixel format BGR8 unless `format` says otherwise.
  TestCameraOptions settings;
};

// Parses a "cameras" JSON array (text; "" gives none) as if it were in `scene_file`, model paths
// relative to `base`. Throws IoError with one line naming the file and the key, e.g.
// "room.json: cameras[0].gain_db: must be in [0, 24]",
// "room.json: cameras[0].model: camera.cameramodel: file not found".
std::vector<SceneCamera> ParseSceneCameras(const std::string& cameras_json,
                                           const std::string& scene_file,
                                           const std::filesystem::path& base);

}  // namespace procam
