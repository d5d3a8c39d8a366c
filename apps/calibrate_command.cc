// procam calibrate camera SESSION_DIR --out RIG_DIR (pipeline/camera_stage.h), procam
// calibrate board SESSION... --out RIG_DIR (pipeline/board_stage.h) and procam calibrate
// photometric SESSION_DIR --out RIG_DIR (pipeline/photometric_stage.h): each stage's options
// as its option table declares them.
#include <memory>

#include "apps/command_line.h"
#include "apps/commands.h"
#include "base/output_directory.h"
#include "pipeline/board_stage.h"
#include "pipeline/camera_stage.h"
#include "pipeline/photometric_stage.h"

namespace procam {

void AddCalibrateCommands(CLI::App& app) {
  CLI::App* calibrate = app.add_subcommand("calibrate", "Calibrate the rig from captures");
  calibrate->require_subcommand(1);

  CLI::App* camera = calibrate->add_subcommand(
      "camera", "Camera intrinsics from chessboard images (OpenCV detection, mrcal refinement)");
  const auto camera_options = AddDeclaredOptions<CameraStageOptions>(camera);
  camera->callback([camera_options] {
    CheckOutputDirectory(camera_options->out, DirectoryKind::kRig);
    camera_options->progress = PrintProgress();
    RunCameraStage(*camera_options);
  });

  CLI::App* photometric = calibrate->add_subcommand(
      "photometric",
      "Projector black, max, gamma, response table and mixing from a photometric capture "
      "session (camera units)");
  const auto photometric_options = AddDeclaredOptions<PhotometricStageOptions>(photometric);
  photometric->callback([photometric_options] {
    CheckOutputDirectory(photometric_options->out, DirectoryKind::kRig);
    photometric_options->progress = PrintProgress();
    RunPhotometricStage(*photometric_options);
  });

  CLI::App* board = calibrate->add_subcommand(
      "board",
      "Camera and projector together from a chessboard held at several poses, one "
      "structured-light session per pose (docs/chessboard.md)");
  const auto board_options = AddDeclaredOptions<BoardStageOptions>(board);
  board->callback([board_options] {
    board_options->progress = PrintProgress();
    CheckOutputDirectory(board_options->out, DirectoryKind::kRig);
    RunBoardStage(*board_options);
  });

  AddCalibrateResponseCommand(*calibrate);
  AddCalibrateAllCommand(*calibrate);
  AddCalibrateProjectorsCommand(*calibrate);
}

}  // namespace procam
