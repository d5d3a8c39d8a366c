// LoadScene (geometry/scene.h), the scene's projectors (ReadProjectors) and cameras
// (ParseSceneCameras). The directory holds
// data/scenes/column.obj, sunset.png and the corpus's left/right.cameramodel, so that scenes
// naming them get past the file checks.
#include "capture/scene_cameras.h"
#include "fuzz/fuzz_input.h"
#include "geometry/scene.h"
#include "projection/projector.h"

namespace {
const bool kSceneFilesCopied = [] {
  procam::CopyIntoFuzzDirectory("data/scenes/column.obj");
  procam::CopyIntoFuzzDirectory("data/scenes/sunset.png");
  procam::CopyIntoFuzzDirectory("fuzz/corpus/cameramodel/left.cameramodel");
  procam::CopyIntoFuzzDirectory("fuzz/corpus/cameramodel/right.cameramodel");
  return true;
}();
}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const auto path = procam::WriteFuzzInput(data, size, "scene.json");
  procam::ReadOrRefuse([&] {
    const procam::Scene scene = procam::LoadScene(path);
    procam::ReadProjectors(scene);
    procam::ParseSceneCameras(scene.cameras_json, path.string(), path.parent_path());
  });
  return 0;
}
