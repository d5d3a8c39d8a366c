// procam bench decode: importing and decoding a structured-light capture of realistic size
// (benchmarks.h).
#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <opencv2/imgproc.hpp>
#include <unistd.h>
#include <random>

#include "base/image_io.h"
#include "base/io.h"
#include "base/timing.h"
#include "calibration/capture_layout.h"
#include "datasets_synthetic/benchmarks.h"

namespace procam {

void DecodeBenchmarkOptions::Declare(OptionTable* table) {
  table->Integer("camera-width", &camera_width, 1, 16384, "pixels", "photo width")
      .Integer("camera-height", &camera_height, 1, 16384, "pixels", "photo height")
      .Integer("repeat", &repeat, 1, 100, "", "timed runs")
      .Text("out", &out, "keep the photos and the session here");
}

void RunDecodeBenchmark(const DecodeBenchmarkOptions& options) {
  namespace fs = std::filesystem;
  StructuredLightOptions sequence_options;
  sequence_options.width = options.projector_width;
  sequence_options.height = options.projector_height;
  const CaptureSequence sequence = MakeStructuredLightSequence(sequence_options);
  CaptureLayout layout = CaptureLayoutOf(sequence_options);
  const fs::path folder =
      options.out.empty() ? fs::temp_directory_path() / fmt::format("procam_bench_decode_{}", ::getpid())
                          : fs::path(options.out);
  fs::create_directories(folder);
  // The photos: a plane seen slightly skewed, the projector filling most of the camera image,
  // 8-bit with ambient light and read noise; nearest projector pixel per camera pixel.
  std::mt19937 random(1);
  std::normal_distribution<float> noise(0.0f, 1.5f);
  const int w = options.camera_width, h = options.camera_height;
  cv::Mat map_u(h, w, CV_32F), map_v(h, w, CV_32F);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      map_u.at<float>(y, x) = static_cast<float>(0.86 * x * options.projector_width / w + 0.03 * y);
      map_v.at<float>(y, x) = static_cast<float>(0.88 * y * options.projector_height / h + 0.02 * x);
    }
  for (size_t i = 0; i < sequence.patterns.size(); ++i) {
    cv::Mat grey, photo;
    cv::extractChannel(sequence.patterns[i].image, grey, 0);
    cv::remap(grey, photo, map_u, map_v, cv::INTER_LINEAR, cv::BORDER_CONSTANT, cv::Scalar(0));
    photo.convertTo(photo, CV_32F, 0.8, 20.0);
    for (auto it = photo.begin<float>(); it != photo.end<float>(); ++it) *it += noise(random);
    photo.convertTo(photo, CV_8U);
    char name[32];
    std::snprintf(name, sizeof(name), "pat%03zu.png", i);
    WritePng(folder / name, photo);
  }
  WriteCaptureLayout(folder / "layout.json", layout);
  Report(options.progress,
         fmt::format("{} photos of {}x{} (8-bit PNG) of a {}x{} projector in {}", sequence.patterns.size(),
                     w, h, options.projector_width, options.projector_height, folder.string()));
  std::vector<double> import_s, read_s, decode_s;
  DecodeSummary summary;
  for (int run = 0; run < options.repeat; ++run) {
    ImportOptions import;
    import.layout = folder / "layout.json";
    import.out = folder / "session";
    auto start = Clock::now();
    summary = ImportCaptures(import);
    import_s.push_back(SecondsSince(start));
    start = Clock::now();
    const StructuredLightSession session = ReadStructuredLightSession(folder / "session");
    read_s.push_back(SecondsSince(start));
    start = Clock::now();
    const StructuredLightMap map = DecodeStructuredLight(session.layout, session.images);
    decode_s.push_back(SecondsSince(start));
  }
  const auto median = [](std::vector<double> v) {
    std::sort(v.begin(), v.end());
    return v[v.size() / 2];
  };
  Report(options.progress, "decode: " + summary.BriefReport());
  Report(options.progress,
         fmt::format("median of {} runs: import (read, checksum, session, decode, picture) {:.3f} s; "
                     "reading the session back {:.3f} s; decoding alone {:.3f} s",
                     options.repeat, median(import_s), median(read_s), median(decode_s)));
  if (options.out.empty()) fs::remove_all(folder);
}

}  // namespace procam
