#include "capture/session.h"

#include <algorithm>
#include <chrono>
#include <initializer_list>
#include <cmath>
#include <cstdio>
#include <ctime>
#include <opencv2/imgcodecs.hpp>

#include "base/image_io.h"
#include "base/io.h"
#include "base/timing.h"

namespace procam {
namespace {

namespace fs = std::filesystem;

constexpr const char* kManifestName = "session.json";
constexpr const char* kFormat = "procam capture session";
constexpr int kVersion = 1;

std::string UtcNow() {
  const std::time_t now = std::chrono::system_clock::to_time_t(std::chrono::system_clock::now());
  std::tm utc{};
  gmtime_r(&now, &utc);
  char text[32];
  std::strftime(text, sizeof(text), "%Y-%m-%dT%H:%M:%SZ", &utc);
  return text;
}

std::string Padded(int value) {
  char text[16];
  std::snprintf(text, sizeof(text), "%03d", value);
  return text;
}

std::string ExposureTag(double exposure_us) {
  char text[32];
  std::snprintf(text, sizeof(text), "%.0f", exposure_us);
  return text;
}

// The device part of a camera URI: "aravis:Fake_1" of "aravis:Fake_1?trigger=software".
std::string DeviceOf(const std::string& uri) { return uri.substr(0, uri.find('?')); }

nlohmann::json RangeJson(const ControlRange& range) {
  if (!range.available) return nullptr;
  return {{"min", range.min}, {"max", range.max}, {"step", range.step}};
}

nlohmann::json SettingsJson(const CameraSettings& settings) {
  return {{"width", settings.width},
          {"height", settings.height},
          {"pixel_format", PixelFormatName(settings.pixel_format)},
          {"exposure_us", settings.exposure_us},
          {"gain", settings.gain},
          {"gain_unit", settings.gain_unit},
          {"auto_exposure", settings.auto_exposure},
          {"trigger", settings.trigger},
          {"exposure_range_us", RangeJson(settings.exposure_range_us)},
          {"gain_range", RangeJson(settings.gain_range)}};
}

nlohmann::json CaptureJson(const SequencerOptions& options) {
  return {{"frames_per_pattern", options.frames_per_pattern},
          {"discard_frames", options.discard_frames},
          {"exposures_us", options.exposures_us},
          {"settle_ms", options.settle_ms}};
}

// Writes the image and returns its file's ContentChecksum.
std::string WriteImage(const fs::path& path, const cv::Mat& image,
                       const std::vector<int>& params = {}) {
  std::vector<uint8_t> bytes;
  bool encoded = false;
  try {
    encoded = cv::imencode(path.extension().string(), image, bytes, params);
  } catch (const cv::Exception& error) {
    throw IoError(path.string() + ": cannot encode image: " + error.what());
  }
  if (!encoded) throw IoError(path.string() + ": cannot encode image");
  const std::string contents(bytes.begin(), bytes.end());
  WriteFileAtomically(path, contents);
  return ContentChecksum(contents);
}

void WriteManifest(const fs::path& directory, nlohmann::json& manifest) {
  manifest["updated"] = UtcNow();
  WriteFileAtomically(directory / kManifestName, manifest.dump(2) + "\n");
}

// A recorded frame read back: checked against the checksum recorded with it (sessions written
// before checksums were recorded have none, and are only decoded), then decoded.
cv::Mat ReadFrame(const fs::path& file, const nlohmann::json& checksum) {
  if (checksum.is_string())
    return ReadImageChecked(file, cv::IMREAD_UNCHANGED, checksum.get<std::string>());
  return ReadImage(file, cv::IMREAD_UNCHANGED);
}

// Whether `file` still holds the frame recorded (its checksum) and decodes to an image of one of
// `depths` (a frame left by a crash, altered or truncated since does not, and is captured again).
bool FrameReadable(const fs::path& file, const nlohmann::json& checksum,
                   std::initializer_list<int> depths) {
  try {
    const int depth = ReadFrame(file, checksum).depth();
    return std::find(depths.begin(), depths.end(), depth) != depths.end();
  } catch (const IoError&) {
    return false;
  }
}

bool PatternComplete(const fs::path& directory, const nlohmann::json& entry) {
  if (!entry.contains("captured") || entry["captured"].is_null()) return false;
  const nlohmann::json& captured = entry["captured"];
  for (const nlohmann::json& exposure : captured.at("exposures")) {
    if (!FrameReadable(directory / exposure.at("file").get<std::string>(),
                       exposure.value("file_checksum", nlohmann::json()), {CV_16U}))
      return false;
  }
  if (captured.contains("hdr") && !captured["hdr"].is_null() &&
      !FrameReadable(directory / captured["hdr"].get<std::string>(),
                     captured.value("hdr_checksum", nlohmann::json()), {CV_32F})) {
    return false;
  }
  return true;
}

// Why an existing session cannot be resumed with these settings; empty when it can.
std::string Mismatch(const nlohmann::json& manifest, const CaptureSequence& sequence,
                     const SequencerOptions& options, const CameraInfo& info,
                     const CameraSettings& settings) {
  if (manifest.value("format", "") != kFormat) return "not a procam capture session";
  if (manifest.value("version", 0) != kVersion)
    return "session version " + manifest.value("version", nlohmann::json()).dump() + " is not 1";
  const nlohmann::json& stored_sequence = manifest.at("sequence");
  if (stored_sequence.at("kind") != sequence.kind) {
    return "it holds a '" + stored_sequence.at("kind").get<std::string>() + "' sequence, not '" +
           sequence.kind + "'";
  }
  if (stored_sequence.at("parameters") != sequence.parameters) {
    return "sequence parameters differ: stored " + stored_sequence.at("parameters").dump() +
           ", now " + sequence.parameters.dump();
  }
  const nlohmann::json& patterns = manifest.at("patterns");
  if (patterns.size() != sequence.patterns.size()) return "pattern count differs";
  for (size_t i = 0; i < patterns.size(); ++i) {
    if (patterns[i].at("name") != sequence.patterns[i].name ||
        patterns[i].at("checksum") != PatternChecksum(sequence.patterns[i].image)) {
      return "pattern " + std::to_string(i) + " (" + patterns[i].at("name").get<std::string>() +
             ") differs";
    }
  }
  nlohmann::json stored_capture = manifest.at("capture");
  nlohmann::json capture = CaptureJson(options);
  stored_capture.erase("settle_ms");  // timing may change between runs; what is averaged may not
  capture.erase("settle_ms");
  if (stored_capture != capture)
    return "capture settings differ: stored " + stored_capture.dump() + ", now " + capture.dump();
  const nlohmann::json& camera = manifest.at("camera");
  if (camera.at("device") != DeviceOf(info.uri)) {
    return "it was captured with camera '" + camera.at("device").get<std::string>() + "', not '" +
           DeviceOf(info.uri) + "'";
  }
  const nlohmann::json& stored_settings = camera.at("settings");
  if (stored_settings.at("width") != settings.width ||
      stored_settings.at("height") != settings.height ||
      stored_settings.at("pixel_format") != PixelFormatName(settings.pixel_format)) {
    return "camera format differs: stored " + stored_settings.at("width").dump() + "x" +
           stored_settings.at("height").dump() + " " +
           stored_settings.at("pixel_format").get<std::string>() + ", now " +
           std::to_string(settings.width) + "x" + std::to_string(settings.height) + " " +
           PixelFormatName(settings.pixel_format);
  }
  return "";
}

nlohmann::json NewManifest(const CaptureSequence& sequence, const SequencerOptions& options,
                           const CameraInfo& info, const CameraSettings& settings,
                           const PatternDisplay& display) {
  nlohmann::json manifest;
  manifest["format"] = kFormat;
  manifest["version"] = kVersion;
  manifest["sequence"] = {{"kind", sequence.kind}, {"parameters", sequence.parameters}};
  manifest["capture"] = CaptureJson(options);
  manifest["camera"] = {{"device", DeviceOf(info.uri)},
                        {"uri", info.uri},
                        {"backend", info.backend},
                        {"vendor", info.vendor},
                        {"model", info.model},
                        {"serial", info.serial},
                        {"settings", SettingsJson(settings)}};
  manifest["display"] = {{"name", display.Name()},
                         {"width", display.Resolution().width},
                         {"height", display.Resolution().height}};
  manifest["complete"] = false;
  manifest["created"] = UtcNow();
  manifest["runs"] = nlohmann::json::array();
  manifest["interruptions"] = nlohmann::json::array();
  nlohmann::json patterns = nlohmann::json::array();
  for (size_t i = 0; i < sequence.patterns.size(); ++i) {
    const Pattern& pattern = sequence.patterns[i];
    patterns.push_back(
        {{"index", i},
         {"name", pattern.name},
         {"file", "patterns/" + Padded(static_cast<int>(i)) + "_" + pattern.name + ".png"},
         {"checksum", PatternChecksum(pattern.image)},
         {"info", pattern.info},
         {"captured", nullptr}});
  }
  manifest["patterns"] = patterns;
  return manifest;
}

// Writes a captured pattern's images and returns its manifest entry.
nlohmann::json WriteCapture(const fs::path& directory, int index, const std::string& name,
                            const PatternCapture& capture) {
  const std::string stem = "frames/" + Padded(index) + "_" + name;
  nlohmann::json exposures = nlohmann::json::array();
  const double png_scale = 65535.0 / capture.full_scale;
  for (const ExposureCapture& exposure : capture.exposures) {
    const std::string file = stem + "_e" + ExposureTag(exposure.exposure_us) + "us.png";
    cv::Mat png;
    exposure.mean.convertTo(png, CV_16U, png_scale);  // rounds and saturates
    const std::string checksum = WriteImage(directory / file, png);
    exposures.push_back({{"exposure_us", exposure.exposure_us},
                         {"file_checksum", checksum},
                         {"gain", exposure.gain},
                         {"file", file},
                         {"png_scale", png_scale},
                         {"frames", exposure.frames},
                         {"sequences", exposure.sequences},
                         {"buffered_dropped", exposure.buffered_dropped},
                         {"stale_dropped", exposure.stale_dropped},
                         {"discarded", exposure.discarded},
                         {"first_exposure_start_ns", exposure.first_exposure_start_ns},
                         {"last_arrival_ns", exposure.last_arrival_ns}});
  }
  nlohmann::json hdr = nullptr, hdr_checksum = nullptr;
  if (!capture.hdr.empty()) {
    const std::string file = stem + "_hdr.tiff";
    hdr_checksum = WriteImage(directory / file, capture.hdr,
                              {cv::IMWRITE_TIFF_COMPRESSION, 1});  // lossless float
    hdr = file;
  }
  return {{"time", UtcNow()},
          {"shown_ns", capture.shown_ns},
          {"settled_ns", capture.settled_ns},
          {"retries", capture.retries},
          {"retry_reasons", capture.retry_reasons},
          {"full_scale", capture.full_scale},
          {"exposures", exposures},
          {"hdr", hdr},
          {"hdr_checksum", hdr_checksum}};
}

// The manifest of the session in options.directory if it can be resumed with these settings,
// null when there is none. Throws IoError naming what differs.
nlohmann::json ResumableManifest(const CaptureSessionOptions& options,
                                 const CaptureSequence& sequence, const CameraInfo& info,
                                 const CameraSettings& settings) {
  const fs::path manifest_path = options.directory / kManifestName;
  if (!fs::exists(manifest_path)) return nullptr;
  try {
    nlohmann::json manifest = nlohmann::json::parse(ReadFile(manifest_path));
    const std::string mismatch = Mismatch(manifest, sequence, options.sequencer, info, settings);
    if (!mismatch.empty()) {
      throw IoError(manifest_path.string() + ": cannot resume: " + mismatch +
                    " (use another --out directory, or the settings it was started with)");
    }
    return manifest;
  } catch (const nlohmann::json::exception& parse_error) {
    throw IoError(manifest_path.string() + ": malformed manifest: " + parse_error.what());
  }
}

}  // namespace

void WriteImportedSession(const fs::path& directory, const std::string& kind,
                          const nlohmann::json& parameters, const std::string& display_name,
                          cv::Size display_size, const std::vector<ImportedPhoto>& photos) {
  const fs::path manifest_path = directory / kManifestName;
  if (fs::exists(manifest_path)) {
    nlohmann::json old;
    try {
      old = nlohmann::json::parse(ReadFile(manifest_path));
    } catch (const nlohmann::json::exception&) {
    }
    if (!old.is_object() || old.value("format", "") != kFormat ||
        old.value("camera", nlohmann::json::object()).value("device", "") != "import") {
      throw IoError(manifest_path.string() +
                    ": holds a capture session that was not imported; import into another "
                    "directory");
    }
  }
  std::error_code error;
  fs::create_directories(directory, error);
  if (error) throw IoError(directory.string() + ": cannot create directory: " + error.message());
  nlohmann::json manifest;
  manifest["format"] = kFormat;
  manifest["version"] = kVersion;
  manifest["sequence"] = {{"kind", kind}, {"parameters", parameters}};
  manifest["capture"] = {{"imported", true}};
  manifest["camera"] = {{"device", "import"}, {"uri", "import"}, {"backend", "import"}};
  manifest["display"] = {
      {"name", display_name}, {"width", display_size.width}, {"height", display_size.height}};
  manifest["complete"] = true;
  manifest["created"] = UtcNow();
  manifest["runs"] = nlohmann::json::array();
  manifest["interruptions"] = nlohmann::json::array();
  nlohmann::json patterns = nlohmann::json::array();
  for (size_t i = 0; i < photos.size(); ++i) {
    const ImportedPhoto& photo = photos[i];
    nlohmann::json exposure = {{"exposure_us", nullptr},
                               {"file", photo.file.string()},
                               {"file_checksum", photo.checksum},
                               {"png_scale", 1.0}};
    patterns.push_back({{"index", i},
                        {"name", photo.name},
                        {"file", nullptr},
                        {"checksum", nullptr},
                        {"info", photo.info},
                        {"captured",
                         {{"time", UtcNow()},
                          {"imported", true},
                          {"full_scale", photo.full_scale},
                          {"exposures", nlohmann::json::array({exposure})},
                          {"hdr", nullptr}}}});
  }
  manifest["patterns"] = patterns;
  WriteManifest(directory, manifest);
}

void CheckSessionResumable(const CaptureSessionOptions& options, const CaptureSequence& sequence,
                           const Camera& camera) {
  ResumableManifest(options, sequence, camera.Info(), camera.Settings());
}

bool CaptureSessionOptions::Check(std::string* why) const {
  if (directory.empty()) {
    if (why) *why = "no session directory";
    return false;
  }
  return sequencer.Check(why);
}

std::string CaptureSummary::BriefReport() const {
  char text[256];
  std::snprintf(text, sizeof(text),
                "%d/%d patterns captured (%d this run, %d already there), %d retries, %d stale "
                "frames dropped, %.1f s",
                patterns_before + patterns_captured, patterns_total, patterns_captured,
                patterns_before, retries, stale_dropped, seconds);
  return text;
}

CaptureSummary RunCaptureSession(const CaptureSessionOptions& options,
                                 const CaptureSequence& sequence, Camera& camera,
                                 PatternDisplay& display) {
  std::string why;
  if (!options.Check(&why)) throw std::invalid_argument("CaptureSessionOptions: " + why);
  if (sequence.patterns.empty()) throw std::invalid_argument("RunCaptureSession: empty sequence");
  const auto start = Clock::now();
  const fs::path& directory = options.directory;
  const fs::path manifest_path = directory / kManifestName;
  const CameraInfo info = camera.Info();
  const CameraSettings settings = camera.Settings();
  nlohmann::json manifest = ResumableManifest(options, sequence, info, settings);
  if (manifest.is_null())
    manifest = NewManifest(sequence, options.sequencer, info, settings, display);
  std::error_code error;
  for (const char* sub : {"patterns", "frames"}) {
    fs::create_directories(directory / sub, error);
    if (error)
      throw IoError((directory / sub).string() + ": cannot create directory: " + error.message());
  }

  CaptureSummary summary;
  summary.manifest = manifest_path;
  summary.patterns_total = static_cast<int>(sequence.patterns.size());
  nlohmann::json& patterns = manifest["patterns"];
  for (size_t i = 0; i < sequence.patterns.size(); ++i) {
    const fs::path file = directory / patterns[i]["file"].get<std::string>();
    if (!fs::exists(file)) WriteImage(file, sequence.patterns[i].image);
    if (PatternComplete(directory, patterns[i])) {
      ++summary.patterns_before;
    } else {
      patterns[i]["captured"] = nullptr;
    }
  }
  manifest["runs"].push_back({{"started", UtcNow()},
                              {"uri", info.uri},
                              {"settings", SettingsJson(settings)},
                              {"patterns_before", summary.patterns_before}});
  WriteManifest(directory, manifest);

  PatternSequencer sequencer(options.sequencer, &camera, &display);
  const auto stopping = [&] { return options.stop != nullptr && options.stop->load(); };
  // Records an interruption at pattern i (what the next run resumes from).
  const auto interrupted = [&](size_t i, const std::string& reason) {
    manifest["interruptions"].push_back({{"time", UtcNow()},
                                         {"pattern", i},
                                         {"name", sequence.patterns[i].name},
                                         {"reason", reason}});
    manifest["runs"].back()["patterns_captured"] = summary.patterns_captured;
    WriteManifest(directory, manifest);
  };
  const auto stopped_at = [&](size_t i) {
    interrupted(i, "stopped by a signal");
    summary.stopped = true;
    summary.seconds = SecondsSince(start);
    return summary;
  };
  for (size_t i = 0; i < sequence.patterns.size(); ++i) {
    if (!patterns[i]["captured"].is_null()) continue;
    if (stopping()) return stopped_at(i);
    PatternCapture capture;
    try {
      capture = sequencer.Capture(sequence.patterns[i].image);
    } catch (const IoError& error) {  // camera or display: record where and why, keep the rest
      if (stopping()) return stopped_at(i);  // a grab the signal cut short: the stop, no fault
      const int kept = summary.patterns_before + summary.patterns_captured;
      interrupted(i, error.what());
      const std::string message =
          std::string(error.what()) + " at pattern " + std::to_string(i + 1) + "/" +
          std::to_string(sequence.patterns.size()) + " (" + sequence.patterns[i].name + "); " +
          std::to_string(kept) + " captured patterns are kept in " + directory.string() +
          "; run the same command again to resume";
      if (dynamic_cast<const CaptureFault*>(&error)) throw CaptureFault(message);
      throw IoError(message);
    }
    patterns[i]["captured"] =
        WriteCapture(directory, static_cast<int>(i), sequence.patterns[i].name, capture);
    ++summary.patterns_captured;
    summary.retries += capture.retries;
    for (const ExposureCapture& exposure : capture.exposures)
      summary.stale_dropped += exposure.stale_dropped;
    manifest["runs"].back()["patterns_captured"] = summary.patterns_captured;
    WriteManifest(directory, manifest);
  }
  manifest["complete"] = true;
  WriteManifest(directory, manifest);
  summary.seconds = SecondsSince(start);
  return summary;
}

CaptureSessionData CaptureSessionData::Load(const fs::path& directory) {
  CaptureSessionData data;
  data.directory_ = directory;
  const fs::path path = directory / kManifestName;
  try {
    data.manifest_ = nlohmann::json::parse(ReadFile(path));
  } catch (const nlohmann::json::exception& error) {
    throw IoError(path.string() + ": malformed manifest: " + error.what());
  }
  if (!data.manifest_.is_object() || data.manifest_.value("format", "") != kFormat ||
      !data.manifest_.contains("patterns") || !data.manifest_["patterns"].is_array()) {
    throw IoError(path.string() + ": not a procam capture session");
  }
  return data;
}

bool CaptureSessionData::complete() const { return manifest_.value("complete", false); }

int CaptureSessionData::pattern_count() const {
  return static_cast<int>(manifest_.at("patterns").size());
}

bool CaptureSessionData::captured(int pattern) const {
  if (pattern < 0 || pattern >= pattern_count()) return false;
  // at() and value(): operator[] on a const json asserts when the key is missing (fuzz_session).
  const nlohmann::json& entry = manifest_.at("patterns").at(pattern);
  return entry.is_object() && !entry.value("captured", nlohmann::json()).is_null();
}

std::string CaptureSessionData::pattern_name(int pattern) const {
  return manifest_.at("patterns").at(pattern).at("name").get<std::string>();
}

cv::Mat CaptureSessionData::Mean(int pattern, int exposure) const {
  double scale = 1.0;
  const cv::Mat png = Stored(pattern, exposure, &scale);
  cv::Mat mean;
  png.convertTo(mean, CV_32F, 1.0 / scale);
  return mean;
}

cv::Mat CaptureSessionData::Stored(int pattern, int exposure, double* scale) const {
  if (!captured(pattern)) {
    throw IoError((directory_ / kManifestName).string() + ": pattern " + std::to_string(pattern) +
                  " is not captured");
  }
  const nlohmann::json& entry =
      manifest_["patterns"][pattern]["captured"]["exposures"].at(exposure);
  const fs::path file = directory_ / entry.at("file").get<std::string>();
  const cv::Mat png = ReadFrame(file, entry.value("file_checksum", nlohmann::json()));
  // procam's own frames are 16-bit PNGs; an imported session's photos 8- or 16-bit.
  if (png.depth() != CV_16U && png.depth() != CV_8U)
    throw IoError(file.string() + ": not an 8- or 16-bit image");
  *scale = entry.at("png_scale").get<double>();
  return png;
}

cv::Mat CaptureSessionData::Hdr(int pattern) const {
  if (!captured(pattern)) {
    throw IoError((directory_ / kManifestName).string() + ": pattern " + std::to_string(pattern) +
                  " is not captured");
  }
  const nlohmann::json& hdr = manifest_["patterns"][pattern]["captured"]["hdr"];
  if (hdr.is_null()) return cv::Mat();
  const fs::path file = directory_ / hdr.get<std::string>();
  const cv::Mat image = ReadFrame(
      file, manifest_["patterns"][pattern]["captured"].value("hdr_checksum", nlohmann::json()));
  if (image.depth() != CV_32F) throw IoError(file.string() + ": missing or not a float TIFF");
  return image;
}

}  // namespace procam
