// DecodeOscPacket and ParseOscCommand (nodes/osc.h): every datagram procam play's OSC control
// takes from a sender it allows. A refusal always says why; a message decoded and encoded again
// decodes to the same message; a command accepted writes a line of its own.
#include <cstdlib>

#include "nodes/osc.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  procam::OscMessage message;
  std::string why;
  if (!procam::DecodeOscPacket(data, size, &message, &why)) {
    if (why.empty()) std::abort();
    return 0;
  }
  if (message.types.find_first_not_of("ifs") == std::string::npos) {
    const std::vector<uint8_t> bytes = procam::EncodeOscMessage(message);
    procam::OscMessage again;
    if (!procam::DecodeOscPacket(bytes.data(), bytes.size(), &again, &why) ||
        again.address != message.address || again.types != message.types)
      std::abort();
    for (size_t k = 0; k < message.arguments.size(); ++k) {
      const procam::OscArgument &a = message.arguments[k], &b = again.arguments[k];
      // NaN is not equal to itself: compared as "both NaN".
      const bool same_number =
          a.number == b.number || (a.number != a.number && b.number != b.number);
      if (a.type != b.type || !same_number || a.text != b.text) std::abort();
    }
  }
  procam::OscCommand command;
  why.clear();
  if (!procam::ParseOscCommand(message, &command, &why)) {
    if (why.empty() || why.find('\n') != std::string::npos) std::abort();
    return 0;
  }
  if (command.Text().empty()) std::abort();
  return 0;
}
