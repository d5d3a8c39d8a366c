// ReadRigFile and ReadRigDirectory (projection/rig_directory.h): a rig directory's rig.json.
#include "fuzz/fuzz_input.h"
#include "projection/rig_directory.h"

namespace {
// The files the seed rig.json names, so that fuzzed rigs get past the file checks.
const bool kRigFilesCopied = [] {
  for (const char* model : {"camera", "left", "right"}) {
    procam::CopyIntoFuzzDirectory(std::string("fuzz/corpus/cameramodel/") + model + ".cameramodel");
  }
  procam::CopyIntoFuzzDirectory("fuzz/corpus/npy/reflectance.npy");
  return true;
}();
}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  procam::WriteFuzzInput(data, size, "rig.json");
  procam::ReadOrRefuse([&] { procam::ReadRigFile(procam::FuzzDirectory()); });
  procam::ReadOrRefuse([&] { procam::ReadRigDirectory(procam::FuzzDirectory()); });
  return 0;
}
