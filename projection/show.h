#pragma once
// Images or a test pattern fullscreen on projector monitors (`procam show`), part of the optional
// GLFW backend (procam_projection_glfw). Main thread only (GLFW's rule).

#include <filesystem>
#include <optional>
#include <string>
#include <vector>

#include "base/progress.h"
#include "projection/glfw_display.h"
#include "projection/test_pattern.h"

namespace procam {

class OptionTable;

struct ShowOptions {
  // PNGs, one per monitor in its resolution; or, when empty, `pattern` on every chosen monitor.
  std::vector<std::filesystem::path> images;
  std::optional<TestPattern> pattern;
  // Monitors by index or name (ListMonitors' names, e.g. "HDMI-1" or "XWAYLAND1"), one per
  // image (or the pattern's monitors); empty: image k on monitor k, or the pattern on every
  // monitor.
  std::vector<std::string> monitors;
  // How the windows reach their monitors; each is checked to cover its monitor before anything
  // is reported shown.
  GlfwDisplayOptions display;
  // Where to write what each window shows (monitorN.png); empty: nowhere.
  std::filesystem::path readback;
  // How long to show; ≤ 0: until Esc or Q in a window.
  double seconds = 0.0;
  // List the connected monitors instead (a line each through `progress`) and show nothing.
  bool list = false;
  ProgressCallback progress;  // a line per monitor with what it shows

  // Declares the images (positional), --monitor, --placement, --list, --pattern, --seconds and
  // --readback in `table`, bound to these fields (base/option_table.h; show_options.cc, so that
  // a build without GLFW declares them too).
  void Declare(OptionTable* table);
  // "" when valid, else why not (images and pattern both or neither, monitors not one per image,
  // display options).
  std::string Check() const;
};

// With options.list, a line per connected monitor through options.progress. Otherwise checks
// every image (readable, the monitor's resolution) before a window opens, then shows them
// until `seconds` pass, Esc or Q is pressed or a window is closed. Throws std::invalid_argument
// for bad options, IoError naming the file or the monitor otherwise, also when a window is not
// on its monitor, at opening or later (GlfwDisplay::CheckStillThere).
void RunShow(const ShowOptions& options);

}  // namespace procam
