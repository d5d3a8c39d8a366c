// CaptureSessionData (capture/session.h): a capture session's session.json and its accessors.
#include "capture/session.h"
#include "fuzz/fuzz_input.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  procam::WriteFuzzInput(data, size, "session.json");
  procam::ReadOrRefuse([&] {
    const auto session = procam::CaptureSessionData::Load(procam::FuzzDirectory());
    session.complete();
    for (int pattern = 0; pattern < session.pattern_count() && pattern < 64; ++pattern) {
      if (session.captured(pattern)) session.pattern_name(pattern);
    }
  });
  return 0;
}
