#include "apps/geometry_stage.h"

#include "datasets_synthetic/paper_scenes.h"

#include <chrono>
#include <cmath>
#include <sstream>

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <spdlog/fmt/fmt.h>
#include <spdlog/spdlog.h>

#include "base/io.h"

namespace procam {

Scene LoadSceneArgument(const std::string& text) {
  if (text.rfind("synthetic:", 0) != 0) return LoadScene(text);
  const std::string name = text.substr(10);
  std::string known;
  for (const std::string& scene : SyntheticSceneNames()) {
    if (scene == name) {
      Scene synthetic = MakeSyntheticScene(name).scene;
      synthetic.path = text;  // what results record, so that later commands can rebuild it
      return synthetic;
    }
    known += (known.empty() ? "" : ", ") + scene;
  }
  throw IoError(text + ": no such synthetic scene (" + known + ")");
}

GeometryStage RunGeometryStage(const std::filesystem::path& scene_path, std::optional<int> patches,
                               FormFactorStorage storage) {
  return RunGeometryStage(LoadSceneArgument(scene_path.string()), patches, storage);
}

GeometryStage RunGeometryStage(Scene scene, std::optional<int> patches, FormFactorStorage storage) {
  GeometryStage stage;
  stage.scene = std::move(scene);
  if (patches) stage.scene.target_patches = *patches;
  ValidateScene(stage.scene);
  SubdivisionOptions subdivision;
  subdivision.target_patches = stage.scene.target_patches;
  std::string why;
  if (!subdivision.Check(&why)) throw IoError("--patches: " + why);
  const auto start = std::chrono::steady_clock::now();
  stage.patches = SubdividePatches(stage.scene, subdivision);
  stage.subdivision_seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  spdlog::info("{}: {} fine patches ({} coarse), {} adjacent pairs", stage.scene.name,
               stage.patches.fine.size(), stage.patches.coarse.size(), stage.patches.fine.adjacency.size());
  FormFactorOptions options;
  int last_percent = -1;
  options.progress = [&last_percent](double fraction) {
    const int percent = static_cast<int>(fraction * 100.0);
    if (percent / 10 != last_percent / 10) {
      spdlog::info("form factors: {:3d}%", percent);
      last_percent = percent;
    }
  };
  if (storage == FormFactorStorage::kCompressed) {
    const ClusterOptions clusters;
    stage.compressed = std::make_shared<const CompressedFormFactors>(
        ComputeCompressedFormFactors(stage.scene, stage.patches.fine, options, clusters, &stage.compressed_summary));
    const CompressedBuildSummary& c = stage.compressed_summary;
    const int n = stage.patches.fine.size();
    spdlog::info("form factors (compressed, leaf {}, admissibility {}): {} near entries, {} far blocks, "
                 "{:.1f} MB ({:.1f}% of dense), {:.2f} s",
                 clusters.leaf_size, clusters.admissibility, c.near_entries, c.far_blocks, c.bytes / 1e6,
                 100.0 * c.bytes / (8.0 * n * n), c.seconds);
    const Eigen::VectorXd rows = stage.compressed->RowSums();
    FormFactorSummary& summary = stage.form_factor_summary;
    summary.seconds = c.seconds;
    summary.shadow_rays = c.visibility_rays;
    summary.min_row_sum = rows.minCoeff();
    summary.mean_row_sum = rows.mean();
    summary.max_row_sum = rows.maxCoeff();
    return stage;
  }
  stage.form_factors = ComputeFormFactors(stage.scene, stage.patches.fine, options, &stage.form_factor_summary);
  spdlog::info("form factors: {} pairs, {} shadow rays, {:.2f} s", stage.form_factor_summary.pairs_evaluated,
               stage.form_factor_summary.shadow_rays, stage.form_factor_summary.seconds);
  return stage;
}

std::string DescribeGeometry(const GeometryStage& stage) {
  std::ostringstream out;
  const Scene& scene = stage.scene;
  out << "scene " << scene.name << (scene.path.empty() ? "" : " (" + scene.path.string() + ")") << "\n";
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
            : fmt::format("sRGB {:.2f} {:.2f} {:.2f}", surface.desired.srgb[0], surface.desired.srgb[1],
                          surface.desired.srgb[2]);
    out << fmt::format("  {:<20} {:>6} {:>10.3f} {:>7} {:>7}   {:.2f} {:.2f} {:.2f}   {}\n", surface.name,
                       surface.kind == Surface::Kind::kQuad ? "quad" : "mesh", surface.Area(), fine_count[s],
                       coarse_count[s], surface.reflectance[0], surface.reflectance[1],
                       surface.reflectance[2], desired);
  }
  const Eigen::VectorXd areas = stage.patches.fine.Areas();
  const FormFactorSummary& ff = stage.form_factor_summary;
  out << fmt::format("  total area {:.3f} m², {} fine patches (target {}), {} coarse, {} adjacent pairs\n",
                     scene.Area(), stage.patches.fine.size(), scene.target_patches,
                     stage.patches.coarse.size(), stage.patches.fine.adjacency.size());
  out << fmt::format("  patch area min {:.4g} mean {:.4g} max {:.4g} m² (max/min {:.2f})\n", areas.minCoeff(),
                     areas.mean(), areas.maxCoeff(), areas.maxCoeff() / areas.minCoeff());
  out << fmt::format("  form factor row sums min {:.5f} mean {:.5f} max {:.5f}; reciprocity error {:.1e}\n",
                     ff.min_row_sum, ff.mean_row_sum, ff.max_row_sum, ff.max_reciprocity_error);
  out << fmt::format("  form factors: {} facing pairs, {} shadow rays, {:.2f} s; subdivision {:.3f} s\n",
                     ff.pairs_evaluated, ff.shadow_rays, ff.seconds, stage.subdivision_seconds);
  return out.str();
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
      uchar& pixel = gray.at<uchar>(static_cast<int>(int64_t(i) * size / n), static_cast<int>(int64_t(j) * size / n));
      pixel = std::max(pixel, static_cast<uchar>(1 + 254 * level));
    }
  }
  cv::Mat coloured;
  cv::applyColorMap(gray, coloured, cv::COLORMAP_INFERNO);
  std::vector<uchar> png;
  if (!cv::imencode(".png", coloured, png)) throw IoError(path.string() + ": cannot encode PNG");
  WriteFileAtomically(path, std::string(png.begin(), png.end()));
}

}  // namespace procam
