// procam project (a compensation solution → one image per projector), procam show (images or
// test patterns fullscreen on projector monitors) and procam bench projection (images for two
// 1920×1080 projectors from a solution, timed): each parses, calls its library function, prints.
#include <memory>

#include "apps/command_line.h"
#include "apps/commands.h"
#include "base/io.h"
#include "base/output_directory.h"
#include "datasets_synthetic/benchmarks.h"
#include "datasets_synthetic/play_benchmark.h"
#include "procam/config.h"
#include "projection/calibrated_room.h"
#include "projection/show.h"
#include "projection/stage.h"

namespace procam {

void AddProjectionCommands(CLI::App& app) {
  CLI::App* project =
      app.add_subcommand("project", "Turn a compensation solution into one image per projector");
  const auto project_options = AddDeclaredOptions<ProjectionStageOptions>(project);
  project->callback([project_options] {
    CheckOutputDirectory(project_options->out, DirectoryKind::kProjectorImages);
    project_options->progress = PrintProgress();
    ProjectSolution(*project_options);
  });

  CLI::App* show = app.add_subcommand(
      "show", "Show images (or a test pattern) fullscreen on projector monitors");
  const auto show_options = AddDeclaredOptions<ShowOptions>(show);
  show->callback([show_options] {
#if PROCAM_WITH_GLFW
    show_options->progress = PrintProgress();
    RunShow(*show_options);
#else
    throw IoError(
        "procam show: this build has no GLFW output backend (reconfigure with "
        "-DPROCAM_WITH_GLFW=ON; needs libglfw3-dev, libgl-dev, libx11-dev and libxrandr-dev)");
#endif
  });

  // `procam bench projection` joins the bench group when it exists (AddBenchCommands ran).
  CLI::App* bench = nullptr;
  for (CLI::App* sub : app.get_subcommands([](CLI::App* s) { return s->get_name() == "bench"; }))
    bench = sub;
  if (bench == nullptr) bench = app.add_subcommand("bench", "Benchmarks on generated rooms");
  CLI::App* bench_projection = bench->add_subcommand(
      "projection", "Images for two projectors from a solution (default 1920x1080)");
  const auto projection_options = AddDeclaredOptions<ProjectionBenchmarkOptions>(bench_projection);
  bench_projection->callback([projection_options] {
    projection_options->progress = PrintProgress();
    RunProjectionBenchmark(*projection_options);
  });

  CLI::App* bench_play = bench->add_subcommand(
      "play", "One frame of procam play: new desired colours -> warm-started solve -> images of 3 projectors");
  const auto play_options = AddDeclaredOptions<PlayBenchmarkOptions>(bench_play);
  bench_play->callback([play_options] {
    play_options->progress = PrintProgress();
    RunPlayBenchmark(*play_options);
  });
}

}  // namespace procam
