#include "calibration/capture_layout.h"

#include <fmt/format.h>

#include <algorithm>
#include <cctype>
#include <cmath>
#include <numbers>
#include <opencv2/core/utility.hpp>
#include <opencv2/imgcodecs.hpp>

#include "base/image_io.h"
#include "base/io.h"
#include "base/json_fields.h"
#include "base/option_table.h"
#include "base/timing.h"
#include "capture/session.h"

namespace procam {
namespace {

namespace fs = std::filesystem;

constexpr const char* kFormat = "procam capture layout";
constexpr int kVersion = 1;

// "a2" < "a10": runs of digits compare as numbers.
bool NaturalLess(const std::string& a, const std::string& b) {
  size_t i = 0, j = 0;
  while (i < a.size() && j < b.size()) {
    if (std::isdigit(static_cast<unsigned char>(a[i])) &&
        std::isdigit(static_cast<unsigned char>(b[j]))) {
      size_t i_end = i, j_end = j;
      while (i_end < a.size() && std::isdigit(static_cast<unsigned char>(a[i_end]))) ++i_end;
      while (j_end < b.size() && std::isdigit(static_cast<unsigned char>(b[j_end]))) ++j_end;
      std::string x = a.substr(i, i_end - i), y = b.substr(j, j_end - j);
      x.erase(0, std::min(x.find_first_not_of('0'), x.size()));
      y.erase(0, std::min(y.find_first_not_of('0'), y.size()));
      if (x.size() != y.size()) return x.size() < y.size();
      if (x != y) return x < y;
      i = i_end;
      j = j_end;
    } else {
      if (a[i] != b[j]) return a[i] < b[j];
      ++i;
      ++j;
    }
  }
  return a.size() - i < b.size() - j;
}

bool IsImageFile(const fs::path& path) {
  std::string extension = path.extension().string();
  std::transform(extension.begin(), extension.end(), extension.begin(),
                 [](unsigned char c) { return std::tolower(c); });
  for (const char* known : {".png", ".jpg", ".jpeg", ".tif", ".tiff", ".bmp"})
    if (extension == known) return true;
  return false;
}

// `pattern` with its one integer conversion (%d, %0Nd) replaced by `index`; empty when the
// pattern holds no such conversion or more than one.
std::string FormatIndex(const std::string& pattern, int index) {
  std::string out;
  int conversions = 0;
  for (size_t i = 0; i < pattern.size(); ++i) {
    if (pattern[i] != '%') {
      out += pattern[i];
      continue;
    }
    if (i + 1 < pattern.size() && pattern[i + 1] == '%') {
      out += '%';
      ++i;
      continue;
    }
    size_t j = i + 1;
    bool zero = j < pattern.size() && pattern[j] == '0';
    if (zero) ++j;
    int width = 0;
    while (j < pattern.size() && std::isdigit(static_cast<unsigned char>(pattern[j])) && width < 100)
      width = 10 * width + (pattern[j++] - '0');
    if (j >= pattern.size() || pattern[j] != 'd') return "";
    std::string number = std::to_string(index);
    if (static_cast<int>(number.size()) < width)
      number.insert(0, width - number.size(), zero ? '0' : ' ');
    out += number;
    ++conversions;
    i = j;
  }
  return conversions == 1 ? out : "";
}

std::string Sequence(size_t block) { return "sequence[" + std::to_string(block) + "]"; }

LayoutBlock ParseBlock(const nlohmann::json& json, const std::string& file, size_t index) {
  const JsonFields fields(json, file, Sequence(index));
  LayoutBlock block;
  block.kind = fields.String("kind");
  if (block.kind == "white" || block.kind == "black") {
    fields.RejectUnknown({"kind"});
  } else if (block.kind == "gray") {
    fields.RejectUnknown({"kind", "code", "axes", "cell", "finest_bit", "inverse"});
    if (fields.Has("code")) block.code = fields.String("code");
    if (block.code != "gray" && block.code != "opencv" && block.code != "xor")
      throw fields.Error("code", "'" + block.code + "': gray, opencv or xor");
    if (fields.Has("axes")) block.axes = fields.String("axes");
    if (block.axes != "columns" && block.axes != "rows" && block.axes != "both")
      throw fields.Error("axes", "'" + block.axes + "': columns, rows or both");
    const auto integer = [&](const std::string& key, int low, int high) {
      const double value = fields.Number(key);
      if (value != std::floor(value) || value < low || value > high)
        throw fields.Error(key, "must be an integer in [" + std::to_string(low) + ", " +
                                    std::to_string(high) + "]");
      return static_cast<int>(value);
    };
    if (fields.Has("cell")) block.cell = integer("cell", 1, 16384);
    if (fields.Has("finest_bit")) block.finest_bit = integer("finest_bit", 0, 30);
    if (fields.Has("inverse")) {
      if (!fields.At("inverse").is_boolean()) throw fields.Error("inverse", "must be true or false");
      block.inverse = fields.At("inverse").get<bool>();
    }
    if (block.code == "opencv" && (!block.inverse || block.finest_bit != 0))
      throw fields.Error("code", "opencv's Gray code shows every bit, each with its inverse");
  } else if (block.kind == "phase") {
    fields.RejectUnknown({"kind", "axis", "period", "shifts_deg", "origin", "direction", "function"});
    block.axis = fields.String("axis");
    if (block.axis != "columns" && block.axis != "rows")
      throw fields.Error("axis", "'" + block.axis + "': columns or rows");
    block.period = fields.Number("period");
    if (!(block.period > 1.0 && block.period <= 65536.0))
      throw fields.Error("period", "must be in (1, 65536] projector pixels");
    block.shifts_deg = fields.Numbers("shifts_deg", fields.At("shifts_deg"));
    if (block.shifts_deg.size() < 3)
      throw fields.Error("shifts_deg", "needs at least three shifts (one per photo)");
    if (fields.Has("origin")) block.origin = fields.Number("origin");
    if (fields.Has("direction")) {
      const double direction = fields.Number("direction");
      if (direction != 1.0 && direction != -1.0) throw fields.Error("direction", "must be 1 or -1");
      block.direction = static_cast<int>(direction);
    }
    if (fields.Has("function")) block.function = fields.String("function");
    if (block.function != "cos" && block.function != "sin")
      throw fields.Error("function", "'" + block.function + "': cos or sin");
  } else {
    throw fields.Error("kind", "'" + block.kind + "': white, black, gray or phase");
  }
  return block;
}

nlohmann::json BlockJson(const LayoutBlock& block) {
  nlohmann::json json = {{"kind", block.kind}};
  if (block.kind == "gray") {
    json["code"] = block.code;
    json["axes"] = block.axes;
    json["cell"] = block.cell;
    json["finest_bit"] = block.finest_bit;
    json["inverse"] = block.inverse;
  } else if (block.kind == "phase") {
    json["axis"] = block.axis;
    json["period"] = block.period;
    json["shifts_deg"] = block.shifts_deg;
    json["origin"] = block.origin;
    json["direction"] = block.direction;
    json["function"] = block.function;
  }
  return json;
}

}  // namespace

StructuredLightLayout CaptureLayout::Decodable(const std::string& file) const {
  StructuredLightLayout layout;
  layout.width = width;
  layout.height = height;
  int index = 0;
  for (size_t b = 0; b < blocks.size(); ++b) {
    const LayoutBlock& block = blocks[b];
    const auto error = [&](const std::string& key, const std::string& what) {
      return IoError(file + ": " + Sequence(b) + (key.empty() ? "" : "." + key) + ": " + what);
    };
    if (block.kind == "white" || block.kind == "black") {
      int& slot = block.kind == "white" ? layout.white : layout.black;
      if (slot >= 0) throw error("kind", "a second " + block.kind + " image");
      slot = index++;
    } else if (block.kind == "gray") {
      for (bool column : {true, false}) {
        if ((column && block.axes == "rows") || (!column && block.axes == "columns")) continue;
        const int size = column ? width : height;
        StructuredLightLayout::Gray gray;
        gray.column = column;
        gray.cell = block.cell;
        gray.bits = GrayCodeBits((size + block.cell - 1) / block.cell);
        gray.finest_bit = block.finest_bit;
        gray.xor_codes = block.code == "xor";
        if (gray.bits < 1) throw error("cell", "one cell covers the whole projector side");
        if (gray.finest_bit >= gray.bits)
          throw error("finest_bit", "the code has only " + std::to_string(gray.bits) + " bits");
        for (int bit = gray.bits - 1; bit >= gray.finest_bit; --bit) {
          gray.images.push_back(index++);
          gray.inverse.push_back(block.inverse ? index++ : -1);
        }
        for (const auto& other : layout.gray)
          if (other.column == column) throw error("axes", "a second Gray code of the same axis");
        layout.gray.push_back(std::move(gray));
      }
    } else {
      StructuredLightLayout::Phase phase;
      phase.column = block.axis == "columns";
      phase.period = block.period;
      phase.origin = block.origin;
      phase.direction = block.direction;
      // sin(x) = cos(x − 90°).
      const double offset = block.function == "sin" ? -0.5 * std::numbers::pi : 0.0;
      for (double shift : block.shifts_deg) {
        phase.shifts.push_back(shift * std::numbers::pi / 180.0 + offset);
        phase.images.push_back(index++);
      }
      layout.phases.push_back(std::move(phase));
    }
  }
  layout.image_count = index;
  std::string why;
  if (!layout.Check(&why)) throw IoError(file + ": sequence: " + why);
  return layout;
}

CaptureLayout ParseCaptureLayout(const nlohmann::json& json, const std::string& file) {
  const JsonFields fields(json, file, "");
  fields.RejectUnknown({"format", "version", "projector", "files", "sequence"});
  if (fields.String("format") != kFormat)
    throw fields.Error("format", std::string("must be \"") + kFormat + "\"");
  if (fields.Number("version") != kVersion)
    throw fields.Error("version", "version " + fields.At("version").dump() + " is not 1");
  CaptureLayout layout;
  const JsonFields projector(fields.At("projector"), file, "projector");
  projector.RejectUnknown({"width", "height", "name"});
  const auto side = [&](const std::string& key) {
    const double value = projector.Number(key);
    if (value != std::floor(value) || value < 2 || value > 16384)
      throw projector.Error(key, "must be an integer in [2, 16384]");
    return static_cast<int>(value);
  };
  layout.width = side("width");
  layout.height = side("height");
  if (projector.Has("name")) layout.projector_name = projector.String("name");
  if (fields.Has("files")) {
    const nlohmann::json& files = fields.At("files");
    if (files.is_array()) {
      for (size_t i = 0; i < files.size(); ++i) {
        if (!files[i].is_string() || files[i].get<std::string>().empty())
          throw fields.Error("files[" + std::to_string(i) + "]", "must be a file name");
        layout.files.push_back(files[i].get<std::string>());
      }
    } else if (files.is_object()) {
      const JsonFields pattern(files, file, "files");
      pattern.RejectUnknown({"pattern", "first"});
      layout.file_pattern = pattern.String("pattern");
      if (FormatIndex(layout.file_pattern, 0).empty())
        throw pattern.Error("pattern", "'" + layout.file_pattern +
                                           "' must hold one integer conversion, %d or %0Nd");
      if (pattern.Has("first")) {
        const double first = pattern.Number("first");
        if (first != std::floor(first) || first < 0 || first > 1e6)
          throw pattern.Error("first", "must be an integer in [0, 1000000]");
        layout.first = static_cast<int>(first);
      }
    } else {
      throw fields.Error("files", "must be a list of file names or {\"pattern\": ..., \"first\": ...}");
    }
  }
  const nlohmann::json& sequence = fields.At("sequence");
  if (!sequence.is_array() || sequence.empty())
    throw fields.Error("sequence", "must be a non-empty list of blocks");
  for (size_t b = 0; b < sequence.size(); ++b) layout.blocks.push_back(ParseBlock(sequence[b], file, b));
  layout.Decodable(file);  // every consistency check, with the key named
  return layout;
}

CaptureLayout ReadCaptureLayout(const fs::path& path) {
  return ParseCaptureLayout(ReadJsonFile(path), path.string());
}

nlohmann::json CaptureLayoutJson(const CaptureLayout& layout) {
  nlohmann::json projector = {{"width", layout.width}, {"height", layout.height}};
  if (!layout.projector_name.empty()) projector["name"] = layout.projector_name;
  nlohmann::json json = {{"format", kFormat}, {"version", kVersion}, {"projector", projector}};
  if (!layout.files.empty()) json["files"] = layout.files;
  if (!layout.file_pattern.empty())
    json["files"] = {{"pattern", layout.file_pattern}, {"first", layout.first}};
  nlohmann::json sequence = nlohmann::json::array();
  for (const LayoutBlock& block : layout.blocks) sequence.push_back(BlockJson(block));
  json["sequence"] = sequence;
  return json;
}

void WriteCaptureLayout(const fs::path& path, const CaptureLayout& layout) {
  WriteFileAtomically(path, CaptureLayoutJson(layout).dump(2) + "\n");
}

CaptureLayout CaptureLayoutOf(const StructuredLightOptions& options) {
  std::string why;
  if (!options.Check(&why)) throw std::invalid_argument("structured light: " + why);
  CaptureLayout layout;
  layout.width = options.width;
  layout.height = options.height;
  layout.file_pattern = "pat%03d.png";
  const auto block = [](const char* kind) {
    LayoutBlock made;
    made.kind = kind;
    return made;
  };
  layout.blocks.push_back(block("white"));
  layout.blocks.push_back(block("black"));
  for (bool column : {true, false}) {
    if (column ? !options.columns : !options.rows) continue;
    LayoutBlock gray = block("gray");
    gray.code = options.xor_codes ? "xor" : "gray";
    gray.axes = column ? "columns" : "rows";
    gray.finest_bit = StructuredLightFinestBit(options);
    layout.blocks.push_back(gray);
    if (options.phase_period == 0) continue;
    LayoutBlock phase = block("phase");
    phase.axis = column ? "columns" : "rows";
    phase.period = options.phase_period;
    for (int step = 0; step < options.phase_steps; ++step)
      phase.shifts_deg.push_back(-360.0 * step / options.phase_steps);
    layout.blocks.push_back(phase);
  }
  return layout;
}

std::vector<fs::path> LayoutFiles(const CaptureLayout& layout, const fs::path& layout_file,
                                  const fs::path& folder) {
  const int count = layout.Decodable(layout_file.string()).image_count;
  std::vector<fs::path> files;
  if (!layout.files.empty()) {
    for (const std::string& name : layout.files) files.push_back(folder / name);
  } else if (!layout.file_pattern.empty()) {
    for (int i = 0; i < count; ++i)
      files.push_back(folder / FormatIndex(layout.file_pattern, layout.first + i));
  } else {
    std::error_code error;
    if (!fs::is_directory(folder, error))
      throw IoError(folder.string() + ": not a directory of photos");
    std::vector<std::string> names;
    for (const auto& entry : fs::directory_iterator(folder, error)) {
      if (IsImageFile(entry.path())) names.push_back(entry.path().filename().string());
    }
    if (error) throw IoError(folder.string() + ": cannot list: " + error.message());
    std::sort(names.begin(), names.end(), NaturalLess);
    for (const std::string& name : names) files.push_back(folder / name);
  }
  if (static_cast<int>(files.size()) != count) {
    throw IoError(layout_file.string() + ": sequence: needs " + std::to_string(count) +
                  " photos, " + (layout.files.empty() && layout.file_pattern.empty()
                                     ? folder.string() + " holds "
                                     : "files lists ") +
                  std::to_string(files.size()));
  }
  return files;
}

std::string DecodeSummary::BriefReport() const {
  const double total = std::max<long long>(1, pixels);
  return fmt::format(
      "{}x{} camera pixels, {}x{} projector: {} decoded ({:.1f}%), {} more on columns only, {} on "
      "rows only; refused: {} shadowed, {} ambiguous bit, {} weak phase, {} out of range, {} not "
      "unwrapped; phase within its Gray cell at {:.2f}% of {} axis decodes; noise {:.3g} DN; "
      "{:.2f} s",
      camera_size.width, camera_size.height, projector_width, projector_height, decoded,
      100.0 * decoded / total, columns_only, rows_only, map.shadowed, map.ambiguous,
      map.weak_phase, map.out_of_range, map.unwrap,
      100.0 * map.gray_phase_agree /
          std::max<long long>(1, map.gray_phase_agree + map.gray_phase_disagree),
      map.gray_phase_agree + map.gray_phase_disagree, map.noise_sigma, seconds);
}

StructuredLightSession ReadStructuredLightSession(const fs::path& directory, bool both_axes) {
  if (!fs::is_directory(directory)) throw IoError(directory.string() + ": not a directory");
  const CaptureSessionData data = CaptureSessionData::Load(directory);
  const std::string manifest = (directory / "session.json").string();
  const nlohmann::json& sequence = data.manifest().value("sequence", nlohmann::json::object());
  const std::string kind = sequence.value("kind", "");
  if (kind != "structured_light")
    throw IoError(manifest + ": a '" + kind +
                  "' session; this needs structured light (procam capture --sequence "
                  "structured_light, or procam import)");
  const nlohmann::json parameters = sequence.value("parameters", nlohmann::json::object());
  StructuredLightSession session;
  if (parameters.contains("layout")) {
    session.layout =
        ParseCaptureLayout(parameters["layout"], manifest + ": sequence.parameters.layout")
            .Decodable(manifest + ": sequence.parameters.layout");
  } else {
    StructuredLightOptions options;
    try {
      options.width = parameters.at("width").get<int>();
      options.height = parameters.at("height").get<int>();
      options.columns = parameters.at("columns").get<bool>();
      options.rows = parameters.at("rows").get<bool>();
      options.phase_period = parameters.at("phase_period").get<int>();
      options.phase_steps = parameters.at("phase_steps").get<int>();
      options.xor_codes = parameters.at("xor_codes").get<bool>();
      options.pattern_gamma = parameters.at("pattern_gamma").get<double>();
    } catch (const nlohmann::json::exception& error) {
      throw IoError(manifest + ": sequence.parameters: " + error.what());
    }
    std::string why;
    if (!options.Check(&why)) throw IoError(manifest + ": sequence.parameters: " + why);
    session.layout = LayoutOf(options);
  }
  if (both_axes && (!session.layout.Encodes(true) || !session.layout.Encodes(false)))
    throw IoError(manifest + ": sequence.parameters: both columns and rows must be encoded");
  if (data.pattern_count() != session.layout.image_count)
    throw IoError(manifest + ": " + std::to_string(data.pattern_count()) +
                  " patterns for a sequence of " + std::to_string(session.layout.image_count));
  session.images.resize(data.pattern_count());
  for (int p = 0; p < data.pattern_count(); ++p) {
    if (!data.captured(p))
      throw IoError(manifest + ": pattern " + data.pattern_name(p) +
                    " is not captured (run the same capture command again to resume)");
  }
  // Reading (checksums, PNG decoding) is most of the time: one photo per thread.
  std::vector<std::string> errors(session.images.size());
  cv::parallel_for_(cv::Range(0, data.pattern_count()), [&](const cv::Range& range) {
    for (int p = range.start; p < range.end; ++p) {
      try {
        cv::Mat image = data.Hdr(p);
        if (image.empty()) {
          // Frames that store digital numbers as they are (a 16-bit camera's, imported photos)
          // go to the decoder as read: converting 42 megapixel photos to floats cost a third of
          // `calibrate board`'s time (docs/chessboard.md).
          double scale = 1.0;
          image = data.Stored(p, 0, &scale);
          if (scale != 1.0) image.convertTo(image, CV_32F, 1.0 / scale);
        }
        session.images[p] = image;
      } catch (const std::exception& error) {
        errors[p] = error.what();
      }
    }
  });
  for (const std::string& error : errors)
    if (!error.empty()) throw IoError(error);
  for (int p = 1; p < data.pattern_count(); ++p) {
    if (session.images[p].size() != session.images[0].size())
      throw IoError(manifest + ": pattern " + data.pattern_name(p) + " is " +
                    std::to_string(session.images[p].cols) + "x" +
                    std::to_string(session.images[p].rows) + ", pattern " +
                    data.pattern_name(0) + " " + std::to_string(session.images[0].cols) + "x" +
                    std::to_string(session.images[0].rows));
  }
  session.display_name = data.manifest().value("display", nlohmann::json::object()).value("name", "");
  return session;
}

DecodeSummary DecodeSession(const StructuredLightSession& session,
                            const StructuredLightDecodeOptions& decode_options) {
  const auto start = Clock::now();
  DecodeSummary summary;
  try {
    summary.map = DecodeStructuredLight(session.layout, session.images, decode_options);
  } catch (const std::invalid_argument& error) {
    throw IoError(error.what());
  }
  summary.seconds = SecondsSince(start);
  const StructuredLightMap& map = summary.map;
  summary.camera_size = map.column.size();
  summary.projector_width = session.layout.width;
  summary.projector_height = session.layout.height;
  summary.pixels = map.column.total();
  summary.decoded = cv::countNonZero(map.mask);
  const cv::Mat has_column = map.column == map.column, has_row = map.row == map.row;
  summary.columns_only = cv::countNonZero(has_column & ~has_row & ~map.mask);
  summary.rows_only = cv::countNonZero(has_row & ~has_column & ~map.mask);
  return summary;
}

void WriteDecodeReport(const DecodeSummary& summary, const fs::path& out) {
  const StructuredLightMap& map = summary.map;
  std::error_code error;
  fs::create_directories(out, error);
  if (error) throw IoError(out.string() + ": cannot create directory: " + error.message());
  WritePng(out / "decode.png", DecodePicture(map, summary.projector_width, summary.projector_height));
  const nlohmann::json result = {
      {"camera", {{"width", summary.camera_size.width}, {"height", summary.camera_size.height}}},
      {"projector", {{"width", summary.projector_width}, {"height", summary.projector_height}}},
      {"pixels", summary.pixels},
      {"decoded", summary.decoded},
      {"columns_only", summary.columns_only},
      {"rows_only", summary.rows_only},
      {"refused",
       {{"shadowed", map.shadowed},
        {"ambiguous", map.ambiguous},
        {"weak_phase", map.weak_phase},
        {"out_of_range", map.out_of_range},
        {"unwrap", map.unwrap}}},
      {"gray_phase", {{"agree", map.gray_phase_agree}, {"disagree", map.gray_phase_disagree}}},
      {"noise_sigma", map.noise_sigma},
      {"seconds", summary.seconds},
      {"picture", "decode.png"}};
  WriteFileAtomically(out / "result.json", result.dump(2) + "\n");
}

DecodeSummary DecodeAndReport(const StructuredLightSession& session, const fs::path& out,
                              const StructuredLightDecodeOptions& decode_options) {
  DecodeSummary summary = DecodeSession(session, decode_options);
  WriteDecodeReport(summary, out);
  return summary;
}

void ImportOptions::Declare(OptionTable* table) {
  table->Path("layout", &layout, "layout file (docs/capture_layout.md)").Positional().Required();
  table->Path("folder", &folder, "folder of the photos (default: the layout's)").Positional();
  table->Path("out", &out, "session directory to write").Required();
  table->Text("name", &name, "the projector's name (default: the layout's, else 'import')");
}

bool ImportOptions::Check(std::string* why) const {
  if (layout.empty() || out.empty()) {
    if (why) *why = "a layout file and an output session directory are needed";
    return false;
  }
  return true;
}

DecodeSummary ImportCaptures(const ImportOptions& options) {
  std::string why;
  if (!options.Check(&why)) throw std::invalid_argument(why);
  const auto start = Clock::now();
  const CaptureLayout layout = ReadCaptureLayout(options.layout);
  const fs::path folder = options.folder.empty() ? options.layout.parent_path() : options.folder;
  const std::vector<fs::path> files = LayoutFiles(layout, options.layout, folder);
  const StructuredLightLayout decodable = layout.Decodable(options.layout.string());
  // Every photo read once: its checksum recorded, its pixels decoded.
  std::vector<ImportedPhoto> photos(files.size());
  StructuredLightSession session;
  session.layout = decodable;
  session.images.resize(files.size());
  std::vector<std::string> errors(files.size());
  cv::parallel_for_(cv::Range(0, static_cast<int>(files.size())), [&](const cv::Range& range) {
    for (int i = range.start; i < range.end; ++i) {
      try {
        const fs::path file = fs::absolute(files[i]).lexically_normal();
        const std::string bytes = ReadFile(file, kMaxImageBytes);
        const cv::Mat image = DecodeImage(file, bytes, cv::IMREAD_UNCHANGED);
        if (image.depth() != CV_8U && image.depth() != CV_16U)
          throw IoError(file.string() + ": not an 8- or 16-bit image");
        if (image.channels() != 1 && image.channels() != 3)
          throw IoError(file.string() + ": neither grey nor colour (" +
                        std::to_string(image.channels()) + " channels)");
        photos[i].name = file.stem().string();
        photos[i].file = file;
        photos[i].checksum = ContentChecksum(bytes);
        photos[i].full_scale = image.depth() == CV_8U ? 255.0 : 65535.0;
        session.images[i] = image;  // the decoder reads 8- and 16-bit photos as they are
      } catch (const std::exception& error) {
        errors[i] = error.what();
      }
    }
  });
  for (const std::string& error : errors)
    if (!error.empty()) throw IoError(error);
  for (size_t i = 1; i < files.size(); ++i) {
    if (session.images[i].size() != session.images[0].size())
      throw IoError(files[i].string() + ": " + std::to_string(session.images[i].cols) + "x" +
                    std::to_string(session.images[i].rows) + ", " + files[0].string() + " " +
                    std::to_string(session.images[0].cols) + "x" +
                    std::to_string(session.images[0].rows));
  }
  // What each photo shows, as procam's own patterns record it.
  photos[decodable.white].info = {{"kind", "white"}};
  photos[decodable.black].info = {{"kind", "black"}};
  for (const auto& gray : decodable.gray) {
    for (size_t b = 0; b < gray.images.size(); ++b) {
      for (int image : {gray.images[b], gray.inverse[b]}) {
        if (image < 0) continue;
        photos[image].info = {{"kind", "graycode"},
                              {"axis", gray.column ? "column" : "row"},
                              {"bit", gray.bits - 1 - static_cast<int>(b)},
                              {"inverse", image == gray.inverse[b]},
                              {"xor", gray.xor_codes}};
      }
    }
  }
  for (const auto& phase : decodable.phases) {
    for (size_t k = 0; k < phase.images.size(); ++k) {
      photos[phase.images[k]].info = {{"kind", "phase"},
                                      {"axis", phase.column ? "column" : "row"},
                                      {"period", phase.period},
                                      {"shift_rad", phase.shifts[k]}};
    }
  }
  std::vector<std::string> names;
  for (ImportedPhoto& photo : photos) {
    if (std::find(names.begin(), names.end(), photo.name) != names.end())
      photo.name += "_" + std::to_string(names.size());
    names.push_back(photo.name);
  }
  const std::string name = !options.name.empty()            ? options.name
                           : !layout.projector_name.empty() ? layout.projector_name
                                                            : "import";
  Report(options.progress, fmt::format("{}: {} photos of {}x{} read from {}", options.layout.string(),
                                       files.size(), session.images[0].cols,
                                       session.images[0].rows, folder.string()));
  WriteImportedSession(options.out, "structured_light", {{"layout", CaptureLayoutJson(layout)}},
                       "import:" + name, cv::Size(layout.width, layout.height), photos);
  DecodeSummary summary = DecodeAndReport(session, options.out / "decode");
  summary.seconds = SecondsSince(start);
  Report(options.progress, "decoded: " + summary.BriefReport());
  return summary;
}

int ExportPatterns(const StructuredLightOptions& options, const fs::path& out) {
  const CaptureSequence sequence = MakeStructuredLightSequence(options);
  const CaptureLayout layout = CaptureLayoutOf(options);
  std::error_code error;
  fs::create_directories(out, error);
  if (error) throw IoError(out.string() + ": cannot create directory: " + error.message());
  for (size_t i = 0; i < sequence.patterns.size(); ++i) {
    cv::Mat grey;
    cv::extractChannel(sequence.patterns[i].image, grey, 0);
    WritePng(out / FormatIndex(layout.file_pattern, layout.first + static_cast<int>(i)), grey);
  }
  WriteCaptureLayout(out / "layout.json", layout);
  return static_cast<int>(sequence.patterns.size());
}

void SessionDecodeOptions::Declare(OptionTable* table) {
  table->Path("session", &session, "capture session (procam's own or imported)")
      .Positional()
      .Required();
  table->Path("out", &out, "output directory (default: SESSION/decode)");
  decode.Declare(table);
}

bool SessionDecodeOptions::Check(std::string* why) const {
  return CheckDeclared(*this, why) && decode.Check(why);
}

fs::path SessionDecodeOptions::Out() const { return out.empty() ? session / "decode" : out; }

DecodeSummary DecodeSessionDirectory(const SessionDecodeOptions& options) {
  std::string why;
  if (!options.Check(&why)) throw std::invalid_argument(why);
  return DecodeAndReport(ReadStructuredLightSession(options.session), options.Out(),
                         options.decode);
}

void PatternExportOptions::Declare(OptionTable* table) {
  StructuredLightOptions* p = &patterns;
  table->Integer("width", &p->width, 4, 16384, "pixels", "projector width").Required();
  table->Integer("height", &p->height, 4, 16384, "pixels", "projector height").Required();
  table->Path("out", &out, "directory for pat000.png ... and layout.json").Required();
  table
      ->Custom(
          "axes",
          [p] {
            return std::string(p->columns && p->rows ? "both" : p->rows ? "rows" : "columns");
          },
          [p](const std::string& text, std::string* why) {
            if (text != "both" && text != "columns" && text != "rows") {
              *why = "expected both, columns or rows; got '" + text + "'";
              return false;
            }
            p->columns = text != "rows";
            p->rows = text != "columns";
            return true;
          },
          "columns | rows | both", "the axes encoded")
      .Sets(&p->columns)
      .Sets(&p->rows);
  table
      ->Integer("phase-period", &p->phase_period, 0, 1024, "pixels",
                "period of the sinusoids (power of two; 0: none)")
      .Integer("phase-steps", &p->phase_steps, 3, 64, "", "sinusoids per axis")
      .NegatedFlag("no-xor", &p->xor_codes, "plain Gray code instead of XOR codes")
      .Number("pattern-gamma", &p->pattern_gamma, OptionTable::Interval::AboveMin(0.0, 10.0), "",
              "the projector's gamma: sinusoids encoded to be sinusoids in light");
}

bool PatternExportOptions::Check(std::string* why) const {
  return CheckDeclared(*this, why) && patterns.Check(why);
}

int ExportPatterns(const PatternExportOptions& options) {
  std::string why;
  if (!options.Check(&why)) throw std::invalid_argument(why);
  return ExportPatterns(options.patterns, options.out);
}

}  // namespace procam
