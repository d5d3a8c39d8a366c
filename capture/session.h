#pragma once
// Capture sessions: a directory that holds everything one capture run (or several, when it is
// interrupted and resumed) produced, so nothing captured is ever lost.
//
//   DIR/session.json                       the manifest (below), rewritten atomically after
//                                          every pattern
//   DIR/patterns/NNN_<name>.png            each pattern exactly as shown (8-bit)
//   DIR/frames/NNN_<name>_e<us>us.png      mean of the frames at one exposure, 16-bit PNG:
//                                          digital number = png value / png_scale
//   DIR/frames/NNN_<name>_hdr.tiff         with several exposures: the linear HDR merge
//                                          (32-bit float TIFF, full scale per second)
//
// An imported session (WriteImportedSession) holds no patterns/ or frames/: its frames' files are
// the other tool's photos, by absolute path.
//
// Manifest: {"format": "procam capture session", "version": 1, "sequence": {kind, parameters},
// "capture": {frames_per_pattern, discard_frames, exposures_us, settle_ms}, "camera": {device,
// uri, vendor, model, serial, settings}, "display": {name, width, height}, "complete",
// "created", "updated", "runs": [...], "interruptions": [...], "patterns": [{index, name, file,
// checksum, info, "captured": null | {time, shown_ns, settled_ns, retries, full_scale,
// exposures: [{exposure_us, gain, file, file_checksum, png_scale, frames, sequences,
// buffered_dropped, stale_dropped, discarded, first_exposure_start_ns, last_arrival_ns}], hdr,
// hdr_checksum}}]}. file_checksum and hdr_checksum are the ContentChecksum (base/io.h) of the
// frame's file as written: a frame altered or truncated since is captured again on resume and
// refused, with one line naming it, by every reader (sessions written before checksums were
// recorded have none and are read as they are).
//
// Every file is written through a temporary file and a rename (WriteFileAtomically), frames
// before the manifest entry that names them, so a crash at any point leaves a consistent
// session: a pattern is either recorded with all its files or captured again on resume.

#include <atomic>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <opencv2/core.hpp>
#include <string>

#include "capture/camera.h"
#include "capture/display.h"
#include "capture/patterns.h"
#include "capture/sequencer.h"

namespace procam {

struct CaptureSessionOptions {
  std::filesystem::path directory;  // created when missing; resumed when it holds session.json
  SequencerOptions sequencer;
  // Set (by a signal handler) to stop cleanly before the next pattern: the session keeps every
  // pattern captured, records the stop as an interruption and resumes when run again. Null: run
  // to the end.
  const std::atomic<bool>* stop = nullptr;
  bool Check(std::string* why) const;
};

struct CaptureSummary {
  int patterns_total = 0;
  int patterns_before = 0;    // already captured when this run started (a resumed session)
  int patterns_captured = 0;  // captured by this run
  int retries = 0;            // failed grabs retried successfully
  int stale_dropped = 0;      // frames dropped because they were exposed before a pattern settled
  double seconds = 0.0;
  std::filesystem::path manifest;
  std::string camera;  // the camera's URI as it names itself (set by callers that opened it)
  double settle_ms = 0.0;  // the settle time used (set by callers: given, or measured)
  bool stopped = false;    // ended by CaptureSessionOptions::stop before every pattern was captured
  std::string BriefReport() const;  // one line
};

// Captures every pattern of `sequence` that options.directory does not hold yet, showing it on
// `display` and photographing it with `camera`. Returns early, `stopped` set, when options.stop
// is set (a grab that fails once the stop is set is taken as the stop, not as a fault).
// Throws IoError when the directory holds a session of another sequence, another camera or other
// capture settings (the message names what differs); CaptureFault when the camera keeps failing
// — the patterns captured so far and the interruption are in the manifest, and running the same
// call again resumes after the last captured pattern.
CaptureSummary RunCaptureSession(const CaptureSessionOptions& options,
                                 const CaptureSequence& sequence, Camera& camera,
                                 PatternDisplay& display);

// Checks, writing nothing, that RunCaptureSession could start or resume the session in
// options.directory with `sequence` and `camera`: throws the IoError it would ("cannot resume:
// ..." naming what differs, or a malformed manifest). Lets a caller check before it writes files
// of its own beside the session.
void CheckSessionResumable(const CaptureSessionOptions& options, const CaptureSequence& sequence,
                           const Camera& camera);

// One photo made by another tool, recorded in a session as it lies (capture/session.h, imported
// sessions): nothing is copied.
struct ImportedPhoto {
  std::string name;                // the pattern's name ("pat00"), unique in the session
  nlohmann::json info;             // what the pattern encodes, as Pattern::info
  std::filesystem::path file;      // the photo, absolute
  std::string checksum;            // ContentChecksum of its bytes as imported
  double full_scale = 255.0;       // its largest digital number: 255 (8-bit) or 65535 (16-bit)
};

// Writes DIR/session.json for photos captured by another tool: sequence `kind` with
// `parameters`, the display `display_name` of `display_size`, every pattern captured, each
// frame's file the photo itself (absolute path, with its checksum: a photo changed later is
// refused by every reader), camera device "import", complete. The directory is created; a
// directory that holds another session is refused (IoError naming its manifest) unless it holds
// an imported one, which is replaced. Throws IoError naming the file on write errors.
void WriteImportedSession(const std::filesystem::path& directory, const std::string& kind,
                          const nlohmann::json& parameters, const std::string& display_name,
                          cv::Size display_size, const std::vector<ImportedPhoto>& photos);

// A session read back, for calibration and tests.
class CaptureSessionData {
 public:
  // Throws IoError naming the file when session.json is missing or malformed.
  static CaptureSessionData Load(const std::filesystem::path& directory);

  const std::filesystem::path& directory() const { return directory_; }
  const nlohmann::json& manifest() const { return manifest_; }
  bool complete() const;
  int pattern_count() const;
  bool captured(int pattern) const;
  std::string pattern_name(int pattern) const;
  // Mean digital numbers (CV_32FC1 or CV_32FC3) of `pattern` at its `exposure`-th exposure.
  // Throws IoError when the pattern is not captured or its file is unreadable.
  cv::Mat Mean(int pattern, int exposure = 0) const;
  // The same frame as stored (CV_8U or CV_16U, one or three channels) and, in `scale`, stored
  // values per digital number (Mean = stored / scale): readers that take any depth (the
  // structured-light decoder) need not convert it. Throws as Mean does.
  cv::Mat Stored(int pattern, int exposure, double* scale) const;
  // The HDR merge (full scale per second), or an empty matrix without bracketing.
  cv::Mat Hdr(int pattern) const;

 private:
  std::filesystem::path directory_;
  nlohmann::json manifest_;
};

}  // namespace procam
