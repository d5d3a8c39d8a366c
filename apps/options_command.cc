// procam options: every option declared in an option table (base/option_table.h), with its
// default, values, unit and help, as text or as the Markdown of docs/options.md.
#include <iostream>
#include <memory>
#include <string>

#include "apps/command_line.h"
#include "apps/commands.h"
#include "calibration/capture_layout.h"
#include "capture/camera.h"
#include "compensation/stage.h"
#include "datasets_synthetic/benchmarks.h"
#include "datasets_synthetic/demo.h"
#include "datasets_synthetic/emulated_room.h"
#include "datasets_synthetic/evaluation.h"
#include "datasets_synthetic/play_benchmark.h"
#include "datasets_synthetic/random_rooms.h"
#include "datasets_synthetic/scan_judge.h"
#include "datasets_synthetic/scene_info.h"
#include "nodes/node.h"
#include "nodes/play.h"
#include "pipeline/board_stage.h"
#include "pipeline/calibrate_all_stage.h"
#include "pipeline/camera_stage.h"
#include "pipeline/capture_stage.h"
#include "pipeline/photometric_stage.h"
#include "pipeline/projectors_stage.h"
#include "pipeline/response_stage.h"
#include "projection/calibrated_room.h"
#include "projection/show.h"
#include "projection/stage.h"
#include "verification/verification.h"

namespace procam {
namespace {

// The declared option groups at their defaults, in the order docs/options.md lists them.
struct DeclaredOptions {
  struct Group {
    std::string title, struct_name, commands;
    std::shared_ptr<void> options;  // the struct the table is bound to
    OptionTable table;
  };
  std::vector<Group> groups;

  template <typename Options>
  void Add(const std::string& title, const std::string& struct_name, const std::string& commands,
           void (Options::*declare)(OptionTable*) = &Options::Declare) {
    auto options = std::make_shared<Options>();
    Group& group = groups.emplace_back();
    group.title = title;
    group.struct_name = struct_name;
    group.commands = commands;
    group.table = OptionTable(commands);
    ((*options).*declare)(&group.table);
    group.options = options;
  }

  DeclaredOptions() {
    Add<CompensationOptions>("The solve", "CompensationOptions (compensation/stage.h)",
                             "compensate");
    Add<CalibratedRoomOptions>("The room", "CalibratedRoomOptions (projection/calibrated_room.h)",
                               "compensate");
    Add<SolutionOutputOptions>("The solution written",
                               "SolutionOutputOptions (compensation/stage.h)", "compensate");
    Add<ProjectionStageOptions>("Projector images", "ProjectionStageOptions (projection/stage.h)",
                                "project");
    Add<VerificationOptions>("The closed loop and its photos",
                             "VerificationOptions (verification/verification.h), SequencerOptions "
                             "(capture/sequencer.h)",
                             "verify");
    Add<ShowOptions>("Images on projector monitors", "ShowOptions (projection/show.h)", "show");
    Add<ListCamerasOptions>("Cameras listed", "ListCamerasOptions (capture/camera.h)", "cameras");
    Add<CaptureStageOptions>("Captures", "CaptureStageOptions (pipeline/capture_stage.h)",
                             "capture");
    Add<ImportOptions>("Photos of another tool imported",
                       "ImportOptions (calibration/capture_layout.h)", "import");
    Add<SessionDecodeOptions>("A session decoded",
                              "SessionDecodeOptions, StructuredLightDecodeOptions "
                              "(calibration/capture_layout.h, calibration/structured_light.h)",
                              "decode");
    Add<PatternExportOptions>("Patterns for another program",
                              "PatternExportOptions (calibration/capture_layout.h)", "patterns");
    Add<CameraStageOptions>("Camera intrinsics", "CameraStageOptions (pipeline/camera_stage.h)",
                            "calibrate camera");
    Add<ProjectorsStageOptions>("Projectors and registration",
                                "ProjectorsStageOptions (pipeline/projectors_stage.h)",
                                "calibrate projectors");
    Add<PhotometricStageOptions>("Photometry",
                                 "PhotometricStageOptions (pipeline/photometric_stage.h)",
                                 "calibrate photometric");
    Add<BoardStageOptions>("Camera and projector on a chessboard",
                           "BoardStageOptions (pipeline/board_stage.h)", "calibrate board");
    Add<ResponseStageOptions>("Camera linearity",
                              "ResponseStageOptions (pipeline/response_stage.h)",
                              "calibrate response");
    Add<CalibrateAllOptions>("A whole rig", "CalibrateAllOptions (pipeline/calibrate_all_stage.h)",
                             "calibrate all");
    Add<NodeOptions>("A display node", "NodeOptions (nodes/node.h)", "node");
    Add<PlayOptions>("A show's remote control and playlist", "PlayOptions (nodes/play.h)", "play");
    Add<EmulatedRoomOptions>("The room as a device",
                             "EmulatedRoomOptions (datasets_synthetic/emulated_room.h)", "emulate");
    Add<SceneFileOptions>("A scene described", "SceneFileOptions (datasets_synthetic/scene_info.h)",
                          "scene info", &SceneFileOptions::DeclareInfo);
    Add<SceneFileOptions>("A synthetic scene written",
                          "SceneFileOptions (datasets_synthetic/scene_info.h)", "scene write",
                          &SceneFileOptions::DeclareWrite);
    Add<SceneFileOptions>("A scene's problem exported",
                          "SceneFileOptions (datasets_synthetic/scene_info.h)", "scene export",
                          &SceneFileOptions::DeclareExport);
    Add<RandomRoomOptions>("A room made at random",
                           "RandomRoomOptions (datasets_synthetic/random_rooms.h)", "scene random");
    Add<ScanJudgeOptions>("A scan judged", "ScanJudgeOptions (datasets_synthetic/scan_judge.h)",
                          "scene judge-scan");
    Add<EvaluationOptions>("The evaluation", "EvaluationOptions (datasets_synthetic/evaluation.h)",
                           "evaluate");
    Add<SyntheticDemoOptions>("The demo", "SyntheticDemoOptions (datasets_synthetic/demo.h)",
                              "demo");
    Add<BenchmarkOptions>("Form-factor benchmark",
                          "BenchmarkOptions (datasets_synthetic/benchmarks.h)", "bench formfactors",
                          &BenchmarkOptions::DeclareFormFactors);
    Add<BenchmarkOptions>("Solver benchmark", "BenchmarkOptions (datasets_synthetic/benchmarks.h)",
                          "bench solver", &BenchmarkOptions::DeclareSolver);
    Add<BenchmarkOptions>("Scale benchmark", "BenchmarkOptions (datasets_synthetic/benchmarks.h)",
                          "bench scale", &BenchmarkOptions::DeclareScale);
    Add<DecodeBenchmarkOptions>("Decode benchmark",
                                "DecodeBenchmarkOptions (datasets_synthetic/benchmarks.h)",
                                "bench decode");
    Add<ProjectionBenchmarkOptions>("Projection benchmark",
                                    "ProjectionBenchmarkOptions (datasets_synthetic/benchmarks.h)",
                                    "bench projection");
    Add<PlayBenchmarkOptions>("Play benchmark",
                              "PlayBenchmarkOptions (datasets_synthetic/play_benchmark.h)",
                              "bench play");
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
        std::cout << "  " << (option.positional ? "" : "--") << option.name << " ["
                  << option.default_text << "]  " << option.help
                  << (option.unit.empty() ? "" : " (" + option.unit + ")") << "\n";
      }
    }
  });
}

}  // namespace procam
