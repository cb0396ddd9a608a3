#pragma once
/// \file liquid_spec.hpp
/// The plain description of a liquid (a scene's `liquids` entries, docs/scene-format.md): its
/// initial shape, density, velocity and viscosity model, from which seed_particles
/// (particles.hpp), liquid_viscosities (viscosity_field.hpp) and HerschelBulkley::from_spec
/// (herschel_bulkley.hpp) start.

#include <optional>
#include <string>
#include <vector>

#include "reference/core/enum_names.hpp"
#include "reference/geometry/shape_spec.hpp"

namespace monolith {

/// newtonian: constant eta; herschel_bulkley: eq. (27) with (k, n, tau0, gamma0) (section 5).
enum class ViscosityModel { newtonian, herschel_bulkley };

template <>
struct EnumNames<ViscosityModel> {
  static constexpr std::array<std::pair<ViscosityModel, const char*>, 2> values{
      {{ViscosityModel::newtonian, "newtonian"}, {ViscosityModel::herschel_bulkley, "herschel-bulkley"}}};
};

/// The named herschel-bulkley sets of section 6.4.1 (Fig. 10), viscosity_preset.
enum class ViscosityPreset { newtonian, shear_thinning, shear_thickening, bingham };

template <>
struct EnumNames<ViscosityPreset> {
  static constexpr std::array<std::pair<ViscosityPreset, const char*>, 4> values{
      {{ViscosityPreset::newtonian, "newtonian"},
       {ViscosityPreset::shear_thinning, "shear-thinning"},
       {ViscosityPreset::shear_thickening, "shear-thickening"},
       {ViscosityPreset::bingham, "bingham"}}};
};

/// viscosity: `newtonian` (eta) or `herschel-bulkley` (k, n, tau0, gamma0), eq. (27).
struct ViscositySpec {
  ViscosityModel model = ViscosityModel::newtonian;
  double eta = 0.0;
  double k = 0.0;
  double n = 1.0;
  double tau0 = 0.0;
  double gamma0 = 1e-3;
  /// herschel-bulkley only: the named set it started from (viscosity_preset), if any; explicit
  /// keys next to it have overridden its values above.
  std::optional<ViscosityPreset> preset = std::nullopt;
  /// True when this liquid needs stress unknowns (any non-zero viscosity).
  bool is_viscous() const { return model != ViscosityModel::newtonian || eta > 0.0; }
};

/// The section 6.4.1 (Fig. 10) set as eq. (27)'s (k, n = r, tau0, gamma0): newtonian
/// (11, 1, 0, 1), shear-thinning (10, 0.5, 1, 1), shear-thickening (10, 2, 1, 1), bingham
/// (10, 1, 1e3, 1); model herschel_bulkley, `preset` set.
ViscositySpec viscosity_preset(ViscosityPreset preset);

struct LiquidSpec {
  std::string name;
  ShapeSpec shape;
  double density = 0.0;
  std::vector<double> velocity;          ///< dim numbers; empty = zero
  std::vector<double> angular_velocity;  ///< 2D: 1 number, 3D: 3 numbers (about shape centre)
  ViscositySpec viscosity;
};

}  // namespace monolith
