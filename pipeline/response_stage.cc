#include "pipeline/response_stage.h"

#include <fmt/format.h>

#include <filesystem>
#include <limits>
#include <nlohmann/json.hpp>
#include <stdexcept>
#include <string>
#include <vector>

#include "base/io.h"
#include "capture/session.h"
#include "projection/rig_directory.h"

namespace procam {

void ResponseStageOptions::Declare(OptionTable* table) {
  table
      ->Path("session", &session,
             "a capture session with --exposure-us brackets (at least 3 exposures)")
      .Positional()
      .Required()
      .Path("out", &out, "the rig directory: camera_response.json, rig.json")
      .Required()
      .Integer("pattern", &pattern, -1, std::numeric_limits<int>::max(), "",
               "the pattern's index (-1: the brightest captured)")
      .Integer("samples", &options.samples, 10, std::numeric_limits<int>::max(), "",
               "pixels sampled")
      .Number("lambda", &options.lambda,
              OptionTable::Interval::AboveMin(0.0, std::numeric_limits<double>::max()), "",
              "smoothness weight");
}

bool ResponseStageOptions::Check(std::string* why) const {
  return CheckDeclared(*this, why) && options.Check(why);
}

CameraResponse RunResponseStage(const ResponseStageOptions& args) {
  const std::filesystem::path directory(args.session);
  if (!std::filesystem::is_directory(directory)) {
    throw IoError(directory.string() + ": not a directory");
  }
  std::string why;
  if (!args.Check(&why)) throw std::invalid_argument(why);
  const CaptureSessionData data = CaptureSessionData::Load(directory);
  const std::string manifest = (directory / "session.json").string();

  // The pattern: as asked, else the captured one brightest at its first exposure.
  int pattern = args.pattern;
  if (pattern >= data.pattern_count()) {
    throw std::invalid_argument(
        fmt::format("pattern {}: the session has {} patterns", pattern, data.pattern_count()));
  }
  if (pattern < 0) {
    double brightest = -1.0;
    for (int p = 0; p < data.pattern_count(); ++p) {
      if (!data.captured(p)) continue;
      const double mean = cv::mean(data.Mean(p, 0))[0];
      if (mean > brightest) brightest = mean, pattern = p;
    }
    if (pattern < 0) throw IoError(manifest + ": no pattern is captured");
  }
  if (!data.captured(pattern)) {
    throw IoError(manifest + ": pattern " + data.pattern_name(pattern) + " is not captured");
  }
  const nlohmann::json& captured = data.manifest()["patterns"][pattern]["captured"];
  const double full_scale = captured.value("full_scale", 0.0);
  if (full_scale != 255.0) {
    throw IoError(manifest + ": the camera's full scale is " + std::to_string(full_scale) +
                  "; the response is calibrated for 8-bit cameras");
  }
  std::vector<cv::Mat> images;
  std::vector<double> exposures_us;
  const nlohmann::json& exposures = captured.value("exposures", nlohmann::json::array());
  for (size_t e = 0; e < exposures.size(); ++e) {
    cv::Mat mean = data.Mean(pattern, static_cast<int>(e));
    if (mean.channels() != 3) {
      throw IoError(manifest +
                    ": a monochrome camera; the response is calibrated per colour "
                    "channel (capture with a colour format)");
    }
    cv::Mat codes;
    mean.convertTo(codes, CV_8U);  // rounds the mean of the frames to the nearest code
    images.push_back(codes);
    exposures_us.push_back(exposures[e].value("exposure_us", 0.0));
  }
  if (images.size() < 3) {
    throw IoError(
        manifest + ": pattern " + data.pattern_name(pattern) + " has " +
        std::to_string(images.size()) +
        " exposures; bracket at least 3 (e.g. --exposure-us 2500,5000,10000,20000,40000)");
  }
  Report(args.progress,
         fmt::format("pattern {}, {} exposures, {}x{} pixels", data.pattern_name(pattern),
                     images.size(), images[0].cols, images[0].rows));

  CameraResponse response;
  if (!CalibrateCameraResponse(images, exposures_us, args.options, &response, &why)) {
    throw std::runtime_error(manifest + ": " + why);
  }
  Report(args.progress,
         fmt::format(
             "gamma R {:.4f} G {:.4f} B {:.4f} (power-law fit RMS in ln: {:.4f} {:.4f} {:.4f})",
             response.gamma[0], response.gamma[1], response.gamma[2], response.gamma_rms[0],
             response.gamma_rms[1], response.gamma_rms[2]));

  nlohmann::json file = CameraResponseJson(response);
  file["session"] = std::filesystem::absolute(directory).string();
  file["pattern"] = data.pattern_name(pattern);
  file["exposures_us"] = exposures_us;
  const std::filesystem::path out(args.out);
  std::filesystem::create_directories(out);
  WriteFileAtomically(out / "camera_response.json", file.dump(2) + "\n");
  UpdateRigFile(out, [](RigFile& rig) { rig.camera.response = "camera_response.json"; });
  Report(args.progress, "wrote " + (out / "camera_response.json").string());
  return response;
}

}  // namespace procam
