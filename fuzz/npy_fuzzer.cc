// ReadNpy (base/io.h): .npy arrays of every version, shape and dtype.
#include "base/io.h"
#include "fuzz/fuzz_input.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const auto path = procam::WriteFuzzInput(data, size, "input.npy");
  procam::ReadOrRefuse([&] { procam::ReadNpy(path); });
  return 0;
}
