#pragma once
/// \file viscosity_field.hpp
/// The dynamic viscosity eta sampled from the particles: per stress DOF (the N of eq. (8) is
/// built from it) and per cell (the render colour `viscosity`). Several liquids with different
/// eta in one scene give a spatially varying eta; every particle carries its liquid's index
/// (Particles::liquid), so eta_p = eta of liquids[liquid[p]].

#include <vector>

#include "reference/core/common.hpp"
#include "reference/fluid/liquid_spec.hpp"
#include "reference/grid/mac_grid.hpp"
#include "reference/grid/stress_grid.hpp"
#include "reference/particles/particles.hpp"

namespace monolith {

/// Rings of neighbour averaging that extend eta from the samples a particle reaches to the ones
/// no particle reaches (see sample_viscosity).
inline constexpr int kViscosityFillLayers = 2;

/// Newtonian dynamic viscosity of every liquid of the scene (Pa s), in scene order.
std::vector<double> liquid_viscosities(const std::vector<LiquidSpec>& liquids);

/// eta on the sample lattice origin + (c + shift) dx, c in [0, dims) (x fastest; the layout of a
/// cell field, a face axis or a stress component): the mass-weighted average
///   eta_k = sum_p w_kp m_p eta_p / sum_p w_kp m_p,
/// w_kp the multilinear hat weight of support dx (the weights of the APIC transfer), i.e. the
/// particles within the sample's control volume of side 2 dx. Samples no particle reaches take
/// the mean of their reached axis neighbours, repeated kViscosityFillLayers times (the liquid
/// level set ends within a cell of the particles, so every sample inside the liquid is covered);
/// the rest take the mass-weighted mean eta of all particles (0 without particles). A uniform
/// viscosity is reproduced exactly.
template <int Dim>
VectorX sample_viscosity(const MacGrid<Dim>& grid, const Vec<Dim>& shift, const VecI<Dim>& dims,
                         const Particles<Dim>& particles, const std::vector<double>& liquid_eta);

/// eta per stress DOF of `stress` (StressGrid numbering, all components): sample_viscosity on
/// each component's lattice. This is the `viscosity` vector of StokesWeights.
template <int Dim>
VectorX stress_viscosity(const StressGrid<Dim>& stress, const Particles<Dim>& particles,
                         const std::vector<double>& liquid_eta);

/// stress_viscosity written into `eta` (resized to stress.num_dofs() only when its size differs):
/// the same values, without a fresh grid-sized vector (and its first-touch page faults) per call
/// when the caller keeps `eta` across steps.
template <int Dim>
void stress_viscosity_into(const StressGrid<Dim>& stress, const Particles<Dim>& particles,
                           const std::vector<double>& liquid_eta, VectorX& eta);

/// eta per cell (cell centres), for RenderView::viscosity.
template <int Dim>
VectorX cell_viscosity(const MacGrid<Dim>& grid, const Particles<Dim>& particles,
                       const std::vector<double>& liquid_eta);

/// Mass fraction of each liquid per stress DOF (StressGrid numbering, all components): for
/// liquid i, sample_viscosity with eta = 1 for liquid i and 0 for the others, so the fractions
/// of one DOF sum to 1 (exactly 1 everywhere in a scene of one liquid). The weights f_ij of
/// ViscosityMixture (herschel_bulkley.hpp).
template <int Dim>
std::vector<VectorX> liquid_stress_fractions(const StressGrid<Dim>& stress,
                                             const Particles<Dim>& particles, int num_liquids);

}  // namespace monolith
