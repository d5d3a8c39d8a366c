// ParseMessage (nodes/messages.h): every message a display node or a controller receives. Takes
// the bytes directly (a node parses what arrives on its socket, no file); a message it accepts
// must encode again and parse to the same message.
#include <cstdlib>

#include "nodes/messages.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  procam::Message message;
  std::string why;
  if (!procam::ParseMessage(data, size, &message, &why)) {
    if (why.empty()) std::abort();  // a refusal always says why
    return 0;
  }
  const std::string bytes = procam::EncodeMessage(message);
  procam::Message again;
  if (!procam::ParseMessage(bytes.data(), bytes.size(), &again, &why) || again.type != message.type ||
      again.sequence != message.sequence || again.emittance != message.emittance || again.body != message.body ||
      again.presented_ns != message.presented_ns)
    std::abort();
  return 0;
}
