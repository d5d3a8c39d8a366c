// procam-play-bench: `procam bench play` (datasets_synthetic/play_benchmark.h) as a binary of its
// own, linked with only the libraries it calls recorded, so that it can be carried to a GPU
// machine without procam's other libraries (docs/nodes.md: the H100 numbers).
//   procam-play-bench [--render cpu|gpu] [--shader auto|fragment|compute] [--device cpu|cuda]
//                     [--light smooth|flat]
//                     [--method perceptual2000] [--dither ordered] [--patches 1000] [--frames 20]
//                     [--width 1920] [--height 1080] [--json FILE]
#include <CLI/CLI.hpp>
#include <cstdio>
#include <exception>
#include <string>

#include "datasets_synthetic/play_benchmark.h"

int main(int argc, char** argv) {
  using namespace procam;
  PlayBenchmarkOptions options;
  std::string method = MethodName(options.method), device = "cpu", light = "smooth",
              dither = "ordered", render = "cpu";
  CLI::App app("procam bench play, alone: new desired colours -> warm-started solve -> images");
  app.add_option("--width", options.width, "Projector width, pixels")->capture_default_str();
  app.add_option("--height", options.height, "Projector height, pixels")->capture_default_str();
  app.add_option("--patches", options.patches, "Target patch count")->capture_default_str();
  app.add_option("--frames", options.frames, "Timed frames")->check(CLI::Range(1, 10000));
  app.add_option("--method", method)->check(CLI::IsMember({"linear", "perceptual", "perceptual2000"}));
  app.add_option("--device", device)->check(CLI::IsMember({"cpu", "cuda"}));
  app.add_option("--light", light)->check(CLI::IsMember({"smooth", "flat"}));
  app.add_option("--dither", dither)->check(CLI::IsMember({"none", "ordered"}));
  app.add_option("--render", render)->check(CLI::IsMember({"cpu", "gpu"}));
  app.add_option("--shader", options.shader)->check(CLI::IsMember({"auto", "fragment", "compute"}));
  app.add_option("--tolerance", options.tolerance)->check(CLI::Range(0.0, 0.1));
  app.add_option("--json", options.json, "Also write the timings as JSON");
  CLI11_PARSE(app, argc, argv);
  ParseMethod(method, &options.method);
  ParseDevice(device, &options.device);
  ParseLightField(light, &options.light);
  ParseDither(dither, &options.dither);
  options.render = render == "gpu" ? PlayRender::kGpu : PlayRender::kCpu;
  options.progress = [](const std::string& line) { std::printf("%s\n", line.c_str()); };
  try {
    RunPlayBenchmark(options);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "procam-play-bench: %s\n", e.what());
    return 1;
  }
  return 0;
}
