#include "verification/verification.h"

#include <fmt/format.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>
#include <map>
#include <mutex>

#include "base/image_io.h"
#include "base/io.h"
#include "base/json_fields.h"
#include "base/option_table.h"
#include "base/parse.h"
#include "base/stop.h"
#include "base/timing.h"
#include "calibration/camera_response.h"
#include "capture/camera.h"
#include "capture/patterns.h"
#include "capture/pixel_format.h"
#include "capture/session.h"
#include "capture/test_camera.h"
#include "compensation/colour.h"
#include "compensation/problem.h"
#include "compensation/stage.h"
#include "geometry/stage.h"
#include "projection/calibrated_room.h"
#include "projection/camera_rays.h"
#include "projection/projection_rig.h"
#include "projection/projector_images.h"
#include "projection/rig_directory.h"
#include "projection/stage.h"
#include "verification/model_fit.h"

namespace procam {
namespace {



void CreateDirectories(const std::filesystem::path& dir) {
  std::error_code error;
  std::filesystem::create_directories(dir, error);
  if (error) throw IoError(dir.string() + ": cannot create directory: " + error.message());
}

// ---------------------------------------------------------------------------------------------
// Camera colour

// What the rig or the options say (the synthetic camera's is derived per photo).
struct ColourSource {
  bool simulated = false;
  Eigen::Matrix3d matrix = Eigen::Matrix3d::Identity();  // per unit camera value
  double black = 0.0;
  std::string source;
};

ColourSource ResolveColourSource(const VerificationOptions& options, const RigCamera& camera,
                                 const std::string& rig_file, bool simulated) {
  ColourSource c;
  c.black = std::max(0.0, options.camera_black);
  if (options.camera_scale) {
    c.matrix = options.camera_scale->cwiseInverse().asDiagonal();
    c.source = FlagOf(options, &options.camera_scale);
    return c;
  }
  if (camera.colour) {
    // ReadRigFile checked it: a positive scale or a non-singular matrix.
    c.matrix = camera.colour->scale ? Eigen::Matrix3d(camera.colour->scale->cwiseInverse().asDiagonal())
                                    : *camera.colour->matrix;
    if (options.camera_black < 0) c.black = camera.colour->black.value_or(0.0);
    c.source = "rig.json camera.colour";
    return c;
  }
  if (simulated) {
    c.simulated = true;
    c.source = "simulated camera";
    return c;
  }
  throw IoError(rig_file + ": camera.colour: required key is missing for camera '" +
                options.camera +
                "' (the camera's value per unit exitance: {\"scale\": [R,G,B]} or {\"matrix\": "
                "3x3}), or give " +
                FlagOf(options, &options.camera_scale));
}

// Linear working RGB (CV_32FC3, R, G, B) in scene units from the camera's linear photo (B, G, R).
cv::Mat PhotoToExitance(const cv::Mat& photo, const CameraColour& colour) {
  cv::Mat exitance(photo.rows, photo.cols, CV_32FC3);
  for (int row = 0; row < photo.rows; ++row) {
    for (int col = 0; col < photo.cols; ++col) {
      const cv::Vec3f& v = photo.at<cv::Vec3f>(row, col);
      const Eigen::Vector3d camera(v[2] - colour.black, v[1] - colour.black, v[0] - colour.black);
      const Eigen::Vector3d x = colour.to_exitance * camera;
      exitance.at<cv::Vec3f>(row, col) = cv::Vec3f(float(x[0]), float(x[1]), float(x[2]));
    }
  }
  return exitance;
}

// ---------------------------------------------------------------------------------------------
// Photo against desired and predicted

struct Comparison {
  PhotoDeltaE measured, model;
  double predicted_mean76 = 0, predicted_mean2000 = 0;
  double model_constant_mean76 = 0;  // per pixel, photo vs its patch's B (constant per patch)
  Eigen::MatrixX3d patch_exitance;   // mean measured exitance per patch (NaN where unseen)
  std::vector<bool> seen;
  int seen_pixels = 0, seen_patches = 0;
  cv::Mat delta_e76, delta_e2000, model_delta_e76, predicted;  // per pixel
  SeamMeasure seams;                                           // of the photo
};

// Per pixel: the photo against the desired appearance of the patch each pixel sees and against
// the per-pixel prediction `predicted_pixels` (PredictPixels), ΔE maps and means over the seen
// pixels (colour_image.h); and against its patch's B (constant over the patch).
void ComparePixels(const cv::Mat& exitance, const std::vector<int>& pixel_patch,
                   const std::vector<int>& patch_surface, const LabConverter& lab,
                   const std::vector<Eigen::Vector3d>& lab_desired,
                   const std::vector<Eigen::Vector3d>& lab_predicted,
                   const cv::Mat& predicted_pixels, Comparison* result) {
  const int rows = exitance.rows, cols = exitance.cols;
  cv::Mat seen(rows, cols, CV_8UC1, cv::Scalar(0));
  cv::Mat desired(rows, cols, CV_64FC3, cv::Scalar::all(0));
  const cv::Mat lab_measured = LabImage(exitance, lab);
  double constant76 = 0;
  for (int row = 0; row < rows; ++row) {
    for (int col = 0; col < cols; ++col) {
      const int i = pixel_patch[static_cast<size_t>(row) * cols + col];
      if (i < 0) continue;
      seen.at<uchar>(row, col) = 255;
      desired.at<cv::Vec3d>(row, col) =
          cv::Vec3d(lab_desired[i][0], lab_desired[i][1], lab_desired[i][2]);
      const cv::Vec3d& m = lab_measured.at<cv::Vec3d>(row, col);
      constant76 += DeltaE76(Eigen::Vector3d(m[0], m[1], m[2]), lab_predicted[i]);
    }
  }
  const ImageDeltaE against_desired = CompareLabImages(lab_measured, desired, seen);
  const cv::Mat patch_image(rows, cols, CV_32SC1, const_cast<int*>(pixel_patch.data()));
  result->seams = MeasureSeams(lab_measured, desired, patch_image, patch_surface);
  const ImageDeltaE against_model =
      CompareLabImages(lab_measured, LabImage(predicted_pixels, lab), seen);
  result->delta_e76 = against_desired.delta_e76;
  result->delta_e2000 = against_desired.delta_e2000;
  result->model_delta_e76 = against_model.delta_e76;
  result->predicted = predicted_pixels;
  result->measured.mean76 = against_desired.mean76;
  result->measured.max76 = against_desired.max76;
  result->measured.mean2000 = against_desired.mean2000;
  result->measured.max2000 = against_desired.max2000;
  result->model.mean76 = against_model.mean76;
  result->model.max76 = against_model.max76;
  result->model.mean2000 = against_model.mean2000;
  result->model.max2000 = against_model.max2000;
  result->seen_pixels = static_cast<int>(against_desired.pixels);
  result->model_constant_mean76 = constant76 / std::max(1, result->seen_pixels);
}

// Per patch: the mean exitance of its interior pixels (away from patch borders, where projector
// pixels straddling two patches spill light), or of all its pixels when too few are interior;
// patches with fewer than `min_pixels` pixels are unseen. ΔE area-weighted over the seen ones:
// against the desired colour, and against the per-pixel prediction's mean over the same pixels
// (the model's view of that mean, also where a shadow or an image border darkens part of the
// patch: the solution's B is then its lit part's, projection_rig.h).
void ComparePatches(const cv::Mat& exitance, const std::vector<int>& pixel_patch,
                    const std::vector<bool>& interior, const CompensationProblem& problem,
                    const LabConverter& lab, const std::vector<Eigen::Vector3d>& lab_desired,
                    const std::vector<Eigen::Vector3d>& lab_predicted,
                    const cv::Mat& predicted_pixels, int min_pixels, Comparison* result) {
  const int n = problem.size();
  const PatchPixelSums all = SumPixelsPerPatch(exitance, pixel_patch, n);
  const PatchPixelSums inside = SumPixelsPerPatch(exitance, pixel_patch, n, &interior);
  const PatchPixelSums predicted_all = SumPixelsPerPatch(predicted_pixels, pixel_patch, n);
  const PatchPixelSums predicted_inside =
      SumPixelsPerPatch(predicted_pixels, pixel_patch, n, &interior);
  result->patch_exitance =
      Eigen::MatrixX3d::Constant(n, 3, std::numeric_limits<double>::quiet_NaN());
  result->seen.assign(n, false);
  double area = 0, patch76 = 0, patch2000 = 0, model_patch76 = 0, model_patch2000 = 0,
         predicted76 = 0, predicted2000 = 0;
  for (int i = 0; i < n; ++i) {
    if (all.count[i] < min_pixels) continue;
    result->seen[i] = true;
    ++result->seen_patches;
    const bool use_interior = inside.count[i] >= min_pixels;
    result->patch_exitance.row(i) = use_interior ? inside.Mean(i) : all.Mean(i);
    const Eigen::RowVector3d predicted_mean =
        use_interior ? predicted_inside.Mean(i) : predicted_all.Mean(i);
    const Eigen::Vector3d lab_measured = lab.Lab(result->patch_exitance.row(i).transpose());
    const Eigen::Vector3d lab_model = lab.Lab(predicted_mean.transpose());
    const double a = problem.area[i];
    area += a;
    patch76 += a * DeltaE76(lab_measured, lab_desired[i]);
    patch2000 += a * DeltaE2000(lab_measured, lab_desired[i]);
    model_patch76 += a * DeltaE76(lab_measured, lab_model);
    model_patch2000 += a * DeltaE2000(lab_measured, lab_model);
    predicted76 += a * DeltaE76(lab_predicted[i], lab_desired[i]);
    predicted2000 += a * DeltaE2000(lab_predicted[i], lab_desired[i]);
  }
  if (area > 0) {
    result->measured.patch_mean76 = patch76 / area;
    result->measured.patch_mean2000 = patch2000 / area;
    result->model.patch_mean76 = model_patch76 / area;
    result->model.patch_mean2000 = model_patch2000 / area;
    result->predicted_mean76 = predicted76 / area;
    result->predicted_mean2000 = predicted2000 / area;
  }
}

// Photo vs desired and vs predicted, per pixel (against the per-pixel prediction) and per patch
// (against the solution's radiosity B), as the header comment says.
Comparison Compare(const cv::Mat& exitance, const std::vector<int>& pixel_patch,
                   const std::vector<int>& patch_surface, const std::vector<bool>& interior,
                   const CompensationProblem& problem, const Eigen::MatrixX3d& radiosity,
                   const cv::Mat& predicted_pixels, int min_pixels) {
  const int n = problem.size();
  const LabConverter lab{problem.rgb_to_xyz, problem.white_xyz};
  std::vector<Eigen::Vector3d> lab_desired(n), lab_predicted(n);
  for (int i = 0; i < n; ++i) {
    lab_desired[i] = lab.Lab(problem.desired.row(i).transpose());
    lab_predicted[i] = lab.Lab(radiosity.row(i).transpose());
  }
  Comparison result;
  ComparePixels(exitance, pixel_patch, patch_surface, lab, lab_desired, lab_predicted,
                predicted_pixels, &result);
  ComparePatches(exitance, pixel_patch, interior, problem, lab, lab_desired, lab_predicted,
                 predicted_pixels, min_pixels, &result);
  return result;
}

double SolverMeanDeltaE76(const CompensationProblem& problem, const Eigen::MatrixX3d& radiosity) {
  const LabConverter lab{problem.rgb_to_xyz, problem.white_xyz};
  double sum = 0;
  for (int i = 0; i < problem.size(); ++i) {
    sum += problem.area[i] * DeltaE76(lab.Lab(radiosity.row(i).transpose()),
                                      lab.Lab(problem.desired.row(i).transpose()));
  }
  return sum / problem.area.sum();
}

nlohmann::json DeltaEJson(const PhotoDeltaE& d) {
  return {{"pixel_mean76", d.mean76},       {"pixel_max76", d.max76},
          {"pixel_mean2000", d.mean2000},   {"pixel_max2000", d.max2000},
          {"patch_mean76", d.patch_mean76}, {"patch_mean2000", d.patch_mean2000}};
}

nlohmann::json IterationJson(const VerificationIteration& it) {
  nlohmann::json exponents = nlohmann::json::array();
  for (const Eigen::Vector3d& e : it.response_exponent) exponents.push_back(JsonTriple(e));
  nlohmann::json json = {
      {"iteration", it.index},
      {"directory", it.directory.string()},
      {"measured_vs_desired", DeltaEJson(it.measured)},
      {"measured_vs_predicted", DeltaEJson(it.model)},
      {"seam", it.seams.Json()},
      {"measured_vs_patch_radiosity_pixel_mean76", it.model_constant_mean76},
      {"predicted_vs_desired",
       {{"patch_mean76", it.predicted_mean76},
        {"patch_mean2000", it.predicted_mean2000},
        {"solver_mean76_all_patches", it.solver_mean76}}},
      {"seen_pixels", it.seen_pixels},
      {"seen_patches", it.seen_patches},
      {"seconds",
       {{"capture", it.capture_seconds}, {"solve", it.solve_seconds}, {"total", it.seconds}}}};
  if (!it.response_exponent.empty()) {
    json["update"] = {{"response_exponent", exponents},
                      {"reflectance_scale", JsonTriple(it.reflectance_scale)}};
    if (it.map_refitted_pixels > 0) {
      json["update"]["reflectance_maps"] = {{"refitted_pixels", it.map_refitted_pixels},
                                            {"rms_gain", it.map_rms_gain}};
    }
  }
  return json;
}

}  // namespace

// ---------------------------------------------------------------------------------------------

void VerificationOptions::Declare(OptionTable* table) {
  table->Path("rig", &rig_dir, "rig directory (rig.json: camera.model, projectors[])")
      .Positional()
      .Required();
  table
      ->Path("solution", &solution_dir,
             "solution directory (procam compensate SCENE --rig RIG_DIR --out DIR)")
      .Positional()
      .Required();
  table->Text("camera", &camera, "camera URI: synthetic:SCENE?..., aravis:<id>, v4l2:/dev/video0")
      .Required();
  table->Path("out", &out, "output directory").Required();
  table->Texts("display", &display_names,
               "per projector, in rig.json's order: glfw:N|NAME, its monitor "
               "(procam show --list); not for synthetic cameras");
  table
      ->Integer("iterations", &iterations, 1, 50, "",
                "photos at most: 1 verifies only; more refine the model and solve again")
      .Number("min-improvement", &min_improvement, OptionTable::Interval::BelowMax(0.0, 1.0), "",
              "stop when the measured mean ΔE76 drops by less than this fraction")
      .Number("reflectance-step", &reflectance_step, OptionTable::Interval::AboveMin(0.0, 1.0), "",
              "damping of the per-patch reflectance update")
      .NegatedFlag("no-response-fit", &fit_response,
                   "leave the projectors' responses as the rig has them")
      .NegatedFlag("no-reflectance-fit", &fit_reflectance,
                   "leave the per-patch reflectance as the rig has it")
      .Integer("min-patch-pixels", &min_patch_pixels, 1, 1 << 30, "pixels",
               "camera pixels a patch needs to count as seen")
      .Choice("light", &light, LightFieldChoices(),
              "how the projector images shape the light within each patch: smooth (seamless) or "
              "flat")
      .NegatedFlag("no-reflectance-maps", &reflectance_maps,
                   "leave the rig's per-pixel reflectance maps unused: images and prediction "
                   "with one reflectance per patch")
      .NegatedFlag("no-reflectance-map-fit", &fit_reflectance_map,
                   "leave the reflectance maps as the rig has them (else each photo refits a "
                   "gain per projector pixel)");
  sequencer.Declare(table);
  std::optional<Eigen::Vector3d>* scale = &camera_scale;
  table->Custom(
      "camera-scale",
      [scale] {
        if (!*scale) return std::string();
        const Eigen::Vector3d& v = **scale;
        if (v[0] == v[1] && v[1] == v[2]) return OptionNumberText(v[0]);
        return OptionNumberText(v[0]) + "," + OptionNumberText(v[1]) + "," + OptionNumberText(v[2]);
      },
      [scale](const std::string& text, std::string* why) {
        if (text.empty()) {
          scale->reset();
          return true;
        }
        try {
          *scale = ParsePositiveRgb("camera-scale", text);
          return true;
        } catch (const IoError& error) {
          *why = std::string(error.what()).substr(std::string("camera-scale: ").size());
          return false;
        }
      },
      "a positive number, or R,G,B",
      "camera value per unit exitance (scene units); default: rig.json camera.colour, or the "
      "synthetic camera's own");
  table->Sets(&camera_scale);
  table->Number(
      "camera-black", &camera_black, -1.0, 1e9, "DN",
      "camera black level (< 0: rig.json camera.colour.black, the synthetic URI's, or 0)");
  table->Text("camera-response", &camera_response,
              "camera_response.json (procam calibrate response) for a camera that is not linear; "
              "needs --exposure-us bracketing");
  table->Number("gain", &gain, -1.0, 1000.0, "dB", "camera gain to set (< 0: leave it)");
  DeclareSettleOption(table, &sequencer.settle_ms, &measure_latency);
  table->Numbers("exposure-us", &sequencer.exposures_us, OptionTable::Interval::AboveMin(0.0, 1e9),
                 "µs", "exposure(s); several bracket and merge to HDR");
}

bool VerificationOptions::Check(std::string* why) const {
  auto fail = [why](const std::string& text) {
    if (why) *why = text;
    return false;
  };
  if (rig_dir.empty()) return fail("the rig directory is required");
  if (solution_dir.empty()) return fail("the solution directory is required");
  if (out.empty()) return fail(FlagOf(*this, &out) + " is required");
  if (camera.empty()) return fail(FlagOf(*this, &camera) + " is required");
  // The table only reads the fields here.
  OptionTable table("verify");
  const_cast<VerificationOptions*>(this)->Declare(&table);
  std::string table_why;
  if (!table.Check(&table_why)) return fail(table_why);
  std::string sequencer_why;
  if (!sequencer.Check(&sequencer_why)) return fail(sequencer_why);
  if (measure_latency && !latency.Check(&sequencer_why)) return fail("latency: " + sequencer_why);
  if (!camera_response.empty() && sequencer.exposures_us.size() < 2)
    return fail(FlagOf(*this, &camera_response) + " needs bracketed exposures (" +
                FlagOf(*this, &sequencer.exposures_us) + " a,b,...)");
  return true;
}

nlohmann::json VerificationSummary::Json() const {
  nlohmann::json list = nlohmann::json::array();
  for (const VerificationIteration& it : iterations) list.push_back(IterationJson(it));
  nlohmann::json json = {{"format_version", kVerificationFormatVersion},
                         {"command", "verify"},
                         {"iterations", list},
                         {"best", best},
                         {"complete", complete},
                         {"termination", termination},
                         {"seconds", seconds}};
  if (!error.empty()) json["error"] = error;
  json["rig"] = rig;
  json["solution"] = solution;
  json["camera"] = camera;
  json["colour_source"] = colour_source;
  json["hdr"] = hdr;
  json["exposures_us"] = exposures_us;
  json["settle_ms"] = settle_ms;
  if (!iterations.empty() && best >= 0) {
    const double first = iterations.front().measured.mean76;
    const double kept = iterations[best].measured.mean76;
    json["initial_mean76"] = first;
    json["best_mean76"] = kept;
    json["improvement"] = first > 0 ? (first - kept) / first : 0.0;
  }
  return json;
}

void WriteVerificationRun(const std::filesystem::path& dir, const VerificationSummary& summary) {
  std::filesystem::create_directories(dir);
  WriteFileAtomically(dir / "result.json", summary.Json().dump(2) + "\n");
}

namespace {

int ReadInt(const JsonFields& fields, const std::string& key) {
  const nlohmann::json& value = fields.At(key);
  if (!value.is_number_integer()) throw fields.Error(key, "must be an integer");
  return value.get<int>();
}

bool ReadBool(const JsonFields& fields, const std::string& key) {
  const nlohmann::json& value = fields.At(key);
  if (!value.is_boolean()) throw fields.Error(key, "must be true or false");
  return value.get<bool>();
}

PhotoDeltaE ReadDeltaE(const JsonFields& parent, const std::string& key, const std::string& file) {
  const JsonFields fields(parent.At(key), file, parent.Path(key));
  PhotoDeltaE d;
  d.mean76 = fields.Number("pixel_mean76");
  d.max76 = fields.Number("pixel_max76");
  d.mean2000 = fields.Number("pixel_mean2000");
  d.max2000 = fields.Number("pixel_max2000");
  d.patch_mean76 = fields.Number("patch_mean76");
  d.patch_mean2000 = fields.Number("patch_mean2000");
  return d;
}

VerificationIteration ReadIteration(const nlohmann::json& object, const std::string& file,
                                    const std::string& prefix) {
  const JsonFields fields(object, file, prefix);
  VerificationIteration it;
  it.index = ReadInt(fields, "iteration");
  it.directory = fields.String("directory");
  it.measured = ReadDeltaE(fields, "measured_vs_desired", file);
  it.model = ReadDeltaE(fields, "measured_vs_predicted", file);
  it.model_constant_mean76 = fields.Number("measured_vs_patch_radiosity_pixel_mean76");
  const JsonFields predicted(fields.At("predicted_vs_desired"), file,
                             fields.Path("predicted_vs_desired"));
  it.predicted_mean76 = predicted.Number("patch_mean76");
  it.predicted_mean2000 = predicted.Number("patch_mean2000");
  it.solver_mean76 = predicted.Number("solver_mean76_all_patches");
  const JsonFields seam(fields.At("seam"), file, fields.Path("seam"));
  it.seams.seam = seam.Number("seam");
  it.seams.across = seam.Number("across");
  it.seams.within = seam.Number("within");
  it.seams.across_pairs = static_cast<int64_t>(seam.Number("across_pairs"));
  it.seams.within_pairs = static_cast<int64_t>(seam.Number("within_pairs"));
  it.seen_pixels = ReadInt(fields, "seen_pixels");
  it.seen_patches = ReadInt(fields, "seen_patches");
  const JsonFields seconds(fields.At("seconds"), file, fields.Path("seconds"));
  it.capture_seconds = seconds.Number("capture");
  it.solve_seconds = seconds.Number("solve");
  it.seconds = seconds.Number("total");
  if (fields.Has("update")) {
    const JsonFields update(fields.At("update"), file, fields.Path("update"));
    const nlohmann::json& exponents = update.At("response_exponent");
    if (!exponents.is_array()) throw update.Error("response_exponent", "must be an array");
    for (size_t j = 0; j < exponents.size(); ++j) {
      it.response_exponent.push_back(
          update.Triple("response_exponent[" + std::to_string(j) + "]", exponents[j]));
    }
    it.reflectance_scale = update.Triple("reflectance_scale", update.At("reflectance_scale"));
    if (update.Has("reflectance_maps")) {
      const JsonFields maps(update.At("reflectance_maps"), file, update.Path("reflectance_maps"));
      it.map_refitted_pixels = static_cast<long long>(maps.Number("refitted_pixels"));
      it.map_rms_gain = maps.Number("rms_gain");
    }
  }
  return it;
}

}  // namespace

VerificationSummary ReadVerificationRun(const std::filesystem::path& dir) {
  const std::filesystem::path path = dir / "result.json";
  const std::string file = path.string();
  const nlohmann::json object = ReadJsonFile(path);
  const JsonFields fields(object, file, "");
  if (!fields.Has("format_version") || !object["format_version"].is_number_integer())
    throw fields.Error("format_version", "required key is missing (an integer)");
  if (object["format_version"].get<int64_t>() != kVerificationFormatVersion) {
    throw fields.Error("format_version",
                       object["format_version"].dump() + " is not supported (this procam reads " +
                           std::to_string(kVerificationFormatVersion) + ")");
  }
  if (fields.String("command") != "verify") throw fields.Error("command", "not a verification run");
  VerificationSummary summary;
  const nlohmann::json& iterations = fields.At("iterations");
  if (!iterations.is_array()) throw fields.Error("iterations", "must be an array");
  for (size_t k = 0; k < iterations.size(); ++k)
    summary.iterations.push_back(
        ReadIteration(iterations[k], file, "iterations[" + std::to_string(k) + "]"));
  summary.best = ReadInt(fields, "best");
  if (summary.best < -1 || summary.best >= static_cast<int>(summary.iterations.size()))
    throw fields.Error("best", "not an iteration of the run");
  summary.complete = ReadBool(fields, "complete");
  summary.termination = fields.String("termination");
  if (fields.Has("error")) summary.error = fields.String("error");
  summary.seconds = fields.Number("seconds");
  summary.rig = fields.At("rig");
  summary.solution = fields.String("solution");
  summary.camera = fields.String("camera");
  summary.colour_source = fields.String("colour_source");
  summary.hdr = ReadBool(fields, "hdr");
  summary.exposures_us = fields.Numbers("exposures_us", fields.At("exposures_us"));
  if (fields.Has("settle_ms")) summary.settle_ms = fields.Number("settle_ms");
  return summary;
}

std::string VerificationSummary::BriefReport() const {
  if (iterations.empty()) return "verify: no photo taken (" + termination + ")";
  std::string text =
      "verify: " + std::to_string(iterations.size()) + " photo(s), measured mean ΔE76";
  for (const VerificationIteration& it : iterations)
    text += fmt::format(" {:.2f}", it.measured.mean76);
  if (best >= 0) {
    text += fmt::format(
        "; best iteration {} ({:.2f}, model error {:.2f}, predicted {:.2f}, seam {:.2f}), {}", best,
        iterations[best].measured.mean76, iterations[best].model.mean76,
        iterations[best].predicted_mean76, iterations[best].seams.seam, termination);
  }
  return text;
}

namespace {

// A camera or projector fault while photographing: the loop keeps what it did and says so.
class PhotoFault : public IoError {
 public:
  using IoError::IoError;
};

// Everything the loop reads, checked before anything is shown or written.
struct VerificationInputs {
  CalibratedRoomOptions room;  // what the model is built with (RoomOptions)
  std::optional<Scene> scene;  // VerificationOptions::scene
  RigDirectory rig;
  std::string rig_file;
  std::filesystem::path camera_model_path;
  ProjectorGeometry camera_geometry;
  SolutionDirectory solution;
  std::optional<SimulatedCamera> simulated;
  ColourSource colour_source;
  std::vector<std::shared_ptr<PatternDisplay>> displays;
  std::vector<std::string> names;  // the rig's projectors, in rig.json's order
};

// The room as the loop models it: the solution's (or options.scene's) room at the solution's patch
// count, the rig's projectors at the displays' 8 bits, the camera's rays with each projector's
// light.
CalibratedRoomOptions RoomOptions(const VerificationOptions& options) {
  CalibratedRoomOptions room;
  room.rig_dir = options.rig_dir;
  room.solution_dir = options.solution_dir;
  room.display_bits = 8;
  room.reflectance_maps = options.reflectance_maps;
  room.camera_rays = true;
  room.camera_lighting = true;
  room.progress = options.progress;
  return room;
}

VerificationInputs ReadInputs(const VerificationOptions& options) {
  VerificationInputs in;
  in.rig_file = (options.rig_dir / "rig.json").string();
  in.room = RoomOptions(options);
  RoomSources sources = ReadRoomSources(in.room);
  in.rig = std::move(*sources.rig);
  in.camera_model_path = sources.camera_model_path;
  in.camera_geometry = sources.camera;
  in.solution = std::move(*sources.solution);
  in.scene = options.scene;
  in.room.alpha = in.solution.alpha;  // the problem as solved

  in.simulated = FindSimulatedCamera(options.camera);
  in.colour_source =
      ResolveColourSource(options, in.rig.file.camera, in.rig_file, in.simulated.has_value());
  in.displays = options.displays;
  if (in.simulated && in.displays.empty()) in.displays = in.simulated->displays;
  if (in.displays.size() != in.rig.projectors.size()) {
    throw IoError(
        in.rig_file + ": projectors: the rig has " + std::to_string(in.rig.projectors.size()) +
        " projector(s) but " + std::to_string(in.displays.size()) +
        " display(s) were given (one --display glfw:N|NAME per projector, in rig.json's order)");
  }
  for (size_t k = 0; k < in.displays.size(); ++k) {
    const Projector& projector = in.rig.projectors[k];
    in.names.push_back(projector.name);
    const cv::Size size(projector.geometry.width(), projector.geometry.height());
    const cv::Size display = in.displays[k]->Resolution();
    if (display != size) {
      throw IoError(in.rig_file + ": projectors[" + std::to_string(k) + "] ('" + projector.name +
                    "') is " + std::to_string(size.width) + "x" + std::to_string(size.height) +
                    " but its display " + in.displays[k]->Name() + " is " +
                    std::to_string(display.width) + "x" + std::to_string(display.height));
    }
  }
  return in;
}

// The model the loop refines: the room (geometry with the rig's reflectance, the projection rig
// at 8-bit displays, the camera's rays, the problem as solved), and the camera pixels away from
// patch borders.
struct VerificationModel {
  CalibratedRoom room;
  std::vector<bool> interior;  // pixels whose four neighbours see the same patch
};

VerificationModel BuildModel(const VerificationInputs& in) {
  VerificationModel model;
  RoomSources sources;
  sources.rig = in.rig;
  sources.solution = in.solution;
  sources.camera_model_path = in.camera_model_path;
  sources.camera = in.camera_geometry;
  sources.scene = in.scene;
  // The geometry is fixed; the photometry the loop refines is applied per photo (PredictPixels).
  model.room = BuildCalibratedRoom(in.room, std::move(sources));
  const CameraPixelRays& rays = model.room.camera_rays;
  model.interior.assign(rays.patch.size(), false);
  for (int row = 1; row + 1 < rays.height; ++row) {
    for (int col = 1; col + 1 < rays.width; ++col) {
      const size_t index = static_cast<size_t>(row) * rays.width + col;
      const int i = rays.patch[index];
      model.interior[index] = i >= 0 && rays.patch[index - 1] == i && rays.patch[index + 1] == i &&
                              rays.patch[index - rays.width] == i &&
                              rays.patch[index + rays.width] == i;
    }
  }
  return model;
}

// A projector's per-pixel reflectance (ProjectorMap::reflectance) as a picture (8-bit BGR, its
// pixels; black where it lights nothing).
cv::Mat ReflectanceMapPicture(const ProjectorMap& map,
                              const std::vector<Eigen::Vector3f>& reflectance) {
  cv::Mat linear(map.height, map.width, CV_32FC3, cv::Scalar::all(0));
  for (int y = 0; y < map.height; ++y) {
    for (int x = 0; x < map.width; ++x) {
      const size_t k = static_cast<size_t>(y) * map.width + x;
      if (map.patch[k] < 0) continue;
      linear.at<cv::Vec3f>(y, x) =
          cv::Vec3f(reflectance[k][0], reflectance[k][1], reflectance[k][2]);
    }
  }
  return LinearToDisplay(linear);
}

// How far a refit moved each pixel's reflectance: |after / before − 1| in percent (the largest of
// the three channels) as a heat map up to 50% (the refit's clamp, ReflectanceMapFitOptions).
cv::Mat ReflectanceGainPicture(const ProjectorMap& map, const std::vector<Eigen::Vector3f>& before,
                               const std::vector<Eigen::Vector3f>& after) {
  cv::Mat percent(map.height, map.width, CV_32FC1, cv::Scalar::all(0));
  for (int y = 0; y < map.height; ++y) {
    for (int x = 0; x < map.width; ++x) {
      const size_t k = static_cast<size_t>(y) * map.width + x;
      if (map.patch[k] < 0) continue;
      float change = 0;
      for (int c = 0; c < 3; ++c) {
        if (before[k][c] > 0) change = std::max(change, std::abs(after[k][c] / before[k][c] - 1));
      }
      percent.at<float>(y, x) = 100 * change;
    }
  }
  return HeatMapWithColourBar(percent, 50, "% change");
}

// The desired appearance as the camera sees it (8-bit BGR): each pixel its patch's desired colour.
cv::Mat DesiredPicture(const VerificationModel& model) {
  const CameraPixelRays& rays = model.room.camera_rays;
  const double white = model.room.geometry.scene.white;
  cv::Mat desired = cv::Mat::zeros(rays.height, rays.width, CV_32FC3);
  for (int row = 0; row < rays.height; ++row) {
    for (int col = 0; col < rays.width; ++col) {
      const int i = rays.patch[static_cast<size_t>(row) * rays.width + col];
      if (i < 0) continue;
      desired.at<cv::Vec3f>(row, col) = cv::Vec3f(float(model.room.problem.desired(i, 0) / white),
                                                  float(model.room.problem.desired(i, 1) / white),
                                                  float(model.room.problem.desired(i, 2) / white));
    }
  }
  return LinearToDisplay(desired);
}

// The loop's state from one iteration to the next.
class VerificationLoop {
 public:
  VerificationLoop(const VerificationOptions& options, const VerificationInputs& in,
                   VerificationModel* model)
      : options_(options), in_(in), model_(*model), wall_(in.displays, in.names) {
    camera_ = OpenCamera(options.camera, OpenCameraOptions());
    if (!IsColour(camera_->Settings().pixel_format)) {
      throw IoError("camera '" + options.camera +
                    "': delivers grey images; verification needs colour");
    }
    const CameraSettings settings = camera_->Settings();
    const CameraPixelRays& rays = model->room.camera_rays;
    if (settings.width > 0 && (settings.width != rays.width || settings.height != rays.height)) {
      throw IoError("camera '" + options.camera + "' delivers " + std::to_string(settings.width) +
                    "x" + std::to_string(settings.height) + " photos but " +
                    in.camera_model_path.string() + " is " + std::to_string(rays.width) + "x" +
                    std::to_string(rays.height));
    }
    if (options.gain >= 0) camera_->SetGain(options.gain);
    sequencer_ = options.sequencer;
    if (!options.camera_response.empty()) {
      sequencer_.hdr.inverse_response = ReadInverseResponse(options.camera_response, 3);
    }
    hdr_ = sequencer_.exposures_us.size() >= 2;
    if (options.measure_latency) {
      const LatencyMeasurement latency = MeasureDisplayLatency(camera_.get(), &wall_, options.latency);
      sequencer_.settle_ms = latency.SettleMs();
      Report(options.progress, latency.Summary());
    }
    // The HDR merge subtracts the camera's black level: the option's, the simulated camera's,
    // or rig.json's.
    if (options.camera_black >= 0) {
      sequencer_.hdr.black_level = options.camera_black;
    } else if (in.simulated) {
      sequencer_.hdr.black_level = in.simulated->black_level;
    } else {
      sequencer_.hdr.black_level = in.colour_source.black;
    }
    emittance_ = in.solution.emittance;
    radiosity_ = in.solution.radiosity;
  }

  const SequencerOptions& sequencer() const { return sequencer_; }
  bool hdr() const { return hdr_; }

  // Renders the current solution's projector images and the pattern they make, and checks that
  // iteration k's session can take it (one an earlier run left with other inputs cannot), writing
  // nothing. Throws IoError ("cannot resume: ...").
  void Prepare(int k);
  // Shows the current solution, photographs it, compares; writes the iteration's files. Throws
  // PhotoFault on a camera or projector fault (the caller keeps what was done).
  VerificationIteration Photograph(int k, nlohmann::json* json);
  // Fits the model to the iteration's photo and solves again (verification/model_fit.h).
  void UpdateAndSolve(VerificationIteration* it);

 private:
  CameraColour ColourOf(const CaptureSessionData& session) const;
  CaptureSessionOptions SessionOptions(int k) const;  // iteration k's session

  const VerificationOptions& options_;
  const VerificationInputs& in_;
  VerificationModel& model_;
  DisplayWall wall_;
  std::unique_ptr<Camera> camera_;
  SequencerOptions sequencer_;
  bool hdr_ = false;
  Eigen::MatrixX3d emittance_, radiosity_;
  double heat_scale_ = 0.0;
  // What Prepare(prepared_) made: the images shown, their pattern and how they were rendered.
  int prepared_ = -1;
  CaptureSequence sequence_;
  RenderSummary render_;
  // What the last photo said, for the update.
  std::vector<ProjectorImage> images_;
  cv::Mat exitance_;  // the photo's exitance per camera pixel (CV_32FC3 R, G, B)
  Comparison comparison_;
};

CameraColour VerificationLoop::ColourOf(const CaptureSessionData& session) const {
  if (in_.colour_source.simulated) {
    const nlohmann::json& manifest = session.manifest();
    const double full_scale = manifest["patterns"][0]["captured"].value("full_scale", 255.0);
    return SimulatedColour(*in_.simulated, manifest, hdr_, full_scale, options_.camera_black);
  }
  CameraColour colour;
  colour.to_exitance = in_.colour_source.matrix;
  colour.black = hdr_ ? 0.0 : in_.colour_source.black;
  colour.source = in_.colour_source.source;
  return colour;
}

CaptureSessionOptions VerificationLoop::SessionOptions(int k) const {
  CaptureSessionOptions session_options;
  session_options.directory = options_.out / "iterations" / std::to_string(k) / "session";
  session_options.sequencer = sequencer_;
  session_options.stop = options_.stop;
  return session_options;
}

void VerificationLoop::Prepare(int k) {
  RenderOptions render_options;
  render_options.light = options_.light;
  render_options.reflectance = HasReflectanceMaps(model_.room.projection);
  images_ = RenderProjectorImages(model_.room.projection, model_.room.geometry.scene, emittance_, render_options,
                                  &render_);
  std::vector<cv::Mat> patterns;
  for (const ProjectorImage& image : images_) patterns.push_back(PatternFromImage(image));
  const cv::Mat pattern = wall_.Compose(patterns);
  sequence_ = CaptureSequence();
  sequence_.kind = "verify";
  sequence_.parameters = {
      {"iteration", k}, {"projectors", in_.names}, {"checksum", PatternChecksum(pattern)}};
  sequence_.patterns.push_back({"solution", pattern, {{"kind", "verify"}, {"iteration", k}}});
  CheckSessionResumable(SessionOptions(k), sequence_, *camera_);
  prepared_ = k;
}

VerificationIteration VerificationLoop::Photograph(int k, nlohmann::json* json) {
  if (prepared_ != k) Prepare(k);
  VerificationIteration it;
  it.index = k;
  it.directory = options_.out / "iterations" / std::to_string(k);
  CreateDirectories(it.directory);
  for (size_t p = 0; p < images_.size(); ++p) {
    WriteProjectorImage(it.directory / (in_.names[p] + ".png"), images_[p]);
  }
  WriteNpy(it.directory / "E.npy", RowMatrixXd(emittance_));
  WriteNpy(it.directory / "B.npy", RowMatrixXd(radiosity_));
  WriteNpy(it.directory / "reflectance.npy", RowMatrixXd(model_.room.projection.reflectance));

  // Show and photograph: the session keeps the photo the moment it is taken.
  const CaptureSessionOptions session_options = SessionOptions(k);
  const auto capture_start = Clock::now();
  CaptureSummary captured;
  try {
    captured = RunCaptureSession(session_options, sequence_, *camera_, wall_);
  } catch (const std::exception& error) {
    throw PhotoFault(error.what());
  }
  if (captured.stopped) throw Stopped("before its photo, which its session records");
  it.capture_seconds = SecondsSince(capture_start);
  const CaptureSessionData session = CaptureSessionData::Load(session_options.directory);
  const cv::Mat photo = hdr_ ? session.Hdr(0) : session.Mean(0);
  const CameraPixelRays& rays = model_.room.camera_rays;
  if (photo.channels() != 3)
    throw IoError(session_options.directory.string() + ": the photo is not colour");
  if (photo.cols != rays.width || photo.rows != rays.height) {
    throw IoError("camera '" + options_.camera + "' delivers " + std::to_string(photo.cols) + "x" +
                  std::to_string(photo.rows) + " photos but " + in_.camera_model_path.string() +
                  " is " + std::to_string(rays.width) + "x" + std::to_string(rays.height));
  }
  const CameraColour colour = ColourOf(session);
  cv::Mat photo32;
  photo.convertTo(photo32, CV_32FC3);
  const cv::Mat exitance = PhotoToExitance(photo32, colour);
  exitance_ = exitance;
  const cv::Mat predicted = PredictPixels(rays, model_.room.projection, images_, model_.room.geometry.form_factors);
  comparison_ = Compare(exitance, rays.patch, model_.room.projection.surface, model_.interior, model_.room.problem,
                        radiosity_, predicted, options_.min_patch_pixels);
  it.seams = comparison_.seams;
  it.measured = comparison_.measured;
  it.model = comparison_.model;
  it.predicted_mean76 = comparison_.predicted_mean76;
  it.predicted_mean2000 = comparison_.predicted_mean2000;
  it.solver_mean76 = SolverMeanDeltaE76(model_.room.problem, radiosity_);
  it.seen_pixels = comparison_.seen_pixels;
  it.seen_patches = comparison_.seen_patches;
  it.model_constant_mean76 = comparison_.model_constant_mean76;
  if (k == 0) heat_scale_ = std::max(10.0, 10.0 * std::ceil(3.0 * it.measured.mean76 / 10.0));
  const double white = model_.room.geometry.scene.white;
  it.photo = LinearToDisplay(exitance / white);
  it.predicted = LinearToDisplay(comparison_.predicted / white);
  it.delta_e76 = HeatMapWithColourBar(comparison_.delta_e76, heat_scale_, "dE76");
  it.model_delta_e76 = HeatMapWithColourBar(comparison_.model_delta_e76, heat_scale_, "dE76");
  WritePng(it.directory / "photo.png", it.photo);
  WritePng(it.directory / "predicted.png", it.predicted);
  WritePng(it.directory / "delta_e76.png", it.delta_e76);
  WritePng(it.directory / "delta_e2000.png",
           HeatMapWithColourBar(comparison_.delta_e2000, heat_scale_ / 2, "dE00"));
  WritePng(it.directory / "model_delta_e76.png", it.model_delta_e76);
  WriteNpy(it.directory / "measured_B.npy", RowMatrixXd(comparison_.patch_exitance));
  Report(options_.progress,
         fmt::format("verify: iteration {}: measured ΔE76 {:.2f} (max {:.1f}), model error "
                     "{:.2f}, predicted {:.2f}, seam {:.2f}, {} patches seen",
                     k, it.measured.mean76, it.measured.max76, it.model.mean76, it.predicted_mean76,
                     it.seams.seam, it.seen_patches));
  if (it.seen_patches == 0) {
    throw IoError("camera '" + options_.camera + "': " + in_.camera_model_path.string() +
                  " sees no patch of the scene (is the camera registered in the room frame?)");
  }
  *json = {{"colour", colour.Json()},
           {"render",
            {{"patches_below_lower", render_.patches_below_lower},
             {"patches_above_upper", render_.patches_above_upper},
             {"max_relative_error", render_.max_relative_error},
             {"reflectance_pixels", render_.reflectance_pixels},
             {"reflectance_saturated_pixels", render_.reflectance_saturated_pixels}}}};
  return it;
}

void VerificationLoop::UpdateAndSolve(VerificationIteration* it) {
  const auto solve_start = Clock::now();
  ModelFitOptions fit;
  fit.fit_response = options_.fit_response;
  fit.fit_reflectance = options_.fit_reflectance;
  fit.reflectance_step = options_.reflectance_step;
  const ModelUpdate update = FitModel(fit, model_.room.projection, images_, model_.room.geometry.form_factors,
                                      comparison_.patch_exitance, comparison_.seen, radiosity_);
  it->response_exponent = update.exponent;
  it->reflectance_scale = update.scale;
  Report(options_.progress,
         fmt::format("verify: model update: reflectance scale ({:.3f}, {:.3f}, {:.3f}), fit "
                     "rms {:.4f} → {:.4f}",
                     update.scale[0], update.scale[1], update.scale[2], update.rms_before,
                     update.rms_after));
  for (size_t p = 0; p < update.exponent.size(); ++p) {
    Report(options_.progress,
           fmt::format("verify:   projector '{}': response exponent ({:.3f}, {:.3f}, {:.3f})",
                       in_.names[p], update.exponent[p][0], update.exponent[p][1],
                       update.exponent[p][2]));
  }
  ApplyModelUpdate(update, &model_.room.projection, &model_.room.geometry.patches);
  if (options_.fit_reflectance_map && HasReflectanceMaps(model_.room.projection)) {
    const ReflectanceMapUpdate map_update =
        FitReflectanceMaps(ReflectanceMapFitOptions(), model_.room.camera_rays, exitance_,
                           comparison_.predicted, model_.interior, &model_.room.projection);
    it->map_refitted_pixels = map_update.updated_pixels;
    it->map_rms_gain = std::exp(map_update.rms_log_gain) - 1.0;
    Report(options_.progress,
           fmt::format("verify: reflectance maps: {} projector pixels refitted, rms gain {:.2f}%",
                       map_update.updated_pixels, 100.0 * it->map_rms_gain));
  }
  CompensationOptions compensation;
  compensation.solver.method = in_.solution.method;
  compensation.solver.multires = in_.solution.multires;
  compensation.alpha = in_.solution.alpha;
  compensation.lower = model_.room.projection.lower;
  compensation.upper = model_.room.projection.upper;
  compensation.progress = options_.progress;
  const CompensationRun run = RunCompensation(model_.room.geometry, compensation);
  emittance_ = run.solution.emittance;
  radiosity_ = run.solution.radiosity;
  model_.room.problem = run.fine;
  it->solve_seconds = SecondsSince(solve_start);
}

// The projectors' response after the iteration's update, for its result.json.
nlohmann::json ProjectorResponses(const ProjectionRig& rig, const std::vector<std::string>& names) {
  nlohmann::json model = nlohmann::json::array();
  for (size_t p = 0; p < rig.projectors.size(); ++p) {
    nlohmann::json gamma = nlohmann::json::array();
    for (int j = 0; j < 3; ++j) {
      const ResponseCurve& curve = rig.projectors[p].photometry.response[j];
      gamma.push_back(curve.is_table() ? nlohmann::json("table") : nlohmann::json(curve.gamma()));
    }
    model.push_back({{"name", names[p]}, {"gamma_after_update", gamma}});
  }
  return model;
}

}  // namespace

namespace {

VerificationSummary RunVerificationLoop(const VerificationOptions& options) {
  const auto start = Clock::now();
  std::string why;
  if (!options.Check(&why)) throw IoError("verify: " + why);
  const VerificationInputs in = ReadInputs(options);
  VerificationModel model = BuildModel(in);
  VerificationLoop loop(options, in, &model);
  loop.Prepare(0);  // a run left there with other inputs is refused before anything is written

  CreateDirectories(options.out);
  VerificationSummary summary;
  summary.termination = "max_iterations";
  summary.rig = in.rig.Describe();
  summary.solution = options.solution_dir.string();
  summary.camera = options.camera;
  summary.colour_source = in.colour_source.source;
  summary.hdr = loop.hdr();
  summary.exposures_us = loop.sequencer().exposures_us;
  summary.settle_ms = loop.sequencer().settle_ms;
  // The rig's reflectance maps as read, for the report's pictures of what the runs refit.
  std::vector<std::vector<Eigen::Vector3f>> maps_before;
  if (HasReflectanceMaps(model.room.projection)) {
    for (const ProjectorMap& map : model.room.projection.maps)
      maps_before.push_back(map.reflectance);
  }
  auto write_summary = [&] {
    summary.reflectance_maps.clear();
    for (size_t p = 0; p < maps_before.size(); ++p) {
      const ProjectorMap& map = model.room.projection.maps[p];
      summary.reflectance_maps.push_back(
          {in.names[p], ReflectanceMapPicture(map, maps_before[p]),
           ReflectanceMapPicture(map, map.reflectance),
           ReflectanceGainPicture(map, maps_before[p], map.reflectance)});
    }
    WriteVerificationRun(options.out, summary);
    HtmlReport report("procam verify");
    AddVerificationReport(summary, &report);
    report.Write(options.out / "report.html");
  };
  summary.desired = DesiredPicture(model);
  WritePng(options.out / "desired.png", summary.desired);

  const auto stopping = [&] { return options.stop != nullptr && options.stop->load(); };
  // A stop: the run so far is written (termination "stopped") and the stop said.
  const auto stop_here = [&](const std::string& where) {
    summary.complete = false;
    summary.termination = "stopped";
    summary.error = "stopped by a signal " + where;
    summary.seconds = SecondsSince(start);
    write_summary();
    throw Stopped(fmt::format(
        "verify: stopped by a signal {} (kept {} complete iteration(s) and the photos taken in "
        "{}, see result.json); run the same command again to resume",
        where, summary.iterations.size(), options.out.string()));
  };

  double best_mean = std::numeric_limits<double>::infinity();
  for (int k = 0; k < options.iterations; ++k) {
    if (stopping()) stop_here(fmt::format("before iteration {}", k));
    const auto iteration_start = Clock::now();
    VerificationIteration it;
    nlohmann::json extra;
    try {
      it = loop.Photograph(k, &extra);
    } catch (const Stopped& stopped) {
      stop_here(fmt::format("in iteration {}, {}", k, stopped.what()));
    } catch (const PhotoFault& error) {
      summary.complete = false;
      summary.termination = "fault";
      summary.error = error.what();
      summary.seconds = SecondsSince(start);
      write_summary();
      throw IoError("verify: iteration " + std::to_string(k) + ": " + error.what() + " (kept " +
                    std::to_string(k) + " complete iteration(s) and the photos taken in " +
                    options.out.string() + ", see result.json)");
    }
    const bool improved = it.measured.mean76 < best_mean * (1.0 - options.min_improvement);
    if (it.measured.mean76 < best_mean) {
      best_mean = it.measured.mean76;
      summary.best = k;
    }
    const bool last = k + 1 == options.iterations || (k > 0 && !improved);
    // Stopped once the photo is compared: the update and its solve are not begun.
    bool stopped = !last && stopping();
    if (!last && !stopped) {
      try {
        loop.UpdateAndSolve(&it);  // update the model from this photo and solve again
      } catch (const Stopped&) {
        stopped = true;  // a computation of the solve cut short: as a stop before it
      }
    }
    it.seconds = SecondsSince(iteration_start);
    nlohmann::json json = IterationJson(it);
    json.update(extra);
    json["projectors"] = ProjectorResponses(model.room.projection, in.names);
    WriteFileAtomically(it.directory / "result.json", json.dump(2) + "\n");
    summary.iterations.push_back(std::move(it));
    summary.seconds = SecondsSince(start);
    write_summary();
    if (stopped)
      stop_here(fmt::format("after iteration {}'s photo (its model update not made)", k));
    if (last) {
      if (k + 1 < options.iterations) summary.termination = "converged";
      break;
    }
  }
  summary.complete = true;
  summary.seconds = SecondsSince(start);
  write_summary();
  return summary;
}

}  // namespace

VerificationSummary RunVerification(const VerificationOptions& options) {
  // The displays given by name, opened (after the options' checks).
  VerificationOptions opened;
  const VerificationOptions* run = &options;
  if (!options.display_names.empty()) {
    std::string why;
    if (!options.Check(&why)) throw IoError("verify: " + why);
    const std::string flag = FlagOf(options, &options.display_names);
    if (CameraUri::Parse(options.camera).scheme() == "synthetic") {
      throw IoError(flag + ": camera '" + options.camera +
                    "' photographs the simulated room, whose own projectors show the images");
    }
    if (!options.open_display) throw std::invalid_argument(flag + ": no way to open a display");
    opened = options;
    for (const std::string& name : options.display_names)
      opened.displays.push_back(options.open_display(name));
    opened.display_names.clear();
    run = &opened;
  }
  try {
    return RunVerificationLoop(*run);
  } catch (const Stopped& stopped) {
    const std::string what = stopped.what();
    if (what.starts_with("verify: ")) throw;
    // A computation before the first photo cut short (the form factors, the latency).
    throw Stopped("verify: stopped by a signal before its first photo (" + what +
                  "); nothing written; run the same command again");
  }
}

void AddVerificationReport(const VerificationSummary& summary, HtmlReport* report) {
  report->Heading("Verification with photos and the closed loop");
  report->Paragraph(
      "Each iteration shows the solution's projector images, photographs the room and compares "
      "the photo in CIE L*a*b* with the desired appearance (measured ΔE) and with what the model "
      "predicts (model error); then the model (projector response exponents, per-patch "
      "reflectance) is updated from measured minus predicted and the problem solved again. "
      "Predicted: the solver's radiosity against the desired, on the patches the camera sees.");
  std::vector<std::vector<std::string>> rows;
  std::vector<std::pair<double, double>> measured, model, predicted;
  for (const VerificationIteration& it : summary.iterations) {
    std::string update = "—";
    if (!it.response_exponent.empty()) {
      update = fmt::format("ρ scale ({:.3f}, {:.3f}, {:.3f})", it.reflectance_scale[0],
                           it.reflectance_scale[1], it.reflectance_scale[2]);
      for (const Eigen::Vector3d& e : it.response_exponent)
        update += fmt::format("; γ × ({:.3f}, {:.3f}, {:.3f})", e[0], e[1], e[2]);
    }
    rows.push_back({std::to_string(it.index) + (it.index == summary.best ? " (best)" : ""),
                    fmt::format("{:.2f} ({:.1f})", it.measured.mean76, it.measured.max76),
                    fmt::format("{:.2f}", it.measured.mean2000),
                    fmt::format("{:.2f}", it.seams.seam), fmt::format("{:.2f}", it.model.mean76),
                    fmt::format("{:.2f}", it.predicted_mean76), std::to_string(it.seen_patches),
                    update + (it.map_refitted_pixels > 0
                                  ? fmt::format("; maps: {} pixels, rms {:.1f}%",
                                                it.map_refitted_pixels, 100 * it.map_rms_gain)
                                  : ""),
                    fmt::format("{:.1f}", it.seconds)});
    measured.emplace_back(it.index, std::max(1e-3, it.measured.mean76));
    model.emplace_back(it.index, std::max(1e-3, it.model.mean76));
    predicted.emplace_back(it.index, std::max(1e-3, it.predicted_mean76));
  }
  report->Table({"iteration", "measured ΔE76 mean (max)", "measured CIEDE2000 mean",
                 "seam (CIEDE2000)", "model error ΔE76 mean", "predicted ΔE76 mean", "patches seen",
                 "model update after it", "seconds"},
                rows);
  if (!summary.complete) {
    report->Paragraph((summary.termination == "stopped" ? "Stopped: " : "Stopped by a fault: ") +
                      summary.error);
  }
  if (!summary.iterations.empty()) {
    report->Plot("Convergence", "iteration", "mean ΔE76",
                 {{"measured (photo vs desired)", measured},
                  {"model error (photo vs predicted)", model},
                  {"predicted (solver vs desired)", predicted}});
  }
  if (!summary.desired.empty())
    report->Figures({{"desired (per patch, as the camera sees it)", summary.desired}});
  if (!summary.reflectance_maps.empty()) {
    report->Heading("Reflectance maps", 3);
    report->Paragraph(
        "Each projector's per-pixel reflectance (the rig's map, in projector pixels): as the rig "
        "gave it, as the photos refitted it (each camera pixel's photo over prediction, relative "
        "to its patch's), and how much each pixel changed. The refit is kept for this run only; "
        "the rig's files are not changed.");
    std::vector<std::pair<std::string, cv::Mat>> figures;
    for (const VerificationSummary::MapPictures& maps : summary.reflectance_maps) {
      figures.push_back({maps.projector + ": from the rig", maps.before});
      figures.push_back({maps.projector + ": refitted", maps.after});
      figures.push_back({maps.projector + ": change", maps.gain});
    }
    report->Figures(figures);
  }
  for (const VerificationIteration& it : summary.iterations) {
    report->Heading(fmt::format("Iteration {}", it.index), 3);
    report->Figures({{"photo", it.photo},
                     {"predicted", it.predicted},
                     {"ΔE76 photo vs desired", it.delta_e76},
                     {"ΔE76 photo vs predicted", it.model_delta_e76}});
  }
}

}  // namespace procam
