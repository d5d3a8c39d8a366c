// procam import LAYOUT.json [FOLDER] --out SESSION: photos of structured light made by another
// tool, as a capture session (calibration/capture_layout.h; docs/capture_layout.md).
// procam decode SESSION [--out DIR]: a structured-light session decoded, with its picture.
// procam patterns --width W --height H --out DIR: procam's own sequence as numbered PNGs and a
// layout file, for a projector driven by another program.
#include <cstdio>
#include <filesystem>
#include <memory>

#include "apps/commands.h"
#include "base/output_directory.h"
#include "calibration/capture_layout.h"

namespace procam {
namespace {

void PrintLine(const std::string& line) { std::printf("%s\n", line.c_str()); }

void AddDecodeOptions(CLI::App* command, StructuredLightDecodeOptions* options) {
  command->add_option("--min-contrast", options->min_contrast,
                      "Shadow test: white - black at least this fraction of its 99th percentile")
      ->capture_default_str();
  command->add_option("--min-bit-contrast", options->min_bit_contrast,
                      "A bit: |pattern - inverse| at least this fraction of white - black")
      ->capture_default_str();
  command->add_option("--min-modulation", options->min_modulation,
                      "A phase: amplitude at least this fraction of (white - black)/2")
      ->capture_default_str();
  command->add_option("--noise-sigmas", options->noise_sigmas,
                      "Every difference at least this many standard deviations of the photos' "
                      "noise (estimated from them)")
      ->capture_default_str();
  command
      ->add_option("--faint-bits", options->faint_bits,
                   "Gray bits per axis that may fail the bit test: tried at both values, the "
                   "pixel decoded where the phase unwraps the same either way (defocus), [0, 4]")
      ->capture_default_str();
}

void CheckDecodeOptions(const StructuredLightDecodeOptions& options) {
  std::string why;
  if (!options.Check(&why)) throw std::invalid_argument(why);
}

}  // namespace

void AddStructuredLightCommands(CLI::App& app) {
  {
    struct Arguments {
      ImportOptions options;
      std::string layout, folder, out;
    };
    auto args = std::make_shared<Arguments>();
    CLI::App* command = app.add_subcommand(
        "import", "Photos of structured light made by another tool, as a capture session");
    command->add_option("layout", args->layout, "Layout file (docs/capture_layout.md)")->required();
    command->add_option("folder", args->folder, "Folder of the photos (default: the layout's)");
    command->add_option("--out", args->out, "Session directory to write")->required();
    command->add_option("--name", args->options.name,
                        "The projector's name (default: the layout's, else 'import')");
    command->callback([args] {
      args->options.layout = args->layout;
      args->options.folder = args->folder;
      args->options.out = args->out;
      args->options.progress = PrintLine;
      CheckOutputDirectory(args->options.out, DirectoryKind::kCaptureSession);
      ImportCaptures(args->options);
      std::printf("wrote %s/session.json and %s/decode/\n", args->out.c_str(), args->out.c_str());
    });
  }
  {
    struct Arguments {
      std::string session, out;
      StructuredLightDecodeOptions decode;
    };
    auto args = std::make_shared<Arguments>();
    CLI::App* command = app.add_subcommand(
        "decode", "Decode a structured-light session: decode.png and result.json");
    command->add_option("session", args->session, "Capture session (procam's own or imported)")
        ->required();
    command->add_option("--out", args->out, "Output directory (default: SESSION/decode)");
    AddDecodeOptions(command, &args->decode);
    command->callback([args] {
      CheckDecodeOptions(args->decode);
      const std::filesystem::path out =
          args->out.empty() ? std::filesystem::path(args->session) / "decode"
                            : std::filesystem::path(args->out);
      const DecodeSummary summary =
          DecodeAndReport(ReadStructuredLightSession(args->session), out, args->decode);
      PrintLine(summary.BriefReport());
      std::printf("wrote %s and %s\n", (out / "decode.png").c_str(), (out / "result.json").c_str());
    });
  }
  {
    struct Arguments {
      StructuredLightOptions options;
      std::string axes = "both", out;
      bool no_xor = false;
    };
    auto args = std::make_shared<Arguments>();
    CLI::App* command = app.add_subcommand(
        "patterns",
        "procam's structured light as numbered PNGs with a layout file, for another program to "
        "show (import its photos back with procam import)");
    command->add_option("--width", args->options.width, "Projector width, pixels")->required();
    command->add_option("--height", args->options.height, "Projector height, pixels")->required();
    command->add_option("--out", args->out, "Directory for pat000.png ... and layout.json")
        ->required();
    command->add_option("--axes", args->axes, "columns, rows or both")
        ->check(CLI::IsMember({"columns", "rows", "both"}))
        ->capture_default_str();
    command->add_option("--phase-period", args->options.phase_period,
                        "Period of the sinusoids, projector pixels (power of two; 0: none)")
        ->capture_default_str();
    command->add_option("--phase-steps", args->options.phase_steps, "Sinusoids per axis")
        ->capture_default_str();
    command->add_flag("--no-xor", args->no_xor, "Plain Gray code instead of XOR codes");
    command->add_option("--pattern-gamma", args->options.pattern_gamma,
                        "The projector's gamma: sinusoids encoded to be sinusoids in light")
        ->capture_default_str();
    command->callback([args] {
      StructuredLightOptions options = args->options;
      options.columns = args->axes != "rows";
      options.rows = args->axes != "columns";
      options.xor_codes = !args->no_xor;
      std::string why;
      if (!options.Check(&why)) throw std::invalid_argument(why);
      const int count = ExportPatterns(options, args->out);
      std::printf("wrote %d patterns and %s\n", count,
                  (std::filesystem::path(args->out) / "layout.json").c_str());
    });
  }
}

}  // namespace procam
