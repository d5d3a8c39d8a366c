// ReadSolutionDirectory (compensation/stage.h): a solution directory's result.json.
#include "compensation/stage.h"
#include "fuzz/fuzz_input.h"

namespace {
// The arrays the seed result.json goes with, so that fuzzed results get past the file checks.
const bool kSolutionFilesCopied = [] {
  procam::CopyIntoFuzzDirectory("fuzz/corpus/npy/E.npy");
  procam::CopyIntoFuzzDirectory("fuzz/corpus/npy/E.npy", "B.npy");
  return true;
}();
}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  procam::WriteFuzzInput(data, size, "result.json");
  procam::ReadOrRefuse([&] { procam::ReadSolutionDirectory(procam::FuzzDirectory()); });
  return 0;
}
