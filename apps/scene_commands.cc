// procam scene info / write / random / judge-scan / export, and procam demo: each command's
// options as its Options struct declares them (datasets_synthetic/scene_info.h, random_rooms.h,
// scan_judge.h, demo.h).
#include <spdlog/fmt/fmt.h>

#include <iostream>
#include <memory>

#include "apps/command_line.h"
#include "apps/commands.h"
#include "base/io.h"
#include "capture/devices.h"
#include "datasets_synthetic/demo.h"
#include "datasets_synthetic/random_rooms.h"
#include "datasets_synthetic/scan_judge.h"
#include "datasets_synthetic/scene_info.h"

namespace procam {

void AddSceneCommands(CLI::App& app) {
  CLI::App* scene = app.add_subcommand("scene", "Inspect and export scenes");
  scene->require_subcommand(1);

  CLI::App* info_cmd =
      scene->add_subcommand("info", "Print surfaces, areas, patches and form-factor statistics");
  const auto info = AddDeclaredOptions(info_cmd, &SceneFileOptions::DeclareInfo);
  info_cmd->callback([info] {
    info->progress = LogProgress();
    std::cout << DescribeSceneFile(*info);
  });

  CLI::App* write_cmd = scene->add_subcommand("write",
                                              "Write a built-in synthetic scene as a scene file "
                                              "with its projectors and camera (open it as a "
                                              "synthetic rig: --camera synthetic:DIR/NAME.json)");
  const auto write = AddDeclaredOptions(write_cmd, &SceneFileOptions::DeclareWrite);
  write_cmd->callback([write] {
    const std::filesystem::path path = WriteSceneFile(*write);
    std::cout << "wrote " << path.string() << " with its projectors' and camera's models; open it as a rig with "
              << "--camera synthetic:" << path.string() << "\n";
  });

  CLI::App* random_cmd = scene->add_subcommand(
      "random", "Write a room made at random from a seed as a scene file with its projectors and camera "
                "(docs/synthetic.md#rooms-made-at-random)");
  const auto random = AddDeclaredOptions<RandomRoomOptions>(random_cmd);
  auto random_out = std::make_shared<std::string>();
  random_cmd->add_option("--out", *random_out, "Output directory")->required();
  random_cmd->callback([random, random_out] {
    const std::filesystem::path path = WriteRandomRoom(*random, *random_out);
    std::cout << "wrote " << path.string() << "; open it as a rig with --camera synthetic:" << path.string()
              << "\n";
  });

  auto judge_json = std::make_shared<std::string>();
  CLI::App* judge_cmd = scene->add_subcommand(
      "judge-scan", "Scan a scene file's rig without its model (exact correspondences plus decoding noise) and "
                    "judge the scanned room against the file (docs/scan.md#rooms-made-at-random)");
  auto judge_scene = std::make_shared<std::string>();
  judge_cmd->add_option("scene", *judge_scene, "Scene JSON with projectors and a camera")
      ->required();
  const auto judge = AddDeclaredOptions<ScanJudgeOptions>(judge_cmd);
  judge_cmd->add_option("--json", *judge_json, "Also write the judgement as JSON to this file");
  judge_cmd->callback([judge, judge_json, judge_scene] {
    const ScanJudgement judgement = ScanAndJudge(*judge_scene, *judge);
    std::cout << judgement.calibration_report << "\n" << judgement.Report() << "\n"
              << fmt::format("judged {} calibrated {} found {} expected {} planar_rms_mm {:.2f} curved_rms_mm {:.2f} "
                             "area_percent {:+.2f} spurious_percent {:.2f} delta_e2000_model {:.2f} delta_e2000_scan {:.2f} "
                             "seam_scan {:.2f} seconds {:.1f}\n",
                             judgement.room, judgement.calibrated ? 1 : 0, judgement.found, judgement.expected,
                             judgement.worst_planar_rms_mm, judgement.worst_curved_rms_mm,
                             judgement.worst_area_error_percent, judgement.largest_spurious_percent,
                             judgement.model_delta_e2000, judgement.scan_delta_e2000, judgement.scan_seam,
                             judgement.seconds);
    if (!judge_json->empty()) WriteFileAtomically(*judge_json, judgement.Json().dump(2) + "\n");
  });

  CLI::App* export_cmd = scene->add_subcommand("export", "Write the problem as NumPy .npy files and problem.json");
  const auto exported = AddDeclaredOptions(export_cmd, &SceneFileOptions::DeclareExport);
  export_cmd->callback([exported] {
    exported->progress = LogProgress();
    std::cout << ExportSceneProblem(*exported) << "exported to " << exported->out.string() << "\n";
  });
}

void AddDemoCommand(CLI::App& app) {
  CLI::App* demo = app.add_subcommand(
      "demo", "Every pipeline stage on the synthetic rig: geometry, compensation (4 methods), projector images, "
              "simulated photos, ΔE, report.html");
  const auto options = AddDeclaredOptions<SyntheticDemoOptions>(demo);
  demo->callback([options] {
    if (!options->camera.empty()) RegisterDeviceBackends();
    options->open_display = OpenMonitorDisplay;
    options->progress = LogProgress();
    options->steps = PrintProgress();
    std::cout << RunDemo(*options);
  });
}

}  // namespace procam
