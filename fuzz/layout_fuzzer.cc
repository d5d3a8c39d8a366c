// ParseCaptureLayout (calibration/capture_layout.h): a layout file describing photos made by
// another tool, and the decoder's view of it (CaptureLayout::Decodable).
#include "calibration/capture_layout.h"
#include "fuzz/fuzz_input.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const auto path = procam::WriteFuzzInput(data, size, "layout.json");
  procam::ReadOrRefuse([&] {
    const procam::CaptureLayout layout = procam::ReadCaptureLayout(path);
    const procam::StructuredLightLayout decodable = layout.Decodable(path.string());
    procam::CaptureLayoutJson(layout);
    (void)decodable.Encodes(true);
  });
  return 0;
}
