#pragma once
// What `procam emulate` plays: the room of a scene file as a device. Its synthetic rig watches
// what each projector's monitor of a running wlroots compositor shows (monitor_watcher.h) and its
// camera's photographs are served as a GigE Vision camera (capture/gige_emulator.h).

#include <optional>
#include <string>
#include <vector>

#include "base/option_table.h"

namespace procam {

struct EmulatedRoomOptions {
  std::string room;  // scene file with projectors and cameras (docs/scene_format.md)
  // The compositor's output showing each projector, in the scene's order (e.g. HEADLESS-1); each
  // once.
  std::vector<std::string> monitors;
  std::string camera;                 // the scene's camera entry by name; empty: the first
  std::string address = "127.0.0.1";  // local IPv4 address the camera is served on
  std::optional<double> latency_ms;   // display to camera, ms, [0, 10000]; unset: the entry's
  std::optional<double> fps;          // frame rate, [0.1, 1000]; unset: the entry's
  int patches = 300;                  // solver patches the simulated room is built for, [20, 5000]
  double seconds = 0.0;               // stop after this long, s, [0, 1e7]; 0: at a signal
  int board_pose = -1;      // >= 0: photograph this pose of the scene's chessboard, not the room
  double watch_hz = 200.0;  // monitor captures per second at most, [1, 1000]

  // Declares the room (positional), --monitors, --camera, --address, --latency-ms, --fps,
  // --patches, --seconds, --board-pose and --watch-hz in `table`, bound to these fields.
  void Declare(OptionTable* table);
  // The declared values, and each monitor given once; `*why` names the option.
  bool Check(std::string* why) const;
};

}  // namespace procam
