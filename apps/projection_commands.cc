// procam project (a compensation solution → one image per projector), procam show (images or
// test patterns fullscreen on projector monitors) and procam bench projection (images for two
// 1920×1080 projectors from a solution, timed): each parses, calls its library function, prints.
#include <cstdio>
#include <array>
#include <memory>
#include <stdexcept>

#include "apps/command_line.h"
#include "apps/commands.h"
#include "base/io.h"
#include "base/output_directory.h"
#include "base/timing.h"
#include "calibration/rig_directory.h"
#include "datasets_synthetic/benchmarks.h"
#include "datasets_synthetic/play_benchmark.h"
#include "procam/config.h"
#include "projection/projector_images.h"
#include "projection/stage.h"
#include "projection/test_pattern.h"
#if PROCAM_WITH_GLFW
#include "projection/glfw_display.h"
#include "projection/show.h"
#endif

namespace procam {
namespace {

// The projection stage's options (declared once by ProjectionStageOptions) and the command's own.
struct ProjectArguments {
  std::string solution, rig;
  int patches = 0;
  ProjectionStageOptions stage;
  OptionTable table{"project"};
};

void RunProject(const ProjectArguments& args) {
  const auto start = Clock::now();
  ProjectionStageOptions options = args.stage;
  const SolutionDirectory solution = ReadSolutionDirectory(args.solution);
  SolutionGeometry geometry = ReadSolutionGeometry(solution, args.patches);
  SolutionProjectors projectors =
      ProjectorsForSolution(solution, args.rig, geometry.scene, &geometry.patches);
  options.load_seconds = SecondsSince(start);
  options.progress = PrintProgress();
  RunProjectionStage(solution, geometry, std::move(projectors.projectors),
                     projectors.rig_description, options, projectors.reflectance_maps);
}

struct ShowArguments {
  std::vector<std::string> images, monitors;
  std::string pattern, readback, placement = "auto";
  double seconds = 0.0;
  bool list = false;
};

#if PROCAM_WITH_GLFW
void RunShowCommand(const ShowArguments& args) {
  if (args.list) {
    for (const MonitorInfo& m : ListMonitors()) {
      std::printf("%d  %-16s %dx%d @ %d Hz at (%d, %d)\n", m.index, m.name.c_str(), m.width,
                  m.height, m.refresh_hz, m.x, m.y);
    }
    return;
  }
  ShowOptions options;
  options.images.assign(args.images.begin(), args.images.end());
  if (!args.pattern.empty()) {
    TestPattern pattern;
    if (!ParseTestPattern(args.pattern, &pattern))
      throw std::invalid_argument("--pattern: unknown pattern " + args.pattern);
    options.pattern = pattern;
  }
  options.monitors = args.monitors;
  ParseWindowPlacement(args.placement, &options.display.placement);  // CLI11 checked the name
  options.readback = args.readback;
  options.seconds = args.seconds;
  options.progress = PrintProgress();
  RunShow(options);
}
#else
void RunShowCommand(const ShowArguments&) {
  throw IoError(
      "procam show: this build has no GLFW output backend (reconfigure with -DPROCAM_WITH_GLFW=ON; "
      "needs libglfw3-dev, libgl-dev, libx11-dev and libxrandr-dev)");
}
#endif

}  // namespace

void AddProjectionCommands(CLI::App& app) {
  auto args = std::make_shared<ProjectArguments>();
  CLI::App* project =
      app.add_subcommand("project", "Turn a compensation solution into one image per projector");
  project
      ->add_option("solution", args->solution,
                   "Directory written by `procam compensate SCENE --out DIR`")
      ->required();
  project->add_option("--out", args->stage.out, "Output directory (PNG per projector, result.json)")
      ->required();
  project->add_option("--rig", args->rig,
                      "Rig directory whose projectors (and reflectance) to use; default: the rig "
                      "the solution was computed with (compensate --rig), else the scene's");
  project->add_option("--patches", args->patches,
                      "Patch target given to compensate with --patches, if any");
  args->stage.Declare(&args->table);
  AddOptions(project, args->table);
  project->callback([args] {
    CheckOutputDirectory(args->stage.out, DirectoryKind::kProjectorImages);
    RunProject(*args);
  });

  auto show_args = std::make_shared<ShowArguments>();
  CLI::App* show = app.add_subcommand(
      "show", "Show images (or a test pattern) fullscreen on projector monitors");
  show->add_option("images", show_args->images, "PNG per projector, in the monitor's resolution");
  show->add_option("--monitor", show_args->monitors,
                   "Monitor index or name (as --list shows), once per image (default: image k "
                   "on monitor k)");
  show->add_option("--placement", show_args->placement,
                   "How windows reach their monitors: auto | window-manager (fullscreen through "
                   "the window manager) | by-hand (placed by procam, the window manager left out)")
      ->check(CLI::IsMember({"auto", "window-manager", "by-hand"}))
      ->capture_default_str();
  show->add_flag("--list", show_args->list, "List the connected monitors and exit");
  show->add_option("--pattern", show_args->pattern,
                   "Test pattern instead of images: grid | bars | white | black")
      ->check(CLI::IsMember({"grid", "bars", "white", "black"}));
  show->add_option("--seconds", show_args->seconds,
                   "Close after this long (default: until Esc or Q)")
      ->check(FiniteRange(0.0, 1e6));
  show->add_option("--readback", show_args->readback,
                   "Write what each window shows (monitorN.png) into this directory");
  show->callback([show_args] { RunShowCommand(*show_args); });

  // `procam bench projection` joins the bench group when it exists (AddBenchCommands ran).
  CLI::App* bench = nullptr;
  for (CLI::App* sub : app.get_subcommands([](CLI::App* s) { return s->get_name() == "bench"; }))
    bench = sub;
  if (bench == nullptr) bench = app.add_subcommand("bench", "Benchmarks on generated rooms");
  auto bench_args = std::make_shared<ProjectionBenchmarkOptions>();
  auto bench_dither = std::make_shared<std::string>("ordered");
  CLI::App* bench_projection = bench->add_subcommand(
      "projection", "Images for two projectors from a solution (default 1920x1080)");
  bench_projection->add_option("--width", bench_args->width, "Projector width, pixels")
      ->capture_default_str();
  bench_projection->add_option("--height", bench_args->height, "Projector height, pixels")
      ->capture_default_str();
  bench_projection->add_option("--patches", bench_args->patches, "Target patch count")
      ->capture_default_str();
  bench_projection->add_option("--repeat", bench_args->repeat, "Timed runs")
      ->check(FiniteRange(1, 1000))
      ->capture_default_str();
  bench_projection->add_option("--dither", *bench_dither, "none | ordered | error-diffusion")
      ->check(CLI::IsMember({"none", "ordered", "error-diffusion"}))
      ->capture_default_str();
  bench_projection->add_flag("--detail", bench_args->detail,
                             "Give every surface a striped texture and render with its detail");
  AddLightOption(bench_projection, &bench_args->light);
  bench_projection->add_option("--json", bench_args->json, "Also write the timings as JSON");
  bench_projection->callback([bench_args, bench_dither] {
    ParseDither(*bench_dither, &bench_args->dither);  // CLI11 checked the name
    bench_args->progress = PrintProgress();
    RunProjectionBenchmark(*bench_args);
  });

  auto play_args = std::make_shared<PlayBenchmarkOptions>();
  auto play_strings = std::make_shared<std::array<std::string, 4>>(
      std::array<std::string, 4>{MethodName(play_args->method), "cpu", "ordered", "cpu"});
  CLI::App* bench_play = bench->add_subcommand(
      "play", "One frame of procam play: new desired colours -> warm-started solve -> images of 3 projectors");
  bench_play->add_option("--width", play_args->width, "Projector width, pixels")->capture_default_str();
  bench_play->add_option("--height", play_args->height, "Projector height, pixels")->capture_default_str();
  bench_play->add_option("--patches", play_args->patches, "Target patch count (3 variables each)")->capture_default_str();
  bench_play->add_option("--frames", play_args->frames, "Timed frames (after a first, cold one)")
      ->check(FiniteRange(1, 10000))
      ->capture_default_str();
  bench_play->add_option("--method", (*play_strings)[0], "linear | perceptual | perceptual2000")
      ->check(CLI::IsMember({"linear", "perceptual", "perceptual2000"}))
      ->capture_default_str();
  bench_play->add_option("--device", (*play_strings)[1], "cpu | cuda")->check(CLI::IsMember({"cpu", "cuda"}))->capture_default_str();
  bench_play->add_option("--dither", (*play_strings)[2], "none | ordered")->check(CLI::IsMember({"none", "ordered"}))->capture_default_str();
  bench_play->add_option("--render", (*play_strings)[3],
                         "cpu | gpu: the images shaded on the CPU, or drawn by OpenGL into an offscreen "
                         "context (EGL: a GPU, or Mesa's llvmpipe)")
      ->check(CLI::IsMember({"cpu", "gpu"}))
      ->capture_default_str();
  bench_play->add_option("--shader", play_args->shader,
                         "auto | fragment | compute: with --render gpu, the shader path (auto: "
                         "compute where the context has OpenGL 4.3)")
      ->check(CLI::IsMember({"auto", "fragment", "compute"}))
      ->capture_default_str();
  AddPlayToleranceOption(bench_play, &play_args->tolerance);
  AddLightOption(bench_play, &play_args->light);
  bench_play->add_option("--json", play_args->json, "Also write the timings as JSON");
  bench_play->callback([play_args, play_strings] {
    ParseMethod((*play_strings)[0], &play_args->method);
    ParseDevice((*play_strings)[1], &play_args->device);
    ParseDither((*play_strings)[2], &play_args->dither);
    play_args->render = (*play_strings)[3] == "gpu" ? PlayRender::kGpu : PlayRender::kCpu;
    play_args->progress = PrintProgress();
    RunPlayBenchmark(*play_args);
  });
}

}  // namespace procam
