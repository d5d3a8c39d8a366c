// procam emulate: the room as a device. A scene file's synthetic rig (its surfaces, projectors
// and camera) watches what each projector's monitor of a running wlroots compositor shows
// (MonitorWatcher) and is photographed by its camera, served as a GigE Vision camera
// (GigeEmulator), so that procam — calibrate all, capture, verify, the demo — drives a real
// display server and a real camera protocol with no hardware.
#include <fmt/format.h>

#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <memory>
#include <stdexcept>
#include <string>
#include <thread>
#include <vector>

#include "apps/command_line.h"
#include "apps/commands.h"
#include "apps/stop_signals.h"
#include "base/io.h"
#include "capture/pixel_format.h"
#include "datasets_synthetic/emulated_room.h"
#include "datasets_synthetic/monitor_watcher.h"
#include "datasets_synthetic/synthetic_camera.h"
#include "procam/config.h"
#if PROCAM_WITH_ARAVIS
#include "capture/gige_emulator.h"
#endif

namespace procam {
namespace {

#if PROCAM_WITH_ARAVIS
// The emulated camera's pixel format: the entry's where the GigE camera offers it, else RGB8
// for colour (Aravis's fake camera has no BGR8) and Mono8 for grey.
PixelFormat ServedFormat(PixelFormat wanted) {
  for (PixelFormat format : GigeEmulator::SupportedPixelFormats())
    if (format == wanted) return wanted;
  return IsColour(wanted) ? PixelFormat::kRGB8 : PixelFormat::kMono8;
}

void RunEmulate(const EmulatedRoomOptions& args) {
  const std::shared_ptr<SyntheticWorld> world =
      MakeSceneFileWorld(args.room, args.camera, args.patches, 0.0, args.room);
  if (args.board_pose >= 0) PlaceSceneChessboard(world.get(), args.room, args.board_pose);
  const std::vector<std::shared_ptr<MemoryDisplay>>& displays = world->displays;
  if (args.monitors.size() != displays.size()) {
    throw std::invalid_argument(fmt::format("--monitors: {} outputs for the {} projectors of {} (one per projector, in order)",
                                            args.monitors.size(), displays.size(), args.room));
  }
  const TestCameraOptions& camera = world->camera_settings;
  GigeEmulatorOptions options;
  options.address = args.address;
  options.width = camera.width;
  options.height = camera.height;
  options.pixel_format = ServedFormat(camera.pixel_format);
  options.frame_rate = args.fps.value_or(camera.frame_rate);
  options.latency_ms = args.latency_ms.value_or(camera.display_latency_ms);
  options.exposure_us = std::round(camera.exposure_us);
  options.gain_db = std::round(std::min(camera.gain_db, 10.0));
  std::string why;
  if (!options.Check(&why)) throw IoError(args.room + ": cameras: the emulated GigE camera cannot take it: " + why);
  GigeEmulator emulator(options, PhotographScene(MakeSyntheticView(world), camera));
  // The watcher after the emulator: grim's processes are started from then on, and none may
  // inherit a socket while the camera binds its port.
  std::vector<WatchedMonitor> watched;
  for (size_t k = 0; k < displays.size(); ++k) watched.push_back({args.monitors[k], displays[k]});
  MonitorWatcher watcher(watched, args.watch_hz);


  // What calibrate all needs of a real camera: its value per unit exitance at these settings.
  const double scale = CameraValuePerExitance(*world, camera, options.exposure_us, options.gain_db,
                                              FullScale(options.pixel_format));
  std::printf("procam emulate: room %s, camera %s (%dx%d %s, %.3g fps, latency %.0f ms, exposure %.0f us, gain %.0f dB)\n",
              args.room.c_str(), emulator.Uri().c_str(), options.width, options.height,
              PixelFormatName(options.pixel_format).c_str(), options.frame_rate, options.latency_ms,
              options.exposure_us, options.gain_db);
  for (size_t k = 0; k < displays.size(); ++k) {
    std::printf("  projector %s watches output %s (%dx%d)\n", world->rig->projectors()[k].name.c_str(),
                args.monitors[k].c_str(), displays[k]->Resolution().width, displays[k]->Resolution().height);
  }
  std::printf("  camera scale %.6g (camera value per unit exitance at these settings: --camera-scale)\n", scale);
  std::printf("  camera guess %s\n", world->camera_guess.c_str());
  std::fflush(stdout);

  const std::atomic<bool>& stop = StopOnSignals();
  const auto start = std::chrono::steady_clock::now();
  auto last_status = start;
  while (!stop) {
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
    // A signal to the process group stops grim too: the watcher's error is then the stop's.
    if (stop) break;
    const std::string error = watcher.error();
    if (!error.empty()) throw IoError("emulate: " + error);
    const auto now = std::chrono::steady_clock::now();
    const double elapsed = std::chrono::duration<double>(now - start).count();
    if (args.seconds > 0 && elapsed >= args.seconds) break;
    if (now - last_status >= std::chrono::seconds(5)) {
      last_status = now;
      std::printf("procam emulate: %.0f s, %lld frames served (%lld failed), monitors watched every %.1f ms, %lld changes seen\n",
                  elapsed, static_cast<long long>(emulator.frames_served()),
                  static_cast<long long>(emulator.frames_failed()), watcher.round_ms(),
                  static_cast<long long>(watcher.changes()));
      std::fflush(stdout);
    }
  }
  std::printf("procam emulate: stopped after %lld frames (%lld failed%s%s)\n",
              static_cast<long long>(emulator.frames_served()), static_cast<long long>(emulator.frames_failed()),
              emulator.last_error().empty() ? "" : "; last: ", emulator.last_error().c_str());
}
#endif

}  // namespace

void AddEmulateCommand(CLI::App& app) {
  CLI::App* emulate = app.add_subcommand(
      "emulate",
      "Play the room of a scene file as a device: watch what each projector's monitor shows (a wlroots compositor "
      "such as sway, through grim) and serve what the scene's camera photographs as a GigE Vision camera "
      "(aravis:gv:ADDRESS)");
  const auto options = AddDeclaredOptions<EmulatedRoomOptions>(emulate);
  emulate->callback([options] {
    std::string why;
    if (!options->Check(&why)) throw std::invalid_argument(why);
#if PROCAM_WITH_ARAVIS
    RunEmulate(*options);
#else
    throw IoError("emulate: this procam was built without Aravis (apt-get install libaravis-dev libusb-1.0-0-dev, reconfigure)");
#endif
  });
}

}  // namespace procam
