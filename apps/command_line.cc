#include "apps/command_line.h"

#include <spdlog/fmt/fmt.h>
#include <spdlog/spdlog.h>

#include <CLI/CLI.hpp>
#include <cmath>
#include <cstdio>
#include <limits>
#include <map>

#include "base/io.h"
#include "procam/config.h"
#if PROCAM_WITH_GLFW
#include "projection/glfw_display.h"
#endif

namespace procam {

void AddOptions(CLI::App* command, const OptionTable& table) {
  for (const OptionTable::Option& option : table.options()) {
    const std::string flag = option.positional ? option.name : "--" + option.name;
    std::string help = option.help;
    if (!option.unit.empty()) help += " (" + option.unit + ")";
    const auto set = option.set;
    if (option.kind == OptionTable::Kind::kFlag) {
      // --NAME sets it, --NAME=false clears it (CLI11 counts a false as -1).
      command->add_flag_function(
          flag,
          [set](std::int64_t count) {
            std::string why;
            set(count > 0 ? "true" : "false", &why);
          },
          help);
      continue;
    }
    CLI::Option* added = nullptr;
    if (option.kind == OptionTable::Kind::kList) {
      // Every occurrence's items together; one value split at commas unless one item per flag.
      const auto set_items = option.set_items;
      added = command->add_option_function<std::vector<std::string>>(
          flag,
          [set_items, flag](const std::vector<std::string>& items) {
            std::string why;
            if (!set_items(items, &why)) throw CLI::ValidationError(flag, why);
          },
          help);
      if (!option.repeated && !option.positional) added->delimiter(',');
      added->type_name(option.values);
    } else {
      added = command->add_option_function<std::string>(
          flag,
          [set, flag](const std::string& text) {
            std::string why;
            if (!set(text, &why)) throw CLI::ValidationError(flag, why);
          },
          help);
    }
    if (option.required) added->required();
    if (!option.default_text.empty()) added->default_str(option.default_text);
    switch (option.kind) {
      case OptionTable::Kind::kInteger:
        added->type_name("INT in " + option.range->Text());
        break;
      case OptionTable::Kind::kNumber:
        added->type_name("FLOAT in " + option.range->Text());
        break;
      case OptionTable::Kind::kChoice: {
        std::string choices;
        for (const std::string& choice : option.choices)
          choices += (choices.empty() ? "" : "|") + choice;
        added->type_name("{" + choices + "}");
        break;
      }
      case OptionTable::Kind::kPath:
        added->type_name("PATH");
        break;
      case OptionTable::Kind::kCustom:
        added->type_name(option.values);
        break;
      case OptionTable::Kind::kList:
        break;
      default:
        added->type_name("TEXT");
        break;
    }
  }
}

ProgressCallback LogProgress() {
  return [](const std::string& line) { spdlog::info("{}", line); };
}

ProgressCallback PrintProgress() {
  return [](const std::string& line) {
    std::printf("%s\n", line.c_str());
    std::fflush(stdout);
  };
}

std::shared_ptr<PatternDisplay> OpenMonitorDisplay(const std::string& text) {
  if (text.rfind("glfw:", 0) != 0) {
    throw IoError("display '" + text + "': unknown; use glfw:N|NAME (procam show --list)");
  }
#if PROCAM_WITH_GLFW
  try {
    return std::make_shared<GlfwDisplay>(FindMonitor(text.substr(5)));
  } catch (const IoError& error) {
    throw IoError("display '" + text + "': " + error.what());
  }
#else
  throw IoError("display '" + text +
                "': this build has no GLFW output backend (reconfigure with -DPROCAM_WITH_GLFW=ON; "
                "apt-get install libglfw3-dev libgl-dev libx11-dev libxrandr-dev)");
#endif
}

}  // namespace procam
