// LoadScene (geometry/scene.h) and the scene's projectors (ReadProjectors). The directory holds
// data/scenes/column.obj, sunset.png and the corpus's left/right.cameramodel, so that scenes
// naming them get past the file checks.
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
  procam::ReadOrRefuse([&] { procam::ReadProjectors(procam::LoadScene(path)); });
  return 0;
}
