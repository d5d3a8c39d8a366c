#pragma once
// The geometry stage: scene → patches (fine and coarse levels) → the fine level's form factors.
//
// Scenes are named by text: a scene file's path, or PREFIX:NAME for a scene made by a registered
// source. The product registers none; the synthetic world (datasets_synthetic) registers
// "synthetic" (synthetic:c_shaped, ...) where the command line, tests and benchmarks ask for it.

#include <cstdint>
#include <filesystem>
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include "base/progress.h"
#include "geometry/compressed_form_factors.h"
#include "geometry/form_factors.h"
#include "geometry/patches.h"
#include "geometry/scene.h"

namespace procam {

// A source of scenes by name: returns the scene NAME, or throws IoError naming it and listing the
// names it knows. `names()` lists them (for help texts).
struct SceneSource {
  std::function<Scene(const std::string& name)> make;
  std::function<std::vector<std::string>()> names;
};
// Registers `source` for texts "PREFIX:NAME" (PREFIX: letters, digits, '_'; replaces an earlier
// registration of the same prefix). Thread-safe.
void RegisterSceneSource(const std::string& prefix, SceneSource source);
// The names a registered source knows; empty when `prefix` is not registered.
std::vector<std::string> SceneSourceNames(const std::string& prefix);

// The scene `text` names: PREFIX:NAME through its registered source (Scene::path = text, so that
// results record how to rebuild it), otherwise a scene file (LoadScene). Throws IoError naming the
// text: an unknown prefix (listing the registered ones), an unknown name, any error of the file.
Scene LoadSceneArgument(const std::string& text);

// How the fine level's F is kept: dense n² (every command), or compressed
// (geometry/compressed_form_factors.h: rooms far past 10k patches; `procam compensate` only).
enum class FormFactorStorage { kDense, kCompressed };

struct GeometryOptions {
  int patches = 0;  // target patch count of the fine level; 0 = the scene's `patches`, else ≥ 4
  FormFactorStorage storage = FormFactorStorage::kDense;
  ProgressCallback progress;  // patch counts, form factors every 10%, timings
  bool Check(std::string* why) const;
};

// What the stage made.
struct GeometryStage {
  Scene scene;
  PatchHierarchy patches;
  Eigen::MatrixXd form_factors;  // fine level; empty when compressed
  FormFactorSummary form_factor_summary;
  std::shared_ptr<const CompressedFormFactors> compressed;  // fine level, when compressed
  CompressedBuildSummary compressed_summary;
  double subdivision_seconds = 0.0;
  // One line: patches, pairs, row sums, seconds.
  std::string BriefReport() const;
};

// This machine's physical memory in bytes (0 when unknown).
uint64_t PhysicalMemoryBytes();

// Throws IoError naming --patches, the memory the dense form factors of `patches` patches need
// (8 n² bytes) and --form-factors compressed, when that exceeds `memory_bytes` (0: unknown, no
// check): a count that cannot fit is refused before anything is allocated.
void CheckDenseFormFactorMemory(int64_t patches, uint64_t memory_bytes = PhysicalMemoryBytes());

// Validates the scene, subdivides it and computes the fine level's form factors. Throws IoError
// for an invalid scene (naming its file and key) or bad options (naming the option).
GeometryStage RunGeometryStage(Scene scene, const GeometryOptions& options);
// The same for a scene named by text (LoadSceneArgument).
GeometryStage RunGeometryStage(const std::string& scene, const GeometryOptions& options);

// Writes an image of log10 F (one pixel per patch pair, at most 1024² by block maxima).
void WriteFormFactorImage(const Eigen::MatrixXd& form_factors, const std::filesystem::path& path);

}  // namespace procam
