#include "geometry/stage.h"

#include <unistd.h>

#include <fmt/format.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <map>
#include <mutex>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "base/image_io.h"
#include "base/io.h"
#include "base/timing.h"

namespace procam {

namespace {

struct SceneSources {
  std::mutex mutex;
  std::map<std::string, SceneSource> sources;
};
SceneSources& Sources() {
  static SceneSources sources;
  return sources;
}

}  // namespace

void RegisterSceneSource(const std::string& prefix, SceneSource source) {
  SceneSources& registry = Sources();
  const std::lock_guard<std::mutex> lock(registry.mutex);
  registry.sources[prefix] = std::move(source);
}

std::vector<std::string> SceneSourceNames(const std::string& prefix) {
  SceneSources& registry = Sources();
  const std::lock_guard<std::mutex> lock(registry.mutex);
  const auto found = registry.sources.find(prefix);
  return found == registry.sources.end() || !found->second.names ? std::vector<std::string>()
                                                                 : found->second.names();
}

Scene LoadSceneArgument(const std::string& text) {
  const size_t colon = text.find(':');
  const std::string prefix = colon == std::string::npos ? "" : text.substr(0, colon);
  const bool named = !prefix.empty() && std::all_of(prefix.begin(), prefix.end(), [](char c) {
    return std::isalnum(static_cast<unsigned char>(c)) || c == '_';
  });
  if (!named || std::filesystem::exists(text)) return LoadScene(text);
  SceneSource source;
  std::string known;
  {
    SceneSources& registry = Sources();
    const std::lock_guard<std::mutex> lock(registry.mutex);
    const auto found = registry.sources.find(prefix);
    if (found != registry.sources.end()) source = found->second;
    for (const auto& entry : registry.sources)
      known += (known.empty() ? "" : ", ") + entry.first + ":";
  }
  if (!source.make) {
    throw IoError(
        text + ": no such scene file, and no scene source '" + prefix + ":'" +
        (known.empty() ? std::string(" (none is registered)") : " (registered: " + known + ")"));
  }
  Scene scene = source.make(text.substr(colon + 1));
  scene.path = text;  // what results record, so that later commands can rebuild it
  return scene;
}

bool GeometryOptions::Check(std::string* why) const {
  if (patches != 0 && patches < 4) {
    *why = "patches must be 0 (the scene's) or at least 4, got " + std::to_string(patches);
    return false;
  }
  return true;
}

std::string GeometryStage::BriefReport() const {
  const FormFactorSummary& ff = form_factor_summary;
  return fmt::format(
      "{}: {} fine patches ({} coarse), {} adjacent pairs; form factors {}, row sums "
      "{:.5f}..{:.5f}, {:.2f} s; subdivision {:.3f} s",
      scene.name, patches.fine.size(), patches.coarse.size(), patches.fine.adjacency.size(),
      compressed ? "compressed" : "dense", ff.min_row_sum, ff.max_row_sum, ff.seconds,
      subdivision_seconds);
}

uint64_t PhysicalMemoryBytes() {
  const long pages = ::sysconf(_SC_PHYS_PAGES), page_size = ::sysconf(_SC_PAGE_SIZE);
  if (pages <= 0 || page_size <= 0) return 0;  // unknown
  return static_cast<uint64_t>(pages) * static_cast<uint64_t>(page_size);
}

void CheckDenseFormFactorMemory(int64_t patches, uint64_t memory_bytes) {
  if (memory_bytes == 0) return;  // unknown: the allocation will tell
  const double needed = 8.0 * static_cast<double>(patches) * static_cast<double>(patches);
  if (needed <= static_cast<double>(memory_bytes)) return;
  throw IoError(fmt::format(
      "--patches: the dense form factors of {} patches need {:.1f} GB (8 bytes × n²), more than "
      "this machine's {:.1f} GB of memory: give fewer patches, or compensate with --form-factors "
      "compressed",
      patches, needed / 1e9, static_cast<double>(memory_bytes) / 1e9));
}

GeometryStage RunGeometryStage(const std::string& scene, const GeometryOptions& options) {
  return RunGeometryStage(LoadSceneArgument(scene), options);
}

GeometryStage RunGeometryStage(Scene scene, const GeometryOptions& options) {
  std::string why;
  if (!options.Check(&why)) throw IoError("--patches: " + why);
  GeometryStage stage;
  stage.scene = std::move(scene);
  if (options.patches > 0) stage.scene.target_patches = options.patches;
  ValidateScene(stage.scene);
  SubdivisionOptions subdivision;
  subdivision.target_patches = stage.scene.target_patches;
  if (!subdivision.Check(&why)) throw IoError("--patches: " + why);
  if (options.storage == FormFactorStorage::kDense) {
    CheckDenseFormFactorMemory(stage.scene.target_patches);  // before subdividing: at once
  }
  const auto start = Clock::now();
  stage.patches = SubdividePatches(stage.scene, subdivision);
  stage.subdivision_seconds =
      SecondsSince(start);
  if (options.storage == FormFactorStorage::kDense) {
    CheckDenseFormFactorMemory(stage.patches.fine.size());  // the count made may exceed the target
  }
  Report(options.progress,
         fmt::format("{}: {} fine patches ({} coarse), {} adjacent pairs", stage.scene.name,
                     stage.patches.fine.size(), stage.patches.coarse.size(),
                     stage.patches.fine.adjacency.size()));
  FormFactorOptions form_factor_options;
  int last_percent = -1;
  form_factor_options.progress = [&](double fraction) {
    const int percent = static_cast<int>(fraction * 100.0);
    if (percent / 10 != last_percent / 10) {
      Report(options.progress, fmt::format("form factors: {:3d}%", percent));
      last_percent = percent;
    }
  };
  if (options.storage == FormFactorStorage::kCompressed) {
    const ClusterOptions clusters;
    stage.compressed = std::make_shared<const CompressedFormFactors>(ComputeCompressedFormFactors(
        stage.scene, stage.patches.fine, form_factor_options, clusters, &stage.compressed_summary));
    const CompressedBuildSummary& c = stage.compressed_summary;
    const int n = stage.patches.fine.size();
    Report(
        options.progress,
        fmt::format(
            "form factors (compressed, leaf {}, admissibility {}): {} near entries, {} far blocks, "
            "{:.1f} MB ({:.1f}% of dense), {:.2f} s",
            clusters.leaf_size, clusters.admissibility, c.near_entries, c.far_blocks, c.bytes / 1e6,
            100.0 * c.bytes / (8.0 * n * n), c.seconds));
    const Eigen::VectorXd rows = stage.compressed->RowSums();
    FormFactorSummary& summary = stage.form_factor_summary;
    summary.seconds = c.seconds;
    summary.shadow_rays = c.visibility_rays;
    summary.min_row_sum = rows.minCoeff();
    summary.mean_row_sum = rows.mean();
    summary.max_row_sum = rows.maxCoeff();
    return stage;
  }
  stage.form_factors = ComputeFormFactors(stage.scene, stage.patches.fine, form_factor_options,
                                          &stage.form_factor_summary);
  Report(options.progress,
         fmt::format("form factors: {} pairs, {} shadow rays, {:.2f} s",
                     stage.form_factor_summary.pairs_evaluated,
                     stage.form_factor_summary.shadow_rays, stage.form_factor_summary.seconds));
  return stage;
}

void WriteFormFactorImage(const Eigen::MatrixXd& form_factors, const std::filesystem::path& path) {
  const int n = static_cast<int>(form_factors.rows());
  const int size = std::min(n, 1024);
  cv::Mat gray(size, size, CV_8UC1, cv::Scalar(0));
  for (int i = 0; i < n; ++i) {
    for (int j = 0; j < n; ++j) {
      const double value = form_factors(i, j);
      if (value <= 0.0) continue;
      // log10 F from 1e-6 (dark) to 1e-1 (bright); block maximum when downsampling.
      const double level = std::clamp((std::log10(value) + 6.0) / 5.0, 0.0, 1.0);
      uchar& pixel = gray.at<uchar>(static_cast<int>(int64_t(i) * size / n),
                                    static_cast<int>(int64_t(j) * size / n));
      pixel = std::max(pixel, static_cast<uchar>(1 + 254 * level));
    }
  }
  cv::Mat coloured;
  cv::applyColorMap(gray, coloured, cv::COLORMAP_INFERNO);
  WritePng(path, coloured);
}

}  // namespace procam
