// procam calibrate response SESSION_DIR --out RIG_DIR: a camera's inverse response (camera
// linearity, issue 7) from one still pattern captured at several exposures. Writes
// RIG_DIR/camera_response.json and records it in RIG_DIR/rig.json ("camera"."response").
#include <cstdio>
#include <filesystem>
#include <stdexcept>

#include <nlohmann/json.hpp>

#include "apps/commands.h"
#include "base/output_directory.h"
#include "calibration/camera_response.h"
#include "calibration/rig_directory.h"
#include "capture/session.h"
#include "base/io.h"

namespace procam {
namespace {

struct CalibrateResponseArguments {
  std::string session;
  std::string out;
  int pattern = -1;  // -1: the brightest captured pattern
  CameraResponseOptions options;
};

void RunCalibrateResponse(const CalibrateResponseArguments& args) {
  const std::filesystem::path directory(args.session);
  if (!std::filesystem::is_directory(directory)) {
    throw IoError(directory.string() + ": not a directory");
  }
  std::string why;
  if (!args.options.Check(&why)) throw std::invalid_argument(why);
  const CaptureSessionData data = CaptureSessionData::Load(directory);
  const std::string manifest = (directory / "session.json").string();

  // The pattern: as asked, else the captured one brightest at its first exposure.
  int pattern = args.pattern;
  if (pattern >= data.pattern_count()) {
    throw std::invalid_argument("--pattern " + std::to_string(pattern) + ": the session has " +
                                std::to_string(data.pattern_count()) + " patterns");
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
      throw IoError(manifest + ": a monochrome camera; the response is calibrated per colour "
                               "channel (capture with a colour format)");
    }
    cv::Mat codes;
    mean.convertTo(codes, CV_8U);  // rounds the mean of the frames to the nearest code
    images.push_back(codes);
    exposures_us.push_back(exposures[e].value("exposure_us", 0.0));
  }
  if (images.size() < 3) {
    throw IoError(manifest + ": pattern " + data.pattern_name(pattern) + " has " +
                  std::to_string(images.size()) +
                  " exposures; bracket at least 3 (e.g. --exposure-us 2500,5000,10000,20000,40000)");
  }
  std::printf("pattern %s, %zu exposures, %dx%d pixels\n", data.pattern_name(pattern).c_str(),
              images.size(), images[0].cols, images[0].rows);

  CameraResponse response;
  if (!CalibrateCameraResponse(images, exposures_us, args.options, &response, &why)) {
    throw std::runtime_error(manifest + ": " + why);
  }
  std::printf("gamma R %.4f G %.4f B %.4f (power-law fit RMS in ln: %.4f %.4f %.4f)\n",
              response.gamma[0], response.gamma[1], response.gamma[2], response.gamma_rms[0],
              response.gamma_rms[1], response.gamma_rms[2]);

  nlohmann::json file = CameraResponseJson(response);
  file["session"] = std::filesystem::absolute(directory).string();
  file["pattern"] = data.pattern_name(pattern);
  file["exposures_us"] = exposures_us;
  const std::filesystem::path out(args.out);
  std::filesystem::create_directories(out);
  WriteFileAtomically(out / "camera_response.json", file.dump(2) + "\n");
  UpdateRigFile(out, [](RigFile& rig) { rig.camera.response = "camera_response.json"; });
  std::printf("wrote %s\n", (out / "camera_response.json").c_str());
}

}  // namespace

void AddCalibrateResponseCommand(CLI::App& calibrate) {
  auto args = std::make_shared<CalibrateResponseArguments>();
  CLI::App* response = calibrate.add_subcommand(
      "response",
      "Camera linearity: the inverse response from one still pattern at several exposures");
  response
      ->add_option("session", args->session,
                   "Capture session with --exposure-us brackets (at least 3 exposures)")
      ->required();
  response->add_option("--out", args->out, "Rig directory: camera_response.json, rig.json")
      ->required();
  response->add_option("--pattern", args->pattern,
                       "Pattern index to use (default: the brightest captured)");
  response->add_option("--samples", args->options.samples, "Pixels sampled")
      ->capture_default_str();
  response->add_option("--lambda", args->options.lambda, "Smoothness weight")
      ->capture_default_str();
  response->callback([args] {
    CheckOutputDirectory(args->out, DirectoryKind::kRig);
    RunCalibrateResponse(*args);
  });
}

}  // namespace procam
