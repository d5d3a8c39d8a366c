#include "apps/command_line.h"

#include <spdlog/fmt/fmt.h>
#include <spdlog/spdlog.h>

#include <CLI/CLI.hpp>
#include <cmath>
#include <cstdio>
#include <limits>
#include <map>
#include <optional>
#include <sstream>

#include "base/io.h"
#include "base/output_directory.h"
#include "procam/config.h"
#if PROCAM_WITH_GLFW
#include "projection/glfw_display.h"
#endif

namespace procam {

namespace {

CLI::Validator FiniteValidator(double min, double max, bool open_min, const std::string& range) {
  return CLI::Validator(
      [=](std::string& text) -> std::string {
        double value = 0.0;
        if (!CLI::detail::lexical_cast(text, value)) return "'" + text + "' is not a number";
        if (!std::isfinite(value) || value < min || value > max || (open_min && value == min)) {
          return "'" + text + "' is not a number in " + range;
        }
        return std::string();
      },
      range);
}

}  // namespace

void AddOptions(CLI::App* command, const OptionTable& table) {
  for (const OptionTable::Option& option : table.options()) {
    const std::string flag = option.positional ? option.name : "--" + option.name;
    std::string help = option.help;
    if (!option.unit.empty()) help += " (" + option.unit + ")";
    const auto set = option.set;
    if (option.kind == OptionTable::Kind::kFlag) {
      // --NAME sets it, --NAME=false clears it (CLI11 counts a false as -1).
      command->add_flag_function(
          flag,
          [set](std::int64_t count) {
            std::string why;
            set(count > 0 ? "true" : "false", &why);
          },
          help);
      continue;
    }
    CLI::Option* added = nullptr;
    if (option.kind == OptionTable::Kind::kList) {
      // Every occurrence's items together; one value split at commas unless one item per flag.
      const auto set_items = option.set_items;
      added = command->add_option_function<std::vector<std::string>>(
          flag,
          [set_items, flag](const std::vector<std::string>& items) {
            std::string why;
            if (!set_items(items, &why)) throw CLI::ValidationError(flag, why);
          },
          help);
      if (!option.repeated && !option.positional) added->delimiter(',');
      added->type_name(option.values);
    } else {
      added = command->add_option_function<std::string>(
          flag,
          [set, flag](const std::string& text) {
            std::string why;
            if (!set(text, &why)) throw CLI::ValidationError(flag, why);
          },
          help);
    }
    if (option.required) added->required();
    if (!option.default_text.empty()) added->default_str(option.default_text);
    switch (option.kind) {
      case OptionTable::Kind::kInteger:
        added->type_name("INT in " + option.range->Text());
        break;
      case OptionTable::Kind::kNumber:
        added->type_name("FLOAT in " + option.range->Text());
        break;
      case OptionTable::Kind::kChoice: {
        std::string choices;
        for (const std::string& choice : option.choices)
          choices += (choices.empty() ? "" : "|") + choice;
        added->type_name("{" + choices + "}");
        break;
      }
      case OptionTable::Kind::kPath:
        added->type_name("PATH");
        break;
      case OptionTable::Kind::kCustom:
        added->type_name(option.values);
        break;
      case OptionTable::Kind::kList:
        break;
      default:
        added->type_name("TEXT");
        break;
    }
  }
}

CLI::Validator FiniteRange(double min, double max) {
  return FiniteValidator(min, max, false, fmt::format("[{}, {}]", min, max));
}

CLI::Validator FiniteNonNegative() {
  return FiniteValidator(0.0, std::numeric_limits<double>::max(), false, "[0, ∞)");
}

CLI::Validator FinitePositive() {
  return FiniteValidator(0.0, std::numeric_limits<double>::max(), true, "(0, ∞)");
}

ProgressCallback LogProgress() {
  return [](const std::string& line) { spdlog::info("{}", line); };
}

ProgressCallback PrintProgress() {
  return [](const std::string& line) {
    std::printf("%s\n", line.c_str());
    std::fflush(stdout);
  };
}

GeometryOptions GeometryArguments(int patches, FormFactorStorage storage) {
  GeometryOptions options;
  options.patches = patches;
  options.storage = storage;
  options.progress = LogProgress();
  return options;
}

std::string DescribeGeometry(const GeometryStage& stage) {
  std::ostringstream out;
  const Scene& scene = stage.scene;
  out << "scene " << scene.name << (scene.path.empty() ? "" : " (" + scene.path.string() + ")")
      << "\n";
  std::vector<int> fine_count(scene.surfaces.size(), 0), coarse_count(scene.surfaces.size(), 0);
  for (const Patch& patch : stage.patches.fine.patches) ++fine_count[patch.surface];
  for (const Patch& patch : stage.patches.coarse.patches) ++coarse_count[patch.surface];
  out << fmt::format("  {:<20} {:>6} {:>10} {:>7} {:>7} {:>18} {}\n", "surface", "kind", "area m²",
                     "fine", "coarse", "reflectance", "desired");
  for (size_t s = 0; s < scene.surfaces.size(); ++s) {
    const Surface& surface = scene.surfaces[s];
    const std::string desired =
        surface.desired.HasTexture()
            ? "texture " + surface.desired.texture_path
            : fmt::format("sRGB {:.2f} {:.2f} {:.2f}", surface.desired.srgb[0],
                          surface.desired.srgb[1], surface.desired.srgb[2]);
    out << fmt::format("  {:<20} {:>6} {:>10.3f} {:>7} {:>7}   {:.2f} {:.2f} {:.2f}   {}\n",
                       surface.name, surface.kind == Surface::Kind::kQuad ? "quad" : "mesh",
                       surface.Area(), fine_count[s], coarse_count[s], surface.reflectance[0],
                       surface.reflectance[1], surface.reflectance[2], desired);
  }
  const Eigen::VectorXd areas = stage.patches.fine.Areas();
  const FormFactorSummary& ff = stage.form_factor_summary;
  out << fmt::format(
      "  total area {:.3f} m², {} fine patches (target {}), {} coarse, {} adjacent pairs\n",
      scene.Area(), stage.patches.fine.size(), scene.target_patches, stage.patches.coarse.size(),
      stage.patches.fine.adjacency.size());
  out << fmt::format("  patch area min {:.4g} mean {:.4g} max {:.4g} m² (max/min {:.2f})\n",
                     areas.minCoeff(), areas.mean(), areas.maxCoeff(),
                     areas.maxCoeff() / areas.minCoeff());
  out << fmt::format(
      "  form factor row sums min {:.5f} mean {:.5f} max {:.5f}; reciprocity error {:.1e}\n",
      ff.min_row_sum, ff.mean_row_sum, ff.max_row_sum, ff.max_reciprocity_error);
  out << fmt::format(
      "  form factors: {} facing pairs, {} shadow rays, {:.2f} s; subdivision {:.3f} s\n",
      ff.pairs_evaluated, ff.shadow_rays, ff.seconds, stage.subdivision_seconds);
  return out.str();
}

ChessboardSpec ParseChessboard(const std::string& corners, double square) {
  const std::array<int, 2> sides =
      ParseSize("--corners", corners, "COLUMNSxROWS of inner corners, e.g. 9x6", 2, 100);
  ChessboardSpec board;
  board.corners_x = sides[0];
  board.corners_y = sides[1];
  board.square_size = square;
  return board;
}

std::shared_ptr<PatternDisplay> OpenMonitorDisplay(const std::string& text) {
  if (text.rfind("glfw:", 0) != 0) {
    throw IoError("display '" + text + "': unknown; use glfw:N|NAME (procam show --list)");
  }
#if PROCAM_WITH_GLFW
  try {
    return std::make_shared<GlfwDisplay>(FindMonitor(text.substr(5)));
  } catch (const IoError& error) {
    throw IoError("display '" + text + "': " + error.what());
  }
#else
  throw IoError("display '" + text +
                "': this build has no GLFW output backend (reconfigure with -DPROCAM_WITH_GLFW=ON; "
                "apt-get install libglfw3-dev libgl-dev libx11-dev libxrandr-dev)");
#endif
}

void AddLightOption(CLI::App* command, LightField* light) {
  const std::map<std::string, LightField> names = {{"smooth", LightField::kSmooth},
                                                   {"flat", LightField::kFlat}};
  command
      ->add_option("--light", *light,
                   "smooth: the light varies smoothly over each surface, stepping only where the "
                   "desired appearance does, each patch's flux kept (seamless) | flat: one "
                   "uniform level per patch")
      ->transform(CLI::CheckedTransformer(names))
      ->option_text(std::string("smooth|flat (default ") + LightFieldName(*light) + ")");
}

void AddPlayToleranceOption(CLI::App* command, double* tolerance) {
  command
      ->add_option("--tolerance", *tolerance,
                   "Each frame's solve stops when an iteration lowers the cost by less than this "
                   "fraction of it")
      ->check(FiniteRange(0.0, 0.1))
      ->capture_default_str();
}

std::string SettleSetting::Text() const { return measure ? "auto" : fmt::format("{}", ms); }

void AddSettleOption(CLI::App* command, SettleSetting* settle) {
  command
      ->add_option_function<std::string>(
          "--settle-ms",
          [settle](const std::string& text) {
            if (text == "auto") {
              settle->measure = true;
              return;
            }
            char* end = nullptr;
            const double ms = std::strtod(text.c_str(), &end);
            if (text.empty() || *end != '\0' || !(ms >= 0.0 && ms <= 60000.0)) {
              throw CLI::ValidationError("--settle-ms", "'" + text + "': auto, or milliseconds in [0, 60000]");
            }
            settle->measure = false;
            settle->ms = ms;
          },
          "Wait after each pattern before frames count: auto (measure the display-to-camera latency first with "
          "a flash sequence) or milliseconds")
      ->option_text("auto|MS (default " + settle->Text() + ")");
}

void CheckNotProcamDirectory(const std::filesystem::path& dir, const std::string& command,
                             const std::string& option) {
  std::error_code error;
  if (std::filesystem::exists(dir, error) && !std::filesystem::is_directory(dir, error)) {
    throw IoError(dir.string() + ": " + option + " must be a directory, and this is a file");
  }
  if (const std::optional<DirectoryKind> found = DirectoryKindOf(dir)) {
    throw IoError(dir.string() + ": " + option + " is " + DirectoryKindName(*found) + "; " + command +
                  " would write its own files into it: give a new directory");
  }
}

}  // namespace procam
