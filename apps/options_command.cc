// procam options: every option declared in an option table (base/option_table.h), with its
// default, values, unit and help, as text or as the Markdown of docs/options.md.
#include <iostream>
#include <memory>
#include <string>

#include "apps/command_line.h"
#include "apps/commands.h"
#include "calibration/calibrated_room.h"
#include "compensation/stage.h"
#include "projection/stage.h"
#include "verification/verification.h"

namespace procam {
namespace {

// The declared option groups at their defaults, in the order docs/options.md lists them.
struct DeclaredOptions {
  CompensationOptions compensation;
  CalibratedRoomOptions room;
  ProjectionStageOptions projection;
  VerificationOptions verification;
  struct Group {
    std::string title, struct_name, commands;
    OptionTable table;
  };
  std::vector<Group> groups;

  DeclaredOptions() {
    groups.push_back({"The solve", "CompensationOptions (compensation/stage.h)", "compensate",
                      OptionTable("compensate")});
    compensation.Declare(&groups.back().table);
    groups.push_back({"The room", "CalibratedRoomOptions (calibration/calibrated_room.h)",
                      "compensate", OptionTable("room")});
    room.Declare(&groups.back().table);
    groups.push_back({"Projector images", "ProjectionStageOptions (projection/stage.h)", "project",
                      OptionTable("project")});
    projection.Declare(&groups.back().table);
    groups.push_back({"The closed loop and its photos",
                      "VerificationOptions (verification/verification.h), SequencerOptions "
                      "(capture/sequencer.h)",
                      "verify", OptionTable("verify")});
    verification.Declare(&groups.back().table);
  }
};

}  // namespace

std::string DeclaredOptionsMarkdown() {
  DeclaredOptions declared;
  std::string text;
  for (const DeclaredOptions::Group& group : declared.groups) {
    text += "### " + group.title + "\n\n`" + group.struct_name + "`; used by: " + group.commands +
            "\n\n" + group.table.Markdown() + "\n";
  }
  return text;
}

void AddOptionsCommand(CLI::App& app) {
  auto markdown = std::make_shared<bool>(false);
  CLI::App* cmd = app.add_subcommand(
      "options", "List the options declared once per stage: default, values, unit, help");
  cmd->add_flag("--markdown", *markdown, "As the Markdown tables of docs/options.md");
  cmd->callback([markdown] {
    if (*markdown) {
      std::cout << DeclaredOptionsMarkdown();
      return;
    }
    DeclaredOptions declared;
    for (const DeclaredOptions::Group& group : declared.groups) {
      std::cout << group.title << " (" << group.struct_name << "; " << group.commands << ")\n";
      for (const OptionTable::Option& option : group.table.options()) {
        std::cout << "  --" << option.name << " [" << option.default_text << "]  " << option.help
                  << (option.unit.empty() ? "" : " (" + option.unit + ")") << "\n";
      }
    }
  });
}

}  // namespace procam
