#pragma once
// The radiosity of one projector's light at unit output, split into its direct and bounced parts
// per patch: what the photometric calibration needs to turn a photographed flat field into the
// projector's output and the room's reflectance (projection/photometric_transfer.h).

#include <Eigen/Core>

#include "geometry/patches.h"

namespace procam {

// The radiosity model of one projector at unit output (black 0, max 1 on every channel), from
// its direct exitance ρ ⊙ Ḡ per patch (n,3: the projection rig's upper bound of a projector with
// black 0 and max 1, projection/projection_rig.h UnitLightExitance):
// Ḡ (n,3, mean direct irradiance per patch; 0 where ρ is 0) and bounce = F·b (n,3, bounce
// irradiance per patch), b = K⁻¹(ρ ⊙ Ḡ).
struct UnitLightModel {
  Eigen::MatrixX3d direct_irradiance;
  Eigen::MatrixX3d bounce_irradiance;
};
UnitLightModel ModelUnitLight(const PatchLevel& level, const Eigen::MatrixXd& form_factors,
                              const Eigen::MatrixX3d& unit_exitance);

}  // namespace procam
