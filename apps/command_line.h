#pragma once
// Values the commands read from their options (and rig.json keys) beyond what CLI11 parses.

#include <CLI/CLI.hpp>
#include <memory>
#include <string>

#include "base/option_table.h"
#include "base/progress.h"
#include "capture/display.h"
#include "projection/projector_images.h"

namespace procam {

// Registers every option of `table` on `command`, each flag bound straight to its field (the
// table is the only declaration: no copy of the options in apps/). Values are parsed by the table
// (its ranges and choices: an error is one line naming the flag); --help shows each option's
// default, values and unit. The table's fields must outlive the command's parse.
void AddOptions(CLI::App* command, const OptionTable& table);

// A command's options as `Options` declares them (its Declare(OptionTable*)), registered on
// `command` (AddOptions) and bound to the struct returned, which the command's callback runs with
// (the table lives as long as it). `defaults` are the struct's values before parsing.
// `declare`: which of the struct's declarations, when it has several (one per command).
template <typename Options>
std::shared_ptr<Options> AddDeclaredOptions(CLI::App* command,
                                            void (Options::*declare)(OptionTable*),
                                            Options defaults = {}) {
  struct Declared {
    Options options;
    OptionTable table;
  };
  auto declared = std::make_shared<Declared>();
  declared->options = std::move(defaults);
  (declared->options.*declare)(&declared->table);
  AddOptions(command, declared->table);
  return std::shared_ptr<Options>(declared, &declared->options);
}
template <typename Options>
std::shared_ptr<Options> AddDeclaredOptions(CLI::App* command, Options defaults = {}) {
  return AddDeclaredOptions(command, &Options::Declare, std::move(defaults));
}

// A stage's progress lines as the command line shows them: logged (spdlog, info), or printed on
// stdout as they are (the calibration stages' reports).
ProgressCallback LogProgress();
ProgressCallback PrintProgress();

// A projector's monitor, "glfw:N|NAME" (procam show --list), as a fullscreen window. Throws
// IoError naming the display: not glfw:..., no such monitor, a build without GLFW.
std::shared_ptr<PatternDisplay> OpenMonitorDisplay(const std::string& text);

}  // namespace procam
