// ReadImage (base/image_io.h): textures, session frames, photos, as 8-bit colour and unchanged.
#include <opencv2/imgcodecs.hpp>

#include "base/image_io.h"
#include "fuzz/fuzz_input.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const auto path = procam::WriteFuzzInput(data, size, "input.img");
  for (const int flags : {cv::IMREAD_COLOR, cv::IMREAD_UNCHANGED}) {
    procam::ReadOrRefuse([&] { procam::ReadImage(path, flags); });
  }
  return 0;
}
