#include "compensation/unit_light.h"

#include "compensation/radiosity.h"

namespace procam {

UnitLightModel ModelUnitLight(const PatchLevel& level, const Eigen::MatrixXd& form_factors,
                              const Eigen::MatrixX3d& unit_exitance) {
  UnitLightModel model;
  model.direct_irradiance = Eigen::MatrixX3d::Zero(level.size(), 3);
  for (int i = 0; i < level.size(); ++i) {
    for (int c = 0; c < 3; ++c) {
      if (level.reflectance(i, c) > 0.0)
        model.direct_irradiance(i, c) = unit_exitance(i, c) / level.reflectance(i, c);
    }
  }
  const RadiositySystem system(form_factors, level.Areas(), level.reflectance);
  const Eigen::MatrixX3d radiosity = system.Solve(unit_exitance);
  model.bounce_irradiance = form_factors * radiosity;
  return model;
}

}  // namespace procam
