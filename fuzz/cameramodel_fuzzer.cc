// ReadCameraModelFile (base/camera_model.h, libmrcal's parser) and the projector geometry
// read from it (ReadCameraModel, projection/projector.h).
#include "base/camera_model.h"
#include "fuzz/fuzz_input.h"
#include "projection/projector.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const auto path = procam::WriteFuzzInput(data, size, "input.cameramodel");
  procam::ReadOrRefuse([&] { procam::ReadCameraModelFile(path); });
  procam::ReadOrRefuse([&] { procam::ReadCameraModel(path); });
  return 0;
}
