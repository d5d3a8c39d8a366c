#pragma once
// Structured light captured by other tools, and procam's own patterns for other tools to show.
//
// A layout file (JSON, docs/capture_layout.md) describes a folder of photos: the projector's
// size, which photo shows which pattern (OpenCV's GrayCodePattern order, procam's plain or XOR
// Gray code, phase-shift sets with their periods, shifts, sign and origin, white and black) and
// where the photos are. ImportCaptures turns such a folder into a capture session
// (capture/session.h) that records the photos where they lie, each with its checksum, so every
// command that takes a structured-light session takes it; ExportPatterns writes procam's own
// sequence as numbered PNGs with its layout file, for a projector driven by another program.
// ReadStructuredLightSession reads either kind of session back for decoding; DecodeSession
// decodes one and writes a picture and the numbers of the decode.

#include <filesystem>
#include <nlohmann/json.hpp>
#include <opencv2/core.hpp>
#include <string>
#include <vector>

#include "base/progress.h"
#include "calibration/structured_light.h"

namespace procam {

class OptionTable;

// One block of a layout's sequence: one or more consecutive photos.
struct LayoutBlock {
  std::string kind;  // "white", "black", "gray" or "phase"
  // gray: "gray" (the reflected binary code g = n xor (n >> 1), most significant bit first),
  // "opencv" (the same, as OpenCV's structured_light::GrayCodePattern generates it: columns then
  // rows, each bit followed by its inverse; `cell` scales its pattern up), or "xor" (every plane
  // above the finest shown XORed with the finest, Gupta et al. 2011).
  std::string code = "gray";
  std::string axes = "both";  // gray: "columns", "rows" or "both" (columns first)
  int cell = 1;               // gray: projector pixels per code value, ≥ 1
  int finest_bit = 0;         // gray: the lowest bit shown, ≥ 0
  bool inverse = true;        // gray: each bit image followed by its inverse
  std::string axis = "columns";     // phase: "columns" or "rows"
  double period = 0.0;              // phase: projector pixels, > 1
  std::vector<double> shifts_deg;   // phase: one per photo, degrees
  double origin = 0.0;              // phase: projector coordinate of phase 0
  int direction = 1;                // phase: +1 or −1
  std::string function = "cos";     // phase: "cos" or "sin"
};

// A layout file's contents.
struct CaptureLayout {
  int width = 0, height = 0;       // projector pixels
  std::string projector_name;      // optional: the projector's name in a rig
  std::vector<LayoutBlock> blocks;  // in the order the photos were taken
  // Where the photos are, relative to the folder: the names in order, or a printf pattern of one
  // integer ("pat%02d.png") numbered from `first`; neither: the folder's PNG, JPEG, TIFF and BMP
  // files in natural name order ("pat2" before "pat10").
  std::vector<std::string> files;
  std::string file_pattern;
  int first = 0;
  // The decoder's view of the blocks. Throws IoError naming `file` and the key when the blocks
  // do not describe a decodable capture.
  StructuredLightLayout Decodable(const std::string& file = "layout") const;
};

// Reads a layout file; every problem is an IoError "FILE: key: what".
CaptureLayout ReadCaptureLayout(const std::filesystem::path& path);
// The same, from JSON already parsed (`file` names it in errors).
CaptureLayout ParseCaptureLayout(const nlohmann::json& json, const std::string& file);
// The layout file's JSON (format "procam capture layout", version 1): what WriteCaptureLayout
// writes and what an imported session records as its sequence parameters.
nlohmann::json CaptureLayoutJson(const CaptureLayout& layout);
// Writes it atomically. Throws IoError.
void WriteCaptureLayout(const std::filesystem::path& path, const CaptureLayout& layout);
// MakeStructuredLightSequence(options)'s order as a layout file, photos "pat%03d.png" from 0.
CaptureLayout CaptureLayoutOf(const StructuredLightOptions& options);

// The photo files of `layout` in `folder`, in order. Throws IoError naming the folder or file:
// missing, or a count other than the layout's.
std::vector<std::filesystem::path> LayoutFiles(const CaptureLayout& layout,
                                               const std::filesystem::path& layout_file,
                                               const std::filesystem::path& folder);

// What a decode found, as DecodeSession writes it into result.json.
struct DecodeSummary {
  cv::Size camera_size;
  int projector_width = 0, projector_height = 0;
  long long pixels = 0, decoded = 0;  // camera pixels, and those with every axis decoded
  long long columns_only = 0, rows_only = 0;  // one axis decoded, the other refused
  StructuredLightMap map;                     // the decode itself, with its refusal counts
  double seconds = 0.0;                       // reading and decoding
  std::string BriefReport() const;            // one line
};

// A structured-light session read back: procam's own (its sequence's options) or imported (its
// layout), the photos in layout order, linear digital numbers: 8- or 16-bit as the files hold
// them where they store digital numbers as they are (imported photos, a 16-bit camera's frames),
// CV_32F otherwise (frames scaled to 16 bits, HDR merges).
struct StructuredLightSession {
  StructuredLightLayout layout;
  std::vector<cv::Mat> images;
  std::string display_name;  // the display's name as the session recorded it
};
// Throws IoError naming session.json or a photo: not a structured-light session, a pattern not
// captured, a photo changed since it was recorded, sizes that differ; with `both_axes`, a
// sequence that does not encode both columns and rows (checked before any photo is read).
StructuredLightSession ReadStructuredLightSession(const std::filesystem::path& directory,
                                                  bool both_axes = false);

// Decodes `session`. Throws IoError when its layout and photos do not fit.
DecodeSummary DecodeSession(const StructuredLightSession& session,
                            const StructuredLightDecodeOptions& decode_options = {});
// Writes OUT/decode.png (DecodePicture) and OUT/result.json (the summary's numbers) atomically.
// Throws IoError naming the file.
void WriteDecodeReport(const DecodeSummary& summary, const std::filesystem::path& out);
// Both: what `procam decode` runs.
DecodeSummary DecodeAndReport(const StructuredLightSession& session,
                              const std::filesystem::path& out,
                              const StructuredLightDecodeOptions& decode_options = {});

struct ImportOptions {
  std::filesystem::path layout;  // the layout file
  std::filesystem::path folder;  // the photos; empty: the layout file's folder
  std::filesystem::path out;     // the session directory to write
  std::string name;              // the projector's name; empty: the layout's, else "import"
  ProgressCallback progress;     // the count read, the decode's brief report
  // Declares the layout and the folder (positional), --out and --name in `table`, bound to these
  // fields (base/option_table.h).
  void Declare(OptionTable* table);
  bool Check(std::string* why) const;
};

// Reads the layout and every photo (8- or 16-bit, grey or colour, PNG, JPEG, TIFF or BMP, all one
// size), writes OUT/session.json recording them where they lie (WriteImportedSession), then
// decodes them into OUT/decode/ (DecodeAndReport). Throws IoError naming the layout file and key,
// the folder or the photo; nothing is written unless every photo was read.
DecodeSummary ImportCaptures(const ImportOptions& options);

// `procam decode`: a capture session (procam's own or imported) decoded, its picture and
// numbers written (DecodeAndReport).
struct SessionDecodeOptions {
  std::filesystem::path session;  // the capture session directory
  std::filesystem::path out;      // where decode.png and result.json go; empty: SESSION/decode
  StructuredLightDecodeOptions decode;
  // Declares the session (positional), --out and the decode's thresholds in `table`.
  void Declare(OptionTable* table);
  bool Check(std::string* why) const;
  std::filesystem::path Out() const;  // `out`, or SESSION/decode
};
// Throws std::invalid_argument for options failing Check(), IoError like
// ReadStructuredLightSession and DecodeAndReport.
DecodeSummary DecodeSessionDirectory(const SessionDecodeOptions& options);

// `procam patterns`: procam's structured light written for another program to show.
struct PatternExportOptions {
  StructuredLightOptions patterns;  // the projector's size, the axes, the sinusoids
  std::filesystem::path out;        // pat000.png ... and layout.json
  // Declares --width, --height, --out, --axes, --phase-period, --phase-steps, --no-xor and
  // --pattern-gamma in `table`, bound to these fields.
  void Declare(OptionTable* table);
  bool Check(std::string* why) const;
};

// Writes MakeStructuredLightSequence(options)'s patterns as OUT/pat000.png … (8-bit grey) and
// OUT/layout.json (CaptureLayoutOf), for showing by another program and importing its photos
// back. Returns the number of patterns. Throws IoError naming the file.
int ExportPatterns(const StructuredLightOptions& options, const std::filesystem::path& out);
// The same for `procam patterns`' options; throws std::invalid_argument when Check() fails.
int ExportPatterns(const PatternExportOptions& options);

}  // namespace procam
