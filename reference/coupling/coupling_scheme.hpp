#pragma once
/// \file coupling_scheme.hpp
/// The nine ways of solving one step's pressure, viscosity and contact (section 6), the scene
/// key `solver.scheme`; solve_coupled_step (coupled_schemes.hpp) runs them.

#include "reference/core/enum_names.hpp"

namespace monolith {

/// Section 6: the nine ways of solving one step's pressure, viscosity and contact.
enum class CouplingScheme {
  p_c,               ///< P-C: fluid solve (no viscosity), then contact solve (section 6.1)
  c_p,               ///< C-P: contact solve, then fluid solve (no viscosity)
  pc_iterative,      ///< PC-iterative: block Gauss-Seidel P, C, P, C, ... (staggered projections)
  pc_unified,        ///< PC-unified: the MLCP (26) without stress unknowns
  pc_vc_pc_unified,  ///< PC-VC-PC-unified: PC-unified, VC-unified, PC-unified (section 6.2)
  pv_c,              ///< PV-C: Stokes solve, then contact solve (section 6.3)
  c_pv,              ///< C-PV: contact solve, then Stokes solve
  pvc_iterative,     ///< PVC-iterative: block Gauss-Seidel PV, C, PV, C, ...
  pvc_unified        ///< PVC-unified: the MLCP (26) over (tau, p, lambda) (section 4.2)
};

/// The paper's names, in the order of the enum.
template <>
struct EnumNames<CouplingScheme> {
  static constexpr std::array<std::pair<CouplingScheme, const char*>, 9> values{{
      {CouplingScheme::p_c, "P-C"},
      {CouplingScheme::c_p, "C-P"},
      {CouplingScheme::pc_iterative, "PC-iterative"},
      {CouplingScheme::pc_unified, "PC-unified"},
      {CouplingScheme::pc_vc_pc_unified, "PC-VC-PC-unified"},
      {CouplingScheme::pv_c, "PV-C"},
      {CouplingScheme::c_pv, "C-PV"},
      {CouplingScheme::pvc_iterative, "PVC-iterative"},
      {CouplingScheme::pvc_unified, "PVC-unified"},
  }};
};

/// true for PC-VC-PC-unified, PV-C, C-PV, PVC-iterative, PVC-unified. The P.. C schemes drop
/// viscosity: the liquid is treated as inviscid, as the simulator does without bodies.
constexpr bool scheme_uses_viscosity(CouplingScheme s) {
  return s == CouplingScheme::pc_vc_pc_unified || s == CouplingScheme::pv_c ||
         s == CouplingScheme::c_pv || s == CouplingScheme::pvc_iterative ||
         s == CouplingScheme::pvc_unified;
}

/// true for PC-iterative and PVC-iterative.
constexpr bool scheme_is_iterative(CouplingScheme s) {
  return s == CouplingScheme::pc_iterative || s == CouplingScheme::pvc_iterative;
}

}  // namespace monolith
