/// \file liquid_spec.cpp
/// The named herschel-bulkley sets of section 6.4.1 (liquid_spec.hpp).

#include "reference/fluid/liquid_spec.hpp"

namespace monolith {

ViscositySpec viscosity_preset(ViscosityPreset preset) {
  // section 6.4.1 (Fig. 10): (r, gamma0, tau0, k) = (1, 1, 0, 11), (0.5, 1, 1, 10),
  // (2, 1, 1, 10), (1, 1, 1e3, 10)
  ViscositySpec v;
  v.model = ViscosityModel::herschel_bulkley;
  v.preset = preset;
  v.gamma0 = 1.0;
  switch (preset) {
    case ViscosityPreset::newtonian:
      v.k = 11.0;
      v.n = 1.0;
      v.tau0 = 0.0;
      break;
    case ViscosityPreset::shear_thinning:
      v.k = 10.0;
      v.n = 0.5;
      v.tau0 = 1.0;
      break;
    case ViscosityPreset::shear_thickening:
      v.k = 10.0;
      v.n = 2.0;
      v.tau0 = 1.0;
      break;
    case ViscosityPreset::bingham:
      v.k = 10.0;
      v.n = 1.0;
      v.tau0 = 1e3;
      break;
  }
  return v;
}

}  // namespace monolith
