#pragma once
// `procam scene info`, `scene write` and `scene export`: a scene read and described in full (its
// geometry, projectors and cameras), a built-in synthetic scene written as a scene file with its
// devices (scene_files.h), and a scene's problem written as NumPy files (ExportGeometryProblem).

#include <filesystem>
#include <string>

#include "base/progress.h"
#include "geometry/stage.h"

namespace procam {

class OptionTable;

struct SceneFileOptions {
  // A scene file or PREFIX:NAME (LoadSceneArgument); scene write: a synthetic scene's name
  // (SyntheticSceneNames()).
  std::string scene;
  std::filesystem::path out;  // scene write, scene export: the output directory
  int patches = 0;            // the fine level's patch target, ≥ 0; 0: the scene's (write: 1000)
  double alpha = 0.5;         // scene export: weight of the absolute term, (0, 1]
  ProgressCallback progress;  // the geometry stage's lines
  // Each command's options, bound to these fields (base/option_table.h): the scene
  // (positional) and --patches; scene write also --out; scene export --out and --alpha.
  void DeclareInfo(OptionTable* table);
  void DeclareWrite(OptionTable* table);
  void DeclareExport(OptionTable* table);
  bool Check(std::string* why) const;
};

// Surfaces, areas, patch counts and form-factor statistics of the geometry stage, a line each.
std::string DescribeGeometry(const GeometryStage& stage);
// The scene's geometry and its projectors and cameras, each read and checked in full (models
// included), so that a scene `scene info` accepts is one every other command accepts. Throws
// IoError naming the file and key.
std::string DescribeScene(const GeometryStage& stage);
// scene info: the geometry stage on options.scene, described (DescribeScene).
std::string DescribeSceneFile(const SceneFileOptions& options);
// scene write: WriteSyntheticSceneFile of options.scene into options.out. Throws
// std::invalid_argument naming the scene when it is no synthetic scene.
std::filesystem::path WriteSceneFile(const SceneFileOptions& options);
// scene export: the scene described, then its problem written into options.out (which must be
// no directory of procam's: CheckNotProcamDirectory). Returns the description.
std::string ExportSceneProblem(const SceneFileOptions& options);

// For commands whose output is no directory kind of their own (scene export, evaluate): throws
// IoError naming `dir` and its `option` (e.g. FlagOf(options, &options.out)) when it is a file or
// holds a rig, a session, a solution or another of procam's outputs, whose files the command
// would overwrite or mix with its own.
void CheckNotProcamDirectory(const std::filesystem::path& dir, const std::string& command,
                             const std::string& option);

}  // namespace procam
