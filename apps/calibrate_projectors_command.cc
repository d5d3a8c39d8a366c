// procam calibrate projectors SESSION_DIR... --scene SCENE --out RIG_DIR, or without --scene
// (the room scanned: --floor-chessboard PHOTO or --camera-height M)
// (pipeline/projectors_stage.h), its options as ProjectorsStageOptions declares them.
#include <filesystem>
#include <memory>
#include <string>

#include "apps/command_line.h"
#include "apps/commands.h"
#include "base/io.h"
#include "base/output_directory.h"
#include "geometry/stage.h"
#include "pipeline/projectors_stage.h"

namespace procam {
namespace {

// A scene file, or a synthetic scene by name ("c_shaped" or "synthetic:c_shaped").
std::string ResolveScene(const std::string& text) {
  if (std::filesystem::is_regular_file(text)) return text;
  const std::string named = text.rfind("synthetic:", 0) == 0 ? text : "synthetic:" + text;
  try {
    LoadSceneArgument(named);
  } catch (const IoError& error) {
    throw IoError("--scene " + text + ": no such file, nor a synthetic scene (" + error.what() + ")");
  }
  return named;
}

}  // namespace

void AddCalibrateProjectorsCommand(CLI::App& calibrate) {
  CLI::App* command = calibrate.add_subcommand(
      "projectors",
      "Projectors' intrinsics and poses and the camera's pose in the room, from structured-light "
      "sessions (one per projector) and the scene model, or without --scene from the structured "
      "light alone (the room scanned into RIG_DIR/room.json); camera intrinsics held fixed unless "
      "--refine-camera");
  const auto options = AddDeclaredOptions<ProjectorsStageOptions>(command);
  command->callback([options] {
    CheckOutputDirectory(options->out, DirectoryKind::kRig);
    std::string why;
    if (!options->Check(&why)) throw std::invalid_argument(why);
    if (!options->scene.empty()) options->scene = ResolveScene(options->scene);
    options->progress = PrintProgress();
    RunProjectorsStage(*options);
  });
}

}  // namespace procam
