// procam import LAYOUT.json [FOLDER] --out SESSION: photos of structured light made by another
// tool, as a capture session (calibration/capture_layout.h; docs/capture_layout.md).
// procam decode SESSION [--out DIR]: a structured-light session decoded, with its picture.
// procam patterns --width W --height H --out DIR: procam's own sequence as numbered PNGs and a
// layout file, for a projector driven by another program. Each command's options as its
// Options struct declares them.
#include <cstdio>
#include <filesystem>
#include <memory>

#include "apps/command_line.h"
#include "apps/commands.h"
#include "base/output_directory.h"
#include "calibration/capture_layout.h"

namespace procam {

void AddStructuredLightCommands(CLI::App& app) {
  CLI::App* import_cmd = app.add_subcommand(
      "import", "Photos of structured light made by another tool, as a capture session");
  const auto import_options = AddDeclaredOptions<ImportOptions>(import_cmd);
  import_cmd->callback([import_options] {
    import_options->progress = PrintProgress();
    CheckOutputDirectory(import_options->out, DirectoryKind::kCaptureSession);
    ImportCaptures(*import_options);
    std::printf("wrote %s/session.json and %s/decode/\n", import_options->out.c_str(),
                import_options->out.c_str());
  });

  CLI::App* decode =
      app.add_subcommand("decode", "Decode a structured-light session: decode.png and result.json");
  const auto decode_options = AddDeclaredOptions<SessionDecodeOptions>(decode);
  decode->callback([decode_options] {
    const DecodeSummary summary = DecodeSessionDirectory(*decode_options);
    const std::filesystem::path out = decode_options->Out();
    std::printf("%s\nwrote %s and %s\n", summary.BriefReport().c_str(),
                (out / "decode.png").c_str(), (out / "result.json").c_str());
  });

  CLI::App* patterns = app.add_subcommand(
      "patterns",
      "procam's structured light as numbered PNGs with a layout file, for another program to "
      "show (import its photos back with procam import)");
  const auto pattern_options = AddDeclaredOptions<PatternExportOptions>(patterns);
  patterns->callback([pattern_options] {
    const int count = ExportPatterns(*pattern_options);
    std::printf("wrote %d patterns and %s\n", count,
                (pattern_options->out / "layout.json").c_str());
  });
}

}  // namespace procam
