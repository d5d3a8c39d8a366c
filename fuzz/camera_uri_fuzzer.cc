// Camera URIs (capture/camera.h): CameraUri::Parse, its getters, and OpenCamera with the test
// backend (the one registered without devices), which reads every key of its query string.
#include <string>

#include "capture/camera.h"
#include "fuzz/fuzz_input.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::string text(reinterpret_cast<const char*>(data), size);
  procam::ReadOrRefuse([&] {
    const auto uri = procam::CameraUri::Parse(text);
    uri.GetString("format", "");
    uri.GetDouble("fps", 0.0);
    uri.GetInt("width", 0);
    uri.CheckAllRead();
  });
  procam::ReadOrRefuse([&] { procam::OpenCamera(text); });
  return 0;
}
