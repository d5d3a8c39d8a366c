#include "datasets_synthetic/emulated_room.h"

#include <arpa/inet.h>

#include <limits>

namespace procam {

void EmulatedRoomOptions::Declare(OptionTable* table) {
  std::string* served = &address;
  table->Text("room", &room, "scene file with projectors and cameras (docs/scene_format.md)")
      .Positional()
      .Required()
      .Texts("monitors", &monitors,
             "the compositor's output showing each projector, in the scene's order (e.g. "
             "HEADLESS-1,HEADLESS-2)")
      .Required()
      .Text("camera", &camera, "the scene's camera entry by name (default: the first)")
      .Custom(
          "address", [served] { return *served; },
          [served](const std::string& text, std::string* why) {
            in_addr parsed{};
            if (inet_pton(AF_INET, text.c_str(), &parsed) != 1) {
              *why = "'" + text + "' is not an IPv4 address";
              return false;
            }
            *served = text;
            return true;
          },
          "IPv4 address", "local IPv4 address to serve the camera on")
      .OptionalNumber("latency-ms", &latency_ms, OptionTable::Interval::Closed(0.0, 10000.0), "ms",
                      "display-to-camera latency (default: the camera entry's latency_ms)")
      .OptionalNumber("fps", &fps, OptionTable::Interval::Closed(0.1, 1000.0), "",
                      "frame rate (default: the camera entry's fps)")
      .Integer("patches", &patches, 20, 5000, "",
               "solver patches the simulated room is built for (its mesh is 4x finer)")
      .Number("seconds", &seconds, 0.0, 1e7, "s", "stop after this long (0: at Ctrl+C or SIGTERM)")
      .Integer("board-pose", &board_pose, -1, std::numeric_limits<int>::max(), "",
               "photograph pose K of the scene's chessboard (its \"chessboard\" key) instead of "
               "the room: the board alone, lit by the monitors (-1: the room)")
      .Number("watch-hz", &watch_hz, 1.0, 1000.0, "Hz", "monitor captures per second at most");
}

bool EmulatedRoomOptions::Check(std::string* why) const {
  if (!CheckDeclared(*this, why)) return false;
  for (size_t k = 0; k < monitors.size(); ++k) {
    for (size_t j = 0; j < k; ++j) {
      if (monitors[j] == monitors[k]) {
        *why = FlagOf(*this, &monitors) + ": '" + monitors[k] +
               "' is given twice: each projector has its own output";
        return false;
      }
    }
  }
  return true;
}

}  // namespace procam
