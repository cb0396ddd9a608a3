#include "reference/stokes_system.hpp"

#include <algorithm>
#include <stdexcept>

#include "reference/deformation_rate.hpp"
#include "reference/gradient.hpp"
#include "reference/stress_weights.hpp"
#include "reference/volume_fractions.hpp"

namespace monolith {

namespace {

/// C_f = dt W_F^u P^-1 (W_L^u)^-1 per face (0 where the face carries no fluid, liquid or density).
VectorX stokes_face_coefficients(const PressureWeights& w, double dt) {
  VectorX c(w.fluid_face.size());
  for (int f = 0; f < c.size(); ++f)
    c[f] = w.fluid_face[f] > 0.0 && w.face_density[f] > 0.0
               ? dt * w.fluid_face[f] * reciprocal_or_zero(w.liquid_face[f]) / w.face_density[f]
               : 0.0;
  return c;
}

/// The StressGrid DOFs a layout unknown expands into, with the entries of E (+1, and -1 on the
/// eliminated diagonal component in the reduced form). Returns the count (1 or 2).
template <int Dim>
int expansion_column(const StressLayout<Dim>& layout, int unknown, std::array<int, 2>& dof,
                     std::array<double, 2>& sign) {
  const StressGrid<Dim>& stress = layout.grid();
  dof[0] = layout.dof_of_unknown(unknown);
  sign[0] = 1.0;
  const int k = layout.component(layout.component_of_unknown(unknown));
  if (layout.form() != StressForm::reduced || !StressGrid<Dim>::is_diagonal(k)) return 1;
  dof[1] = stress.offset(Dim - 1) + (dof[0] - stress.offset(k));
  sign[1] = -1.0;
  return 2;
}

}  // namespace

// --- DOF selection --------------------------------------------------------------------------

template <int Dim>
StokesDofs select_stokes_dofs(const MacGrid<Dim>& grid, const StressLayout<Dim>& layout,
                              const StokesWeights& w, double dt, StokesUnknowns unknowns) {
  StokesDofs dofs;
  // stress: W^s > 0 and eta > 0 on every StressGrid DOF the unknown stands for
  dofs.dof_of_unknown.assign(layout.num_unknowns(), -1);
  for (int i = 0; i < layout.num_unknowns(); ++i) {
    std::array<int, 2> dof;
    std::array<double, 2> sign;
    const int count = expansion_column(layout, i, dof, sign);
    bool active = true;
    for (int m = 0; m < count; ++m) {
      const int d = dof[m];
      active = active && w.fluid_stress[d] * w.liquid_stress[d] > 0.0 && w.viscosity[d] > 0.0;
    }
    if (!active) continue;
    dofs.dof_of_unknown[i] = dofs.num_stress();
    dofs.unknown_of_dof.push_back(i);
  }
  // pressure: the DOFs of the pressure solve
  if (unknowns == StokesUnknowns::pressure_and_stress)
    dofs.pressure = select_pressure_dofs(grid, w.pressure, dt);
  // null space: an enclosed pressure group with tau = 0 (A11 is definite, so there is no other)
  for (const VectorX& n : dofs.pressure.null_space) {
    VectorX v = VectorX::Zero(dofs.size());
    v.tail(dofs.num_pressure()) = n;
    dofs.null_space.push_back(v);
  }
  return dofs;
}

// --- explicit back end ----------------------------------------------------------------------

template <int Dim>
ExplicitStokesSystem assemble_explicit_stokes(const MacGrid<Dim>& grid,
                                              const StressLayout<Dim>& layout,
                                              const StokesWeights& w, const StokesDofs& dofs,
                                              double dt, const VectorX& u_star) {
  const StressGrid<Dim>& stress = layout.grid();
  ExplicitStokesSystem sys;
  // the named matrices of eq. (8)
  sys.G = gradient_matrix(grid);
  sys.D = deformation_rate_matrix(stress);
  sys.M = sparse_diagonal(stress_multiplicity(stress));
  sys.N_inv = inverse_viscosity_matrix(layout, w.viscosity);
  sys.W_F_u = sparse_diagonal(w.pressure.fluid_face);
  sys.W_L_u_inv = sparse_diagonal(w.pressure.liquid_face.unaryExpr(&reciprocal_or_zero));
  sys.P_inv = sparse_diagonal(w.pressure.face_density.unaryExpr(&reciprocal_or_zero));
  sys.W_L_p = sparse_diagonal(w.pressure.liquid_cell);
  sys.W_F_s = sparse_diagonal(w.fluid_stress);
  sys.W_L_s = sparse_diagonal(w.liquid_stress);
  sys.E = layout.expansion();
  // selections of the active DOFs
  std::vector<Triplet> t;
  for (int k = 0; k < dofs.num_stress(); ++k) t.emplace_back(k, dofs.unknown_of_dof[k], 1.0);
  sys.S_tau.resize(dofs.num_stress(), layout.num_unknowns());
  sys.S_tau.setFromTriplets(t.begin(), t.end());
  t.clear();
  for (int k = 0; k < dofs.num_pressure(); ++k) t.emplace_back(k, dofs.pressure.cell_of_dof[k], 1.0);
  sys.S_p.resize(dofs.num_pressure(), grid.num_cells());
  sys.S_p.setFromTriplets(t.begin(), t.end());
  // K = W_F^u P^-1 (W_L^u)^-1 and the full-layout N^-1 = M diag(1/eta)
  const SparseMatrix K = sys.W_F_u * sys.P_inv * sys.W_L_u_inv;
  const SparseMatrix N_full_inv =
      sys.M * sparse_diagonal(w.viscosity.unaryExpr(&reciprocal_or_zero));
  const SparseMatrix W_s = sys.W_F_s * sys.W_L_s;
  const SparseMatrix Dt = sys.D.transpose();
  const SparseMatrix St_tau = sys.S_tau.transpose();
  const SparseMatrix St_p = sys.S_p.transpose();
  // the stress force of the active unknowns on the faces, F_s = D^T M W_L^s E S_tau^T
  // (num_faces x n_tau): restricting to the active unknowns first keeps every product below as
  // small as the active stress set (empty for an inviscid liquid)
  const SparseMatrix R = sys.E * St_tau;
  const SparseMatrix F_s = Dt * SparseMatrix(sys.M * sys.W_L_s * R);
  const SparseMatrix F_sT = F_s.transpose();
  // A11 = S E^T (1/2 N^-1 W^s + dt W_L^s M D K D^T M W_L^s) E S^T
  const SparseMatrix viscous = SparseMatrix(R.transpose() * N_full_inv * W_s) * R;
  sys.A11 = 0.5 * viscous + dt * SparseMatrix(F_sT * K * F_s);
  // b1 = S E^T W_L^s M D W_F^u u*
  sys.b1 = F_sT * (sys.W_F_u * u_star);
  if (dofs.num_pressure() > 0) {
    // A12 = S E^T dt W_L^s M D K G W_L^p S_p^T
    const SparseMatrix GW = sys.G * sys.W_L_p;
    sys.A12 = dt * SparseMatrix(F_sT * K * GW) * St_p;
    // A22 and b2 are the pressure system's (the same expression, so eta = 0 reproduces
    // solve_pressure bit for bit)
    const ExplicitPressureSystem pressure =
        assemble_explicit_pressure(grid, w.pressure, dofs.pressure, dt, u_star);
    sys.A22 = pressure.A;
    sys.b2 = pressure.b;
  } else {
    sys.A12.resize(dofs.num_stress(), 0);
    sys.A22.resize(0, 0);
    sys.b2.resize(0);
  }
  // A = [A11 A12; A12^T A22]
  const int ns = dofs.num_stress(), n = dofs.size();
  t.clear();
  t.reserve(sys.A11.nonZeros() + 2 * sys.A12.nonZeros() + sys.A22.nonZeros());
  for (int i = 0; i < sys.A11.outerSize(); ++i)
    for (SparseMatrix::InnerIterator it(sys.A11, i); it; ++it)
      t.emplace_back(i, it.col(), it.value());
  for (int i = 0; i < sys.A12.outerSize(); ++i)
    for (SparseMatrix::InnerIterator it(sys.A12, i); it; ++it) {
      t.emplace_back(i, ns + it.col(), it.value());
      t.emplace_back(ns + it.col(), i, it.value());
    }
  for (int i = 0; i < sys.A22.outerSize(); ++i)
    for (SparseMatrix::InnerIterator it(sys.A22, i); it; ++it)
      t.emplace_back(ns + i, ns + it.col(), it.value());
  sys.A.resize(n, n);
  sys.A.setFromTriplets(t.begin(), t.end());
  sys.b.resize(n);
  sys.b << sys.b1, sys.b2;
  return sys;
}

// --- matrix-free back end -------------------------------------------------------------------

template <int Dim>
MatrixFreeStokesOperator<Dim>::MatrixFreeStokesOperator(const MacGrid<Dim>& grid,
                                                        const StressLayout<Dim>& layout,
                                                        const StokesWeights& w,
                                                        const StokesDofs& dofs, double dt)
    : size_(dofs.size()),
      num_faces_(grid.num_faces()),
      face_coefficient_(stokes_face_coefficients(w.pressure, dt)),
      fluid_face_(w.pressure.fluid_face),
      null_space_(dofs.null_space) {
  const StressGrid<Dim>& stress = layout.grid();
  const int ns = dofs.num_stress();
  // the stencils of D (rows) and G (columns): where each unknown acts on the faces
  const SparseMatrix D = deformation_rate_matrix(stress);
  const SparseMatrix Gt = SparseMatrix(gradient_matrix(grid).transpose());
  const VectorX m = stress_multiplicity(stress);
  unknown_start_.assign(1, 0);
  self_.setZero(size_);
  partner_.assign(size_, -1);
  partner_coef_.assign(size_, 0.0);
  std::vector<std::pair<int, double>> column;
  for (int i = 0; i < size_; ++i) {
    column.clear();
    if (i < ns) {
      // stress unknown: column of D^T M W_L^s E, and its 1/2 N^-1 W^s entries
      std::array<int, 2> dof;
      std::array<double, 2> sign;
      const int count = expansion_column(layout, dofs.unknown_of_dof[i], dof, sign);
      for (int c = 0; c < count; ++c) {
        const int d = dof[c];
        const double s = sign[c] * m[d] * w.liquid_stress[d];
        for (SparseMatrix::InnerIterator it(D, d); it; ++it)
          if (it.value() != 0.0) column.emplace_back(it.col(), s * it.value());
        const double x = 0.5 * m[d] * reciprocal_or_zero(w.viscosity[d]) * w.fluid_stress[d] *
                         w.liquid_stress[d];
        self_[i] += x;  // sign^2 = 1
      }
      if constexpr (Dim == 3) {
        // the other diagonal unknown of the cell shares the eliminated DOF: E^T X E couples them
        const int lu = dofs.unknown_of_dof[i];
        const int j = layout.component_of_unknown(lu);
        const int other = count == 2 ? dofs.dof_of_unknown[layout.offset(1 - j) + (lu - layout.offset(j))] : -1;
        if (other >= 0) {
          const int d = dof[1];
          partner_[i] = other;
          partner_coef_[i] = 0.5 * m[d] * reciprocal_or_zero(w.viscosity[d]) * w.fluid_stress[d] *
                             w.liquid_stress[d];
        }
      }
    } else {
      // pressure unknown: column of G W_L^p
      const int cell = dofs.pressure.cell_of_dof[i - ns];
      const double q = w.pressure.liquid_cell[cell];
      for (SparseMatrix::InnerIterator it(Gt, cell); it; ++it)
        if (it.value() != 0.0) column.emplace_back(it.col(), q * it.value());
    }
    // merge repeated faces (a periodic axis of one or two cells)
    std::sort(column.begin(), column.end());
    for (size_t c = 0; c < column.size(); ++c) {
      if (c > 0 && column[c].first == column[c - 1].first) {
        unknown_coef_.back() += column[c].second;
        continue;
      }
      unknown_face_.push_back(column[c].first);
      unknown_coef_.push_back(column[c].second);
    }
    unknown_start_.push_back(static_cast<int>(unknown_face_.size()));
  }
  // the transpose: unknowns per face, in increasing unknown order
  face_start_.assign(num_faces_ + 1, 0);
  for (int f : unknown_face_) ++face_start_[f + 1];
  for (int f = 0; f < num_faces_; ++f) face_start_[f + 1] += face_start_[f];
  face_unknown_.resize(unknown_face_.size());
  face_coef_.resize(unknown_face_.size());
  std::vector<int> fill(face_start_.begin(), face_start_.end() - 1);
  for (int i = 0; i < size_; ++i)
    for (int s = unknown_start_[i]; s < unknown_start_[i + 1]; ++s) {
      const int slot = fill[unknown_face_[s]]++;
      face_unknown_[slot] = i;
      face_coef_[slot] = unknown_coef_[s];
    }
  // diagonal: sum_f C_f B_fi^2 + the N part
  diagonal_ = self_;
  for (int i = 0; i < size_; ++i)
    for (int s = unknown_start_[i]; s < unknown_start_[i + 1]; ++s)
      diagonal_[i] += face_coefficient_[unknown_face_[s]] * unknown_coef_[s] * unknown_coef_[s];
  // colour groups: per unknown component (stress components, then pressure), red-black
  const int num_groups = 2 * (layout.num_components() + 1);
  groups_.assign(num_groups, {});
  for (int i = 0; i < size_; ++i) {
    int block = 0, parity = 0;
    if (i < ns) {
      const int lu = dofs.unknown_of_dof[i];
      const int j = layout.component_of_unknown(lu);
      block = j;
      parity = stress.coord(layout.dof_of_unknown(lu)).second.sum() % 2;
    } else {
      block = layout.num_components();
      parity = grid.cell_coord(dofs.pressure.cell_of_dof[i - ns]).sum() % 2;
    }
    groups_[2 * block + parity].push_back(i);
  }
  // an odd periodic axis couples a colour to itself: relax serially then
  for (int a = 0; a < Dim; ++a)
    if (grid.periodic(a) && grid.cells()[a] % 2 == 1 && grid.cells()[a] > 1)
      colouring_valid_ = false;
}

template <int Dim>
void MatrixFreeStokesOperator<Dim>::apply(const VectorX& x, VectorX& y) const {
  // face values v_f = C_f sum_j B_fj x_j (one writer per face)
  VectorX v(num_faces_);
#pragma omp parallel for schedule(static)
  for (int f = 0; f < num_faces_; ++f) {
    v[f] = face_coefficient_[f] != 0.0 ? face_coefficient_[f] * face_product(f, x) : 0.0;
  }
  // y_i = sum_f B_fi v_f + (1/2 N^-1 W^s x)_i (one writer per unknown)
  y.resize(size_);
#pragma omp parallel for schedule(static)
  for (int i = 0; i < size_; ++i) {
    double s = self_[i] * x[i];
    if (partner_[i] >= 0) s += partner_coef_[i] * x[partner_[i]];
    for (int e = unknown_start_[i]; e < unknown_start_[i + 1]; ++e)
      s += unknown_coef_[e] * v[unknown_face_[e]];
    y[i] = s;
  }
}

template <int Dim>
double MatrixFreeStokesOperator<Dim>::face_product(int f, const VectorX& x) const {
  // (B x)_f from the unknowns acting on face f
  double s = 0.0;
  for (int e = face_start_[f]; e < face_start_[f + 1]; ++e) s += face_coef_[e] * x[face_unknown_[e]];
  return s;
}

template <int Dim>
double MatrixFreeStokesOperator<Dim>::row_product(int i, const VectorX& x) const {
  // (A x)_i from the faces of unknown i only
  double s = self_[i] * x[i];
  if (partner_[i] >= 0) s += partner_coef_[i] * x[partner_[i]];
  for (int e = unknown_start_[i]; e < unknown_start_[i + 1]; ++e) {
    const int f = unknown_face_[e];
    if (face_coefficient_[f] == 0.0) continue;
    s += unknown_coef_[e] * face_coefficient_[f] * face_product(f, x);
  }
  return s;
}

template <int Dim>
void MatrixFreeStokesOperator<Dim>::forward_sweep(const VectorX& rhs, VectorX& x, double omega,
                                                  const std::vector<char>* active) const {
  // unknowns of one group share no face
  colour_sweep(groups_, colouring_valid_, false, diagonal_, rhs, x, omega, active,
               [&](int i) { return row_product(i, x) - diagonal_[i] * x[i]; });
}

template <int Dim>
void MatrixFreeStokesOperator<Dim>::backward_sweep(const VectorX& rhs, VectorX& x, double omega,
                                                   const std::vector<char>* active) const {
  colour_sweep(groups_, colouring_valid_, true, diagonal_, rhs, x, omega, active,
               [&](int i) { return row_product(i, x) - diagonal_[i] * x[i]; });
}

template <int Dim>
VectorX MatrixFreeStokesOperator<Dim>::face_force(const VectorX& x) const {
  VectorX force(num_faces_);
  // one writer per face: gather the unknowns acting on it
#pragma omp parallel for schedule(static)
  for (int f = 0; f < num_faces_; ++f) force[f] = face_product(f, x);
  return force;
}

template <int Dim>
std::vector<std::pair<int, double>> MatrixFreeStokesOperator<Dim>::stencil(int i) const {
  std::vector<std::pair<int, double>> column;
  for (int e = unknown_start_[i]; e < unknown_start_[i + 1]; ++e)
    column.emplace_back(unknown_face_[e], unknown_coef_[e]);
  return column;
}

template <int Dim>
VectorX MatrixFreeStokesOperator<Dim>::rhs(const VectorX& u_star) const {
  VectorX b(size_);
#pragma omp parallel for schedule(static)
  for (int i = 0; i < size_; ++i) {
    double s = 0.0;
    for (int e = unknown_start_[i]; e < unknown_start_[i + 1]; ++e) {
      const int f = unknown_face_[e];
      s += unknown_coef_[e] * fluid_face_[f] * u_star[f];
    }
    b[i] = s;
  }
  return b;
}

// --- update, scatter, energy, solve ---------------------------------------------------------

template <int Dim>
void apply_stokes_update(const MacGrid<Dim>& grid, const StressLayout<Dim>& layout,
                         const StokesWeights& w, double dt, const VectorX& pressure_cells,
                         const VectorX& tau_full, VectorX& u) {
  const StressGrid<Dim>& stress = layout.grid();
  // force per face: G W_L^p p + D^T M W_L^s tau
  VectorX force = VectorX::Zero(grid.num_faces());
  if (pressure_cells.size() > 0)
    force += apply_gradient(grid, VectorX(w.pressure.liquid_cell.cwiseProduct(pressure_cells)));
  if (tau_full.size() > 0) {
    const SparseMatrix D = deformation_rate_matrix(stress);
    const VectorX s = stress_multiplicity(stress).cwiseProduct(w.liquid_stress).cwiseProduct(tau_full);
    force += D.transpose() * s;
  }
  const PressureWeights& pw = w.pressure;
#pragma omp parallel for schedule(static)
  for (int f = 0; f < grid.num_faces(); ++f) {
    if (!(pw.fluid_face[f] * pw.liquid_face[f] > 0.0) || !(pw.face_density[f] > 0.0)) continue;
    u[f] -= dt * force[f] / (pw.face_density[f] * pw.liquid_face[f]);
  }
}

template <int Dim>
VectorX scatter_stress(const StressLayout<Dim>& layout, const StokesDofs& dofs, const VectorX& x) {
  VectorX tau = VectorX::Zero(layout.num_unknowns());
  for (int k = 0; k < dofs.num_stress(); ++k) tau[dofs.unknown_of_dof[k]] = x[k];
  return layout.expand(tau);
}

VectorX scatter_stokes_pressure(const StokesDofs& dofs, const VectorX& x, int num_cells) {
  VectorX p = VectorX::Zero(num_cells);
  for (int k = 0; k < dofs.num_pressure(); ++k)
    p[dofs.pressure.cell_of_dof[k]] = x[dofs.num_stress() + k];
  return p;
}

template <int Dim>
double stokes_energy(const MacGrid<Dim>& grid, const StressLayout<Dim>& layout,
                     const StokesWeights& w, const StokesDofs& dofs, double dt,
                     const VectorX& u_star, const VectorX& x) {
  const StressGrid<Dim>& stress = layout.grid();
  const VectorX tau = scatter_stress(layout, dofs, x);
  const VectorX p = scatter_stokes_pressure(dofs, x, grid.num_cells());
  VectorX u = u_star;
  apply_stokes_update(grid, layout, w, dt, p, tau, u);
  // kinetic part over P W_F^u W_L^u
  const PressureWeights& pw = w.pressure;
  double kinetic = 0.0;
  for (int f = 0; f < grid.num_faces(); ++f)
    kinetic += pw.face_density[f] * pw.fluid_face[f] * pw.liquid_face[f] * u[f] * u[f];
  // stress part dt/4 tau^T N^-1 W^s tau, N^-1 = M / eta
  const VectorX m = stress_multiplicity(stress);
  double viscous = 0.0;
  for (int d = 0; d < stress.num_dofs(); ++d)
    viscous += m[d] * reciprocal_or_zero(w.viscosity[d]) * w.fluid_stress[d] * w.liquid_stress[d] *
               tau[d] * tau[d];
  return 0.5 * kinetic + 0.25 * dt * viscous;
}

template <int Dim>
StokesSolveResult solve_stokes(const MacGrid<Dim>& grid, const StokesWeights& w, double dt,
                               StokesUnknowns unknowns, StressForm form,
                               const std::string& backend, const PcgSettings& settings,
                               VectorX& u) {
  StokesSolveResult result;
  const StressLayout<Dim> layout(StressGrid<Dim>(grid), form);
  // line 7: active DOFs
  const StokesDofs dofs = select_stokes_dofs(grid, layout, w, dt, unknowns);
  result.stress_dofs = dofs.num_stress();
  result.pressure_dofs = dofs.num_pressure();
  VectorX x = VectorX::Zero(dofs.size());
  // lines 8-10: assemble (or set up the stencils) and solve
  if (backend == "explicit") {
    const ExplicitStokesSystem sys = assemble_explicit_stokes(grid, layout, w, dofs, dt, u);
    const SparseMatrixOperator op(sys.A, dofs.null_space);
    result.pcg = pcg_solve(op, sys.b, x, settings);
  } else if (backend == "matrixfree") {
    const MatrixFreeStokesOperator<Dim> op(grid, layout, w, dofs, dt);
    result.pcg = pcg_solve(op, op.rhs(u), x, settings);
  } else {
    throw std::invalid_argument("solve_stokes: unknown backend '" + backend +
                                "' (explicit, matrixfree)");
  }
  // line 11: velocity update
  result.stress = scatter_stress(layout, dofs, x);
  result.pressure = scatter_stokes_pressure(dofs, x, grid.num_cells());
  apply_stokes_update(grid, layout, w, dt, result.pressure, result.stress, u);
  return result;
}

template <int Dim>
StokesWeights uniform_stokes_weights(const MacGrid<Dim>& grid, const VectorX& solid_phi,
                                     const VectorX& liquid_phi,
                                     const std::array<BoundaryType, 2 * Dim>& boundary,
                                     double rho, double eta) {
  const SampleLattice<Dim> lattice = half_lattice(grid);
  const StressGrid<Dim> stress(grid);
  StokesWeights w;
  w.pressure.fluid_face = fluid_face_weights(grid, lattice, solid_phi, boundary);
  w.pressure.liquid_cell = liquid_cell_weights(grid, lattice, liquid_phi);
  w.pressure.liquid_face = liquid_face_weights(grid, lattice, liquid_phi, w.pressure.liquid_cell);
  w.pressure.face_density = VectorX::Constant(grid.num_faces(), rho);
  w.fluid_stress = stress_fluid_weights(stress, lattice, solid_phi, boundary);
  w.liquid_stress = stress_liquid_weights(stress, lattice, liquid_phi);
  w.viscosity = VectorX::Constant(stress.num_dofs(), eta);
  return w;
}

#define MONOLITH_INSTANTIATE(D)                                                                  \
  template StokesWeights uniform_stokes_weights<D>(const MacGrid<D>&, const VectorX&,            \
                                                   const VectorX&,                               \
                                                   const std::array<BoundaryType, 2 * D>&,       \
                                                   double, double);                              \
  template StokesDofs select_stokes_dofs<D>(const MacGrid<D>&, const StressLayout<D>&,           \
                                            const StokesWeights&, double, StokesUnknowns);       \
  template ExplicitStokesSystem assemble_explicit_stokes<D>(const MacGrid<D>&,                   \
                                                            const StressLayout<D>&,              \
                                                            const StokesWeights&,                \
                                                            const StokesDofs&, double,           \
                                                            const VectorX&);                     \
  template class MatrixFreeStokesOperator<D>;                                                    \
  template void apply_stokes_update<D>(const MacGrid<D>&, const StressLayout<D>&,                \
                                       const StokesWeights&, double, const VectorX&,             \
                                       const VectorX&, VectorX&);                                \
  template VectorX scatter_stress<D>(const StressLayout<D>&, const StokesDofs&, const VectorX&); \
  template double stokes_energy<D>(const MacGrid<D>&, const StressLayout<D>&,                    \
                                   const StokesWeights&, const StokesDofs&, double,              \
                                   const VectorX&, const VectorX&);                              \
  template StokesSolveResult solve_stokes<D>(const MacGrid<D>&, const StokesWeights&, double,    \
                                             StokesUnknowns, StressForm, const std::string&,     \
                                             const PcgSettings&, VectorX&);
MONOLITH_INSTANTIATE(2)
MONOLITH_INSTANTIATE(3)
#undef MONOLITH_INSTANTIATE

}  // namespace monolith
