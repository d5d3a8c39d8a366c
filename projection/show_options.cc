// ShowOptions' declared options, in procam_projection so that a build without the GLFW backend
// (which runs RunShow) declares them too: `procam options` and docs/options.md list them.
#include "base/option_table.h"
#include "projection/show.h"

namespace procam {

void ShowOptions::Declare(OptionTable* table) {
  std::optional<TestPattern>* shown = &pattern;
  table->Paths("images", &images, "PNG per projector, in the monitor's resolution").Positional();
  table->Texts("monitor", &monitors,
               "monitor index or name (as --list shows), once per image (default: image k on "
               "monitor k)");
  table->Choice("placement", &display.placement,
                {{"auto", WindowPlacement::kAuto},
                 {"window-manager", WindowPlacement::kWindowManager},
                 {"by-hand", WindowPlacement::kByHand}},
                "how windows reach their monitors: auto, window-manager (fullscreen through the "
                "window manager) or by-hand (placed by procam, the window manager left out)");
  table->Flag("list", &list, "list the connected monitors and exit");
  table
      ->Custom(
          "pattern", [shown] { return *shown ? std::string(TestPatternName(**shown)) : ""; },
          [shown](const std::string& text, std::string* why) {
            TestPattern parsed;
            if (text.empty()) {
              shown->reset();
            } else if (ParseTestPattern(text, &parsed)) {
              *shown = parsed;
            } else {
              *why = "expected grid, bars, white or black; got '" + text + "'";
              return false;
            }
            return true;
          },
          "grid | bars | white | black", "test pattern instead of images")
      .Sets(&pattern);
  table->Number("seconds", &seconds, 0.0, 1e6, "s", "close after this long (0: until Esc or Q)");
  table->Path("readback", &readback,
              "write what each window shows (monitorN.png) into this directory");
}

}  // namespace procam
