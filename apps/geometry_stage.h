#pragma once
// The geometry stage as the commands run it: scene → patches → form factors, with progress.

#include <filesystem>
#include <memory>
#include <optional>

#include "geometry/form_factors.h"
#include "geometry/patches.h"
#include "geometry/scene.h"

namespace procam {

// How the fine level's F is kept: dense n² (every command), or compressed
// (geometry/compressed_form_factors.h: rooms far past 10k patches; `procam compensate` only).
enum class FormFactorStorage { kDense, kCompressed };

struct GeometryStage {
  Scene scene;
  PatchHierarchy patches;
  Eigen::MatrixXd form_factors;  // fine level; empty when compressed
  FormFactorSummary form_factor_summary;
  std::shared_ptr<const CompressedFormFactors> compressed;  // fine level, when compressed
  CompressedBuildSummary compressed_summary;
  double subdivision_seconds = 0.0;
};

// The scene a command names: a scene file, or a synthetic scene as "synthetic:NAME" (its patch
// target 1000 until the caller overrides it). Throws IoError naming the text when it is neither
// a file nor a synthetic scene (the message lists them).
Scene LoadSceneArgument(const std::string& text);

// Loads `scene_path` (a file or "synthetic:NAME", see LoadSceneArgument; patch count from the
// scene unless `patches` is given) and computes the fine level's form factors, logging progress.
GeometryStage RunGeometryStage(const std::filesystem::path& scene_path, std::optional<int> patches,
                               FormFactorStorage storage = FormFactorStorage::kDense);
// Same for a scene already in memory.
GeometryStage RunGeometryStage(Scene scene, std::optional<int> patches,
                               FormFactorStorage storage = FormFactorStorage::kDense);

// Human-readable summary: surfaces, areas, patch counts, form-factor statistics.
std::string DescribeGeometry(const GeometryStage& stage);

// Writes an image of log10 F (one pixel per patch pair, at most 1024² by block maxima).
void WriteFormFactorImage(const Eigen::MatrixXd& form_factors, const std::filesystem::path& path);

}  // namespace procam
