#pragma once
// Values the commands read from their options (and rig.json keys) beyond what CLI11 parses.

#include <Eigen/Core>
#include <string>
#include <vector>

#include "base/progress.h"
#include "geometry/stage.h"

namespace procam {

// Comma-separated finite numbers, e.g. "0.5,-1.4,0.8". `count` > 0 demands exactly that many.
// Throws IoError "OPTION: expected EXPECTED, got 'TEXT'".
std::vector<double> ParseNumberList(const std::string& option, const std::string& text,
                                    const std::string& expected, size_t count = 0);

// One positive number for every channel, or three (R, G, B). Throws IoError naming `option`.
Eigen::Vector3d ParsePositiveRgb(const std::string& option, const std::string& text);

// A stage's progress lines as the command line shows them: logged (spdlog, info).
ProgressCallback LogProgress();

// The geometry stage's options from --patches (0: the scene's) and the storage, logging progress.
GeometryOptions GeometryArguments(int patches, FormFactorStorage storage = FormFactorStorage::kDense);

// Human-readable summary: surfaces, areas, patch counts, form-factor statistics.
std::string DescribeGeometry(const GeometryStage& stage);

}  // namespace procam
