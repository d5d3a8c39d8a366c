// procam project (a compensation solution → one image per projector), procam show (images or
// test patterns fullscreen on projector monitors) and procam bench projection (images for two
// 1920×1080 projectors from a solution, timed).
#include <spdlog/spdlog.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <iostream>
#include <memory>
#include <optional>
#include <nlohmann/json.hpp>
#include <opencv2/core.hpp>
#include <random>
#include <thread>

#include "apps/command_line.h"
#include "apps/commands.h"
#include "projection/stage.h"
#include "geometry/stage.h"
#include "calibration/rig_directory.h"
#include "datasets_synthetic/rooms.h"
#include "base/io.h"
#include "geometry/patches.h"
#include "geometry/scene.h"
#include "procam/config.h"
#include "projection/projection_rig.h"
#include "projection/projector.h"
#include "projection/projector_images.h"
#include "projection/test_pattern.h"
#if PROCAM_WITH_GLFW
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "projection/glfw_display.h"
#endif

namespace procam {
namespace {

using Clock = std::chrono::steady_clock;

double SecondsSince(Clock::time_point start) {
  return std::chrono::duration<double>(Clock::now() - start).count();
}

struct ProjectArguments {
  std::string solution, out, rig, dither = "ordered";
  LightField light = LightField::kSmooth;
  double feather = 0.1;
  int patches = 0;
  bool detail = false;
};

void RunProject(const ProjectArguments& args) {
  const auto start = Clock::now();
  ProjectionStageOptions options;
  if (!ParseDither(args.dither, &options.dither)) throw std::invalid_argument("--dither: unknown method " + args.dither);
  const SolutionDirectory solution = ReadSolutionDirectory(args.solution);
  SolutionGeometry geometry = ReadSolutionGeometry(solution, args.patches);
  SolutionProjectors projectors = ProjectorsForSolution(solution, args.rig, geometry.scene, &geometry.patches);
  options.out = args.out;
  options.feather = args.feather;
  options.detail = args.detail;
  options.light = args.light;
  options.load_seconds = SecondsSince(start);
  options.progress = PrintProgress();
  RunProjectionStage(solution, geometry, std::move(projectors.projectors), projectors.rig_description, options);
}

struct BenchProjectionArguments {
  int width = 1920, height = 1080, patches = 1000, repeat = 10;
  std::string dither = "ordered", json;
  bool detail = false;
};

// A 1024×1024 texture of crossed sinusoidal stripes (linear RGB), ~40 periods across: detail
// finer than the bench's patches, for timing RenderOptions::detail.
cv::Mat BenchTexture() {
  constexpr int kSize = 1024;
  constexpr double kTwoPi = 6.283185307179586;
  cv::Mat texture(kSize, kSize, CV_32FC3);
  for (int y = 0; y < kSize; ++y) {
    for (int x = 0; x < kSize; ++x) {
      const double u = (x + 0.5) / kSize, v = (y + 0.5) / kSize;
      texture.at<cv::Vec3f>(y, x) =
          cv::Vec3f(static_cast<float>(0.5 + 0.3 * std::sin(kTwoPi * 40 * u)),
                    static_cast<float>(0.5 + 0.3 * std::sin(kTwoPi * 40 * v)),
                    static_cast<float>(0.5 + 0.3 * std::sin(kTwoPi * 28 * (u + v))));
    }
  }
  return texture;
}

void RunProjectionBench(const BenchProjectionArguments& args) {
  DitherMethod dither;
  if (!ParseDither(args.dither, &dither))
    throw std::invalid_argument("--dither: unknown method " + args.dither);
  BoxRoomOptions room;
  room.target_patches = args.patches;
  Scene scene = MakeBoxRoom(room);
  if (args.detail) {
    const cv::Mat texture = BenchTexture();
    for (Surface& surface : scene.surfaces) surface.desired.texture_linear = texture;
  }
  SubdivisionOptions subdivision;
  subdivision.target_patches = args.patches;
  const PatchHierarchy hierarchy = SubdividePatches(scene, subdivision);
  // Two projectors near the front wall, overlapping on the back wall and the occluder.
  std::vector<Projector> projectors;
  for (const double x : {1.2, 2.8}) {
    Projector projector;
    projector.name = x < 2.0 ? "left" : "right";
    projector.geometry = ProjectorGeometry(
        "LENSMODEL_OPENCV4",
        {1.0 * args.width, 1.0 * args.width, 0.5 * (args.width - 1), 0.9 * args.height, -0.05, 0.01,
         0.0, 0.0},
        args.width, args.height,
        ProjFromWorldLookingAt(Vec3(x, 0.2, 2.2), Vec3(4.0 - x, 3.0, 0.8), Vec3::UnitZ()));
    projector.photometry.black = Vec3::Constant(0.01);
    projector.photometry.max = Vec3(9.0, 10.0, 8.5);
    projectors.push_back(projector);
  }
  ProjectionRigSummary rig_summary;
  ProjectionRigOptions rig_options;
  rig_options.texture_coordinates = args.detail;
  const ProjectionRig rig =
      BuildProjectionRig(hierarchy.fine, projectors, rig_options, &rig_summary);
  std::mt19937 random(1);
  std::uniform_real_distribution<double> unit(0.05, 0.95);
  Eigen::MatrixX3d emittance(rig.size(), 3);
  for (int i = 0; i < rig.size(); ++i) {
    for (int c = 0; c < 3; ++c)
      emittance(i, c) = rig.lower(i, c) + unit(random) * (rig.upper(i, c) - rig.lower(i, c));
  }
  RenderOptions options;
  options.dither = dither;
  options.detail = args.detail;
  std::vector<double> render_times, encode_times;
  RenderSummary summary;
  for (int r = 0; r < args.repeat; ++r) {
    const std::vector<ProjectorImage> images =
        RenderProjectorImages(rig, scene, emittance, options, &summary);
    render_times.push_back(summary.seconds);
    const auto start = Clock::now();
    EncodeProjectorImages(images);
    encode_times.push_back(SecondsSince(start));
  }
  std::sort(render_times.begin(), render_times.end());
  std::sort(encode_times.begin(), encode_times.end());
  const double render_median = render_times[render_times.size() / 2];
  const double encode_median = encode_times[encode_times.size() / 2];
  std::printf(
      "projection: 2 projectors %dx%d (OpenCV4 lens), closed room with occluder, %d patches\n",
      args.width, args.height, rig.size());
  std::printf("  maps (once per rig: unproject, %lld rays + blending shadow rays): %.3f s\n",
              2LL * args.width * args.height, rig_summary.seconds);
  std::printf(
      "  images from a solution (%s dither%s, %d level passes): median %.1f ms, min %.1f ms over "
      "%d runs\n",
      DitherName(dither), args.detail ? ", textures' detail" : "", summary.level_passes,
      1e3 * render_median, 1e3 * render_times.front(), args.repeat);
  std::printf("  PNG encoding of both: median %.1f ms\n", 1e3 * encode_median);
  std::printf("  largest delivered-emittance error %.2e (relative)\n", summary.max_relative_error);
  if (!args.json.empty()) {
    const nlohmann::json result = {{"benchmark", "projection"},
                                   {"width", args.width},
                                   {"height", args.height},
                                   {"projectors", 2},
                                   {"patches", rig.size()},
                                   {"dither", DitherName(dither)},
                                   {"detail", args.detail},
                                   {"maps_seconds", rig_summary.seconds},
                                   {"render_seconds_median", render_median},
                                   {"render_seconds_min", render_times.front()},
                                   {"png_encode_seconds_median", encode_median},
                                   {"repeat", args.repeat},
                                   {"max_relative_error", summary.max_relative_error}};
    WriteFileAtomically(args.json, result.dump(2) + "\n");
  }
}

struct ShowArguments {
  std::vector<std::string> images, monitors;
  std::string pattern, readback;
  double seconds = 0.0;
  bool list = false;
};

#if PROCAM_WITH_GLFW
void RunShow(const ShowArguments& args) {
  if (args.list) {
    for (const MonitorInfo& m : ListMonitors()) {
      std::printf("%d  %-16s %dx%d @ %d Hz at (%d, %d)\n", m.index, m.name.c_str(), m.width,
                  m.height, m.refresh_hz, m.x, m.y);
    }
    return;
  }
  TestPattern pattern = TestPattern::kGrid;
  if (!args.pattern.empty() && !ParseTestPattern(args.pattern, &pattern)) {
    throw std::invalid_argument("--pattern: unknown pattern " + args.pattern);
  }
  if (args.images.empty() == args.pattern.empty()) {
    throw std::invalid_argument("give either images to show or --pattern (not both)");
  }
  // Which monitor each output goes to: as given, else image k on monitor k, or a pattern on all.
  std::vector<MonitorInfo> monitors;
  if (!args.monitors.empty()) {
    if (!args.images.empty() && args.monitors.size() != args.images.size()) {
      throw std::invalid_argument(std::to_string(args.images.size()) + " images but " +
                                  std::to_string(args.monitors.size()) +
                                  " --monitor options (one per image)");
    }
    for (const std::string& which : args.monitors) monitors.push_back(FindMonitor(which));
  } else {
    const std::vector<MonitorInfo> all = ListMonitors();
    if (args.images.size() > all.size()) {
      throw IoError(std::to_string(args.images.size()) + " images but only " +
                    std::to_string(all.size()) + " monitor(s) connected");
    }
    monitors.assign(all.begin(),
                    args.images.empty() ? all.end() : all.begin() + args.images.size());
  }
  // Read and check every image before any window opens.
  std::vector<cv::Mat> images;
  for (size_t k = 0; k < args.images.size(); ++k) {
    const std::string& file = args.images[k];
    if (!std::filesystem::exists(file)) throw IoError(file + ": file not found");
    cv::Mat image = cv::imread(file, cv::IMREAD_UNCHANGED);
    if (image.empty()) throw IoError(file + ": not a readable image");
    if (image.channels() == 4) cv::cvtColor(image, image, cv::COLOR_BGRA2BGR);
    if (image.cols != monitors[k].width || image.rows != monitors[k].height) {
      throw IoError(file + ": image is " + std::to_string(image.cols) + "x" +
                    std::to_string(image.rows) + ", but monitor " +
                    std::to_string(monitors[k].index) + " '" + monitors[k].name + "' runs at " +
                    std::to_string(monitors[k].width) + "x" + std::to_string(monitors[k].height));
    }
    images.push_back(image);
  }
  std::vector<std::unique_ptr<GlfwDisplay>> displays;
  for (size_t k = 0; k < monitors.size(); ++k) {
    displays.push_back(std::make_unique<GlfwDisplay>(monitors[k]));
    if (images.empty()) {
      displays.back()->Show(MakeTestPattern(pattern, displays.back()->Resolution()));
    } else {
      displays.back()->Show(images[k]);
    }
    std::printf("monitor %d '%s' %dx%d: %s\n", monitors[k].index, monitors[k].name.c_str(),
                monitors[k].width, monitors[k].height,
                images.empty() ? TestPatternName(pattern) : args.images[k].c_str());
  }
  if (!args.readback.empty()) {
    std::filesystem::create_directories(args.readback);
    for (size_t k = 0; k < displays.size(); ++k) {
      cv::Mat bgr;
      cv::cvtColor(displays[k]->ReadBack(), bgr, cv::COLOR_RGB2BGR);
      std::vector<uchar> bytes;
      cv::imencode(".png", bgr, bytes);
      WriteFileAtomically(std::filesystem::path(args.readback) /
                              ("monitor" + std::to_string(monitors[k].index) + ".png"),
                          std::string(bytes.begin(), bytes.end()));
    }
  }
  if (args.seconds <= 0.0) std::printf("Esc or Q in a window ends\n");
  const auto start = Clock::now();
  while (args.seconds <= 0.0 || SecondsSince(start) < args.seconds) {
    bool open = true;
    for (const auto& display : displays) open &= display->PollEvents();
    if (!open) break;
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
}
#else
void RunShow(const ShowArguments&) {
  throw IoError(
      "procam show: this build has no GLFW output backend (reconfigure with -DPROCAM_WITH_GLFW=ON; "
      "needs libglfw3-dev and libgl-dev)");
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
  project->add_option("--out", args->out, "Output directory (PNG per projector, result.json)")
      ->required();
  project
      ->add_option("--rig", args->rig,
                   "Rig directory whose projectors (and reflectance) to use; default: the rig "
                   "the solution was computed with (compensate --rig), else the scene's");
  project->add_option("--dither", args->dither, "none | ordered | error-diffusion")
      ->check(CLI::IsMember({"none", "ordered", "error-diffusion"}))
      ->capture_default_str();
  project
      ->add_option("--feather", args->feather,
                   "Blending ramp at image borders, fraction of the image size")
      ->check(CLI::Range(0.0, 0.5))
      ->capture_default_str();
  project->add_option("--patches", args->patches,
                      "Patch target given to compensate with --patches, if any");
  AddLightOption(project, &args->light);
  project->add_flag("--detail", args->detail,
                    "Modulate the light within each patch by the desired texture's detail "
                    "(patch totals unchanged; untextured surfaces as without)");
  project->callback([args] { RunProject(*args); });

  auto show_args = std::make_shared<ShowArguments>();
  CLI::App* show = app.add_subcommand(
      "show", "Show images (or a test pattern) fullscreen on projector monitors");
  show->add_option("images", show_args->images, "PNG per projector, in the monitor's resolution");
  show->add_option("--monitor", show_args->monitors,
                   "Monitor index or name, once per image (default: image k on monitor k)");
  show->add_flag("--list", show_args->list, "List the connected monitors and exit");
  show->add_option("--pattern", show_args->pattern,
                   "Test pattern instead of images: grid | bars | white | black")
      ->check(CLI::IsMember({"grid", "bars", "white", "black"}));
  show->add_option("--seconds", show_args->seconds,
                   "Close after this long (default: until Esc or Q)")
      ->check(CLI::Range(0.0, 1e6));
  show->add_option("--readback", show_args->readback,
                   "Write what each window shows (monitorN.png) into this directory");
  show->callback([show_args] { RunShow(*show_args); });

  // `procam bench projection` joins the bench group when it exists (AddBenchCommands ran).
  CLI::App* bench = nullptr;
  for (CLI::App* sub : app.get_subcommands([](CLI::App* s) { return s->get_name() == "bench"; }))
    bench = sub;
  if (bench == nullptr) bench = app.add_subcommand("bench", "Benchmarks on generated rooms");
  auto bench_args = std::make_shared<BenchProjectionArguments>();
  CLI::App* bench_projection = bench->add_subcommand(
      "projection", "Images for two projectors from a solution (default 1920x1080)");
  bench_projection->add_option("--width", bench_args->width, "Projector width, pixels")
      ->capture_default_str();
  bench_projection->add_option("--height", bench_args->height, "Projector height, pixels")
      ->capture_default_str();
  bench_projection->add_option("--patches", bench_args->patches, "Target patch count")
      ->capture_default_str();
  bench_projection->add_option("--repeat", bench_args->repeat, "Timed runs")
      ->check(CLI::Range(1, 1000))
      ->capture_default_str();
  bench_projection->add_option("--dither", bench_args->dither, "none | ordered | error-diffusion")
      ->check(CLI::IsMember({"none", "ordered", "error-diffusion"}))
      ->capture_default_str();
  bench_projection->add_flag("--detail", bench_args->detail,
                             "Give every surface a striped texture and render with its detail");
  bench_projection->add_option("--json", bench_args->json, "Also write the timings as JSON");
  bench_projection->callback([bench_args] { RunProjectionBench(*bench_args); });
}

}  // namespace procam
