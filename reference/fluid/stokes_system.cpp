#include "reference/fluid/stokes_system.hpp"

#include <algorithm>
#include <cstddef>
#include <stdexcept>
#include <type_traits>

#include "reference/core/parallel.hpp"
#include "reference/fluid/deformation_rate.hpp"
#include "reference/fluid/gradient.hpp"
#include "reference/grid/box_rows.hpp"
#include "reference/grid/stress_weights.hpp"
#include "reference/grid/volume_fractions.hpp"

namespace monolith {

namespace {

/// C_f = dt W_F^u P^-1 (W_L^u)^-1 of face f (0 where the face carries no fluid, liquid or
/// density).
inline double stokes_face_coefficient(const PressureWeights& w, int f, double dt) {
  return w.fluid_face[f] > 0.0 && w.face_density[f] > 0.0
             ? dt * w.fluid_face[f] * reciprocal_or_zero(w.liquid_face[f]) / w.face_density[f]
             : 0.0;
}

/// Whether MonolithicSystem::fluid_velocities_into updates face f (W_F^u W_L^u > 0 and a
/// density; u* elsewhere): the same test as there.
inline bool stokes_face_updated(const PressureWeights& w, int f) {
  return w.fluid_face[f] * w.liquid_face[f] > 0.0 && w.face_density[f] > 0.0;
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

/// `v`, or when it is empty (the stress vectors of inviscid weights, StokesWeights) zeros of
/// size n in `zeros`.
const VectorX& or_zeros(const VectorX& v, int n, VectorX& zeros) {
  if (v.size() > 0) return v;
  zeros.setZero(n);
  return zeros;
}

}  // namespace

// --- DOF selection --------------------------------------------------------------------------

template <int Dim>
StokesDofs select_stokes_dofs(const MacGrid<Dim>& grid, const StressLayout<Dim>& layout,
                              const StokesWeights& w, double dt, StokesUnknowns unknowns,
                              const LiquidBand* band) {
  StokesDofs dofs;
  // stress: W^s > 0 and eta > 0 on every StressGrid DOF the unknown stands for (none when the
  // weights are inviscid: eta = 0 everywhere)
  // (the active unknowns listed on several threads, each over a contiguous block, the lists
  // joined in block order: the increasing list of the serial loop; then the inverse map)
  if (!w.inviscid()) {
    dofs.unknown_of_dof = gather_in_order<int>(layout.num_unknowns(), [&](int i, std::vector<int>& out) {
      std::array<int, 2> dof;
      std::array<double, 2> sign;
      const int count = expansion_column(layout, i, dof, sign);
      bool active = true;
      for (int m = 0; m < count; ++m) {
        const int d = dof[m];
        active = active && w.fluid_stress[d] * w.liquid_stress[d] > 0.0 && w.viscosity[d] > 0.0;
      }
      if (active) out.push_back(i);
    });
    if (dofs.num_stress() > 0) {
      dofs.dof_of_unknown.assign(layout.num_unknowns(), -1);
      const int ns = dofs.num_stress();
#pragma omp parallel for schedule(static) num_threads(team_threads(ns))
      for (int k = 0; k < ns; ++k) dofs.dof_of_unknown[dofs.unknown_of_dof[k]] = k;
    }
  }
  // without active stress DOFs the map is all -1: not kept (its readers visit stress unknowns)
  if (dofs.num_stress() == 0) std::vector<int>().swap(dofs.dof_of_unknown);
  // pressure: the DOFs of the pressure solve
  if (unknowns == StokesUnknowns::pressure_and_stress)
    dofs.pressure = select_pressure_dofs(grid, w.pressure, dt, band);
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
  // inviscid weights may come without their stress vectors: zeros here
  VectorX zeros_f, zeros_l, zeros_eta;
  const VectorX& fluid_stress = or_zeros(w.fluid_stress, stress.num_dofs(), zeros_f);
  const VectorX& liquid_stress = or_zeros(w.liquid_stress, stress.num_dofs(), zeros_l);
  const VectorX& viscosity = or_zeros(w.viscosity, stress.num_dofs(), zeros_eta);
  ExplicitStokesSystem sys;
  // the named matrices of eq. (8)
  sys.G = gradient_matrix(grid);
  sys.D = deformation_rate_matrix(stress);
  sys.M = sparse_diagonal(stress_multiplicity(stress));
  sys.N_inv = inverse_viscosity_matrix(layout, viscosity);
  sys.W_F_u = sparse_diagonal(w.pressure.fluid_face);
  sys.W_L_u_inv = sparse_diagonal(w.pressure.liquid_face.unaryExpr(&reciprocal_or_zero));
  sys.P_inv = sparse_diagonal(w.pressure.face_density.unaryExpr(&reciprocal_or_zero));
  sys.W_L_p = sparse_diagonal(w.pressure.liquid_cell);
  sys.W_F_s = sparse_diagonal(fluid_stress);
  sys.W_L_s = sparse_diagonal(liquid_stress);
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
      sys.M * sparse_diagonal(viscosity.unaryExpr(&reciprocal_or_zero));
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

namespace {

/// Below this many grid entries the matrix-free loops run on one thread: a parallel region
/// costs more than it saves on small grids (and much more on an oversubscribed machine).
constexpr int kParallelMin = static_cast<int>(kParallelMinWork);

/// out = sum over `terms` of coef * in_field(c + delta e_axis) for every entry c of the field
/// `of` (zero where an input lies outside the domain, wrapped on periodic axes), then times
/// scale entrywise if given. Shares the rows along axis 0 of `of` among the threads of the
/// enclosing parallel region (omp for, no barrier at the end): each row has one writer, and
/// every entry sums its terms in the same order, whatever the thread count. With `spans`
/// (parallel to row_list) only the entries [first, second) of each row are computed, with the
/// bits the whole row's pass gives them; the others are left as they are (box26).
template <int Dim, class FieldT, class TermT, std::size_t N>
void stencil_rows(const FieldT& of, double* out, const std::vector<TermT>& terms,
                  const std::array<FieldT, N>& fields, const std::array<const double*, N>& data,
                  const std::array<bool, Dim>& periodic, const double* scale,
                  const std::vector<int>* row_list,
                  const std::vector<std::pair<int, int>>* spans = nullptr) {
  const int n0 = of.dims[0];
  int rows = 1;
  for (int a = 1; a < Dim; ++a) rows *= of.dims[a];
  // every row, or only those of row_list
  const int count = row_list ? static_cast<int>(row_list->size()) : rows;
#pragma omp for schedule(dynamic, dynamic_chunk(count)) nowait
  for (int m = 0; m < count; ++m) {
    const int r = row_list ? (*row_list)[m] : m;
    // the row's coordinates along axes 1..Dim-1
    VecI<Dim> c = VecI<Dim>::Zero();
    int rest = r;
    for (int a = 1; a < Dim; ++a) {
      c[a] = rest % of.dims[a];
      rest /= of.dims[a];
    }
    double* o = out + of.offset + static_cast<std::ptrdiff_t>(r) * n0;
    // the entries computed: the row's span, or all of it
    const int x_lo = spans ? (*spans)[m].first : 0, x_hi = spans ? (*spans)[m].second : n0;
    for (int x = x_lo; x < x_hi; ++x) o[x] = 0.0;
    for (const TermT& t : terms) {
      // the input row: shifted along axes 1.., wrapped on periodic axes, or outside
      const FieldT& f = fields[t.field];
      int row = 0;
      bool inside = true;
      for (int a = Dim - 1; a >= 1 && inside; --a) {
        int v = c[a] + (t.axis == a ? t.delta : 0);
        if (v < 0 || v >= f.dims[a]) {
          inside = periodic[a];
          v = ((v % f.dims[a]) + f.dims[a]) % f.dims[a];
        }
        row = row * f.dims[a] + v;
      }
      if (!inside) continue;
      // along axis 0: a contiguous interior, then the ends (wrapped or outside)
      const int m0 = f.dims[0];
      const double* in = data[t.field] + f.offset + static_cast<std::ptrdiff_t>(row) * m0;
      const int shift = t.axis == 0 ? t.delta : 0;
      const double coef = t.coef;
      const int lo = std::max(x_lo, -shift), hi = std::min(x_hi, m0 - shift);
      for (int x = lo; x < hi; ++x) o[x] += coef * in[x + shift];
      if (periodic[0]) {
        for (int x = x_lo; x < std::min(lo, x_hi); ++x) o[x] += coef * in[((x + shift) % m0 + m0) % m0];
        for (int x = std::max(hi, lo); x < x_hi; ++x) o[x] += coef * in[((x + shift) % m0 + m0) % m0];
      }
    }
    if (scale) {
      const double* sc = scale + of.offset + static_cast<std::ptrdiff_t>(r) * n0;
      for (int x = x_lo; x < x_hi; ++x) o[x] *= sc[x];
    }
  }
}

/// Index of the first entry (coordinate 0 along axis 0) of the row of field f at the row
/// coordinates of c (axes 1..Dim-1) shifted by delta along `axis` (no shift for axis 0), wrapped
/// on periodic axes; -1 if the row lies outside the domain.
template <int Dim, class FieldT>
int row_start(const FieldT& f, const VecI<Dim>& c, int axis, int delta,
              const std::array<bool, Dim>& periodic) {
  int row = 0;
  for (int a = Dim - 1; a >= 1; --a) {
    int v = c[a] + (axis == a ? delta : 0);
    if (v < 0 || v >= f.dims[a]) {
      if (!periodic[a]) return -1;
      v = ((v % f.dims[a]) + f.dims[a]) % f.dims[a];
    }
    row = row * f.dims[a] + v;
  }
  return f.offset + row * f.dims[0];
}

}  // namespace

template <int Dim>
MatrixFreeStokesOperator<Dim>::MatrixFreeStokesOperator(const MacGrid<Dim>& grid,
                                                        const StressLayout<Dim>& layout,
                                                        const StokesWeights& w,
                                                        const StokesDofs& dofs, double dt,
                                                        StokesWorkspace* workspace)
    : periodic_(grid.periodic()),
      eliminated_(layout.eliminated_component()),
      size_(dofs.size()),
      num_stress_(dofs.num_stress()),
      num_faces_(grid.num_faces()),
      num_stress_dofs_(layout.grid().num_dofs()),
      num_cells_(grid.num_cells()),
      has_pressure_(dofs.num_pressure() > 0),
      fluid_face_(&w.pressure.fluid_face),
      pressure_weights_(&w.pressure),
      null_space_(dofs.null_space) {
  const StressGrid<Dim>& stress = layout.grid();
  const double inv_dx = 1.0 / grid.dx();
  // the lattice blocks: faces per axis, stress components, cells
  for (int a = 0; a < Dim; ++a) fields_[a] = {grid.face_offset(a), grid.face_dims(a)};
  for (int k = 0; k < kComponents; ++k) fields_[Dim + k] = {stress.offset(k), stress.dims(k)};
  fields_[kCellField] = {0, grid.cells()};
  // C_f per face, face row by face row on several threads (each row one writer, the same value
  // per face), with per row whether some C_f != 0 (the face rows the loops visit, below) and
  // whether some face is updated by the velocity update (updated_rows_): one pass over the
  // faces instead of a serial one and a second read of C (issue 20)
  //
  // The face-, cell- and stress-sized vectors: borrowed from the workspace (zero, or -1 for the
  // maps, except where the last operator wrote; that part reset here), else made here (issue
  // 20, docs/preconditioners.md section 39)
  if (workspace && workspace->keep && !workspace->lent) {
    workspace_ = workspace;
    workspace->lent = true;
    ++workspace->reused;
  } else if (workspace && workspace->keep) {
    ++workspace->refused;
  }
  // With the workspace's band, C_f is computed on the face rows that cross the band's face box
  // of their axis only: W_L^u = 0 outside it, so C_f = +0 there, the value the vector holds
  const LiquidBand* band = workspace && workspace->band.valid ? &workspace->band : nullptr;
  if (workspace_) {
    // (without a band every face is written below: no entry needs a reset)
    if (!band) workspace_->face_coefficient.dirty.clear();
    workspace_->face_coefficient.lend(num_faces_, face_coefficient_);
  }
  else if (band)
    face_coefficient_.setZero(num_faces_);
  else
    face_coefficient_.resize(num_faces_);
  std::array<std::vector<char>, Dim> face_row_used;
  // the passes visit whole rows on a periodic axis 0 (their wrapped reads) and under the test
  // switch (the former passes, for the tests' comparison)
  const bool whole_rows = periodic_[0] || stokes_operator_every_face_row();
  // per face row, the span of its faces with C_f != 0 (box26)
  std::array<std::vector<std::pair<int, int>>, Dim> face_row_span;
  for (int a = 0; a < Dim; ++a) {
    const Field& f = fields_[a];
    const int n0 = f.dims[0], rows = f.dims.prod() / std::max(n0, 1);
    face_row_used[a].assign(rows, 0);
    face_row_span[a].assign(rows, {0, 0});
    std::vector<char> updated(rows, 0);
    std::vector<std::pair<int, int>> updated_span(rows, {0, 0});
    // the rows computed: all, or those of the band's box (increasing)
    std::vector<int> band_rows;
    if (band) {
      VecI<Dim> lo = VecI<Dim>::Zero(), hi = VecI<Dim>::Zero();
      bool empty = false;
      for (int d = 1; d < Dim; ++d) {
        lo[d] = std::max(band->face_lo[a][d], 0);
        hi[d] = std::min(band->face_hi[a][d], f.dims[d] - 1);
        empty = empty || lo[d] > hi[d];
      }
      empty = empty || band->face_lo[a][0] > band->face_hi[a][0];
      if (!empty) {
        const VecI<Dim> box = hi - lo + VecI<Dim>::Ones();
        VecI<Dim> row_dims = f.dims;
        row_dims[0] = 1;
        band_rows.reserve(box.prod());
        for (int j = 0; j < box.prod(); ++j)
          band_rows.push_back(lattice_index<Dim>(lo + lattice_coord<Dim>(j, box), row_dims));
      }
    }
    const int count = band ? static_cast<int>(band_rows.size()) : rows;
#pragma omp parallel for schedule(static) num_threads(team_threads(static_cast<long>(count) * n0))
    for (int m = 0; m < count; ++m) {
      const int r = band ? band_rows[m] : m;
      bool used = false, update = false;
      int first = n0, last = -1, first_updated = n0, last_updated = -1;
      for (int e = f.offset + r * n0; e < f.offset + (r + 1) * n0; ++e) {
        const double c = stokes_face_coefficient(w.pressure, e, dt);
        face_coefficient_[e] = c;
        const int x = e - f.offset - r * n0;
        if (c != 0.0) {
          first = std::min(first, x);
          last = x;
        }
        used = used || c != 0.0;
        if (stokes_face_updated(w.pressure, e)) {
          update = true;
          first_updated = std::min(first_updated, x);
          last_updated = x;
        }
      }
      face_row_used[a][r] = used;
      face_row_span[a][r] = {first, last + 1};
      updated[r] = update;
      updated_span[r] = {first_updated, last_updated + 1};
    }
    // the spans written, for the workspace (consecutive rows merged)
    for (int m = 0; m < count; ++m) {
      const long begin = f.offset + static_cast<long>(band ? band_rows[m] : m) * n0;
      if (!coefficient_spans_.empty() && coefficient_spans_.back().second == begin)
        coefficient_spans_.back().second = begin + n0;
      else
        coefficient_spans_.emplace_back(begin, begin + n0);
    }
    for (int r = 0; r < rows; ++r)
      if (updated[r]) {
        updated_rows_[a].push_back(r);
        updated_spans_[a].push_back(whole_rows ? std::pair<int, int>(0, n0) : updated_span[r]);
      }
  }
  for (int j = 0; j < layout.num_components(); ++j) layout_field_.push_back(Dim + layout.component(j));
  // B^T per grid DOF: the rows of D (eq. (8)) and of G^T, +-1/dx on faces around the DOF
  for (int k = 0; k < kComponents; ++k) {
    const auto [a, b] = StressGrid<Dim>::component_axes(k);
    std::vector<Term>& t = terms_[Dim + k];
    if (a == b) {
      // diagonal: du_a/da across the cell
      t.push_back({a, a, 1, inv_dx});
      t.push_back({a, a, 0, -inv_dx});
    } else {
      // off-diagonal: 1/2 (du_a/db + du_b/da) from the four faces around the node/edge
      t.push_back({a, a, 0, 0.5 * inv_dx});
      t.push_back({a, b, -1, -0.5 * inv_dx});
      t.push_back({b, b, 0, 0.5 * inv_dx});
      t.push_back({b, a, -1, -0.5 * inv_dx});
    }
  }
  if (has_pressure_)
    for (int a = 0; a < Dim; ++a) {
      // G^T: the cell is the plus cell of its lower face and the minus cell of its upper face
      terms_[kCellField].push_back({a, a, 0, inv_dx});
      terms_[kCellField].push_back({a, a, 1, -inv_dx});
    }
  // B per face: the transpose of those stencils (a DOF at c reaching face c + delta e_axis is
  // reached from the face at -delta), the same entries on every boundary and periodic axis.
  // Without stress unknowns the stress terms are left out: s is zero there, and its terms come
  // first in every face's sum, so they only added signed zeros to the sum's +0 start (no bit of
  // B x changes), and the operator then keeps no stress-sized vector at all
  for (int field = num_stress_ > 0 ? Dim : kCellField; field < kFields; ++field)
    for (const Term& t : terms_[field]) terms_[t.field].push_back({field, t.axis, -t.delta, t.coef});

  // grid -> unknown maps, per unknown weights and 1/2 N^-1 W^s; M per DOF from its component
  // (stress_multiplicity's values without its stress-sized vector)
  auto m_of = [&](int d) { return StressGrid<Dim>::multiplicity(stress.coord(d).first); };
  auto half_n_inv_ws_m = [&](int d, double m) {
    return 0.5 * m * reciprocal_or_zero(w.viscosity[d]) * w.fluid_stress[d] * w.liquid_stress[d];
  };
  auto half_n_inv_ws = [&](int d) { return half_n_inv_ws_m(d, m_of(d)); };
  // (the StressGrid-sized maps and scratch only with stress unknowns: an inviscid operator
  // keeps none, and its weights may come without stress vectors, StokesWeights)
  if (num_stress_ > 0) {
    if (workspace_)
      workspace_->unknown_of_dof.lend(num_stress_dofs_, unknown_of_dof_);
    else
      unknown_of_dof_.assign(num_stress_dofs_, -1);
  }
  if (workspace_)
    workspace_->unknown_of_cell.lend(num_cells_, unknown_of_cell_);
  else
    unknown_of_cell_.setZero(num_cells_);
  location_.resize(size_);
  weight_.resize(size_);
  self_.setZero(size_);
  // (per unknown: one writer of each entry, and of the maps' entry at its distinct DOF or cell)
#pragma omp parallel for schedule(static) num_threads(team_threads(size_))
  for (int i = 0; i < num_stress_; ++i) {
    const int d = layout.dof_of_unknown(dofs.unknown_of_dof[i]);
    const int k = stress.coord(d).first;
    unknown_of_dof_[d] = i;
    location_[i] = d;
    weight_[i] = StressGrid<Dim>::multiplicity(k) * w.liquid_stress[d];
    self_[i] = half_n_inv_ws(d);
    // reduced form: E adds the eliminated DOF of the cell with sign -1 (sign^2 = 1 here)
    if (eliminated_ >= 0 && StressGrid<Dim>::is_diagonal(k))
      self_[i] += half_n_inv_ws(stress.offset(eliminated_) + d - stress.offset(k));
  }
#pragma omp parallel for schedule(static) num_threads(team_threads(size_))
  for (int k = 0; k < dofs.num_pressure(); ++k) {
    const int i = num_stress_ + k, cell = dofs.pressure.cell_of_dof[k];
    unknown_of_cell_[cell] = i + 1;
    location_[i] = cell;
    weight_[i] = w.pressure.liquid_cell[cell];
  }
  if (eliminated_ >= 0 && num_stress_ > 0) {
    // the eliminated DOF of each cell: its -M W_L^s and (3D, where it couples the two diagonal
    // unknowns of the cell through E^T N^-1 E) its 1/2 N^-1 W^s
    eliminated_weight_.resize(num_cells_);
    if constexpr (Dim == 3) eliminated_coupling_.resize(num_cells_);
    const double m = StressGrid<Dim>::multiplicity(eliminated_);
#pragma omp parallel for schedule(static) num_threads(team_threads(num_cells_))
    for (int c = 0; c < num_cells_; ++c) {
      const int d = stress.offset(eliminated_) + c;
      eliminated_weight_[c] = -m * w.liquid_stress[d];
      if constexpr (Dim == 3) eliminated_coupling_[c] = half_n_inv_ws_m(d, m);
    }
  }
  // diagonal: 1/2 N^-1 W^s plus sum_f C_f B_fi^2 over the merged column of B
  diagonal_ = self_;
#pragma omp parallel for schedule(static) num_threads(team_threads(size_))
  for (int i = 0; i < size_; ++i)
    for (const auto& [f, b] : stencil(i)) diagonal_[i] += face_coefficient_[f] * b * b;
  // an odd periodic axis couples a colour to itself: relax serially then
  for (int a = 0; a < Dim; ++a)
    if (grid.periodic(a) && grid.cells()[a] % 2 == 1 && grid.cells()[a] > 1)
      colouring_valid_ = false;
  // the rows the loops visit: face rows with fluid, stress and cell rows with unknowns (the
  // eliminated component: rows of cells with an unknown of a diagonal component 0..Dim-2), found
  // from the unknowns' locations (a row is visited iff it holds one), in increasing order: the
  // rows a scan of the maps over the grid finds, in time proportional to the unknowns and rows
  //
  // With each row its span along axis 0 (box26): the faces with C_f != 0, the entries with an
  // unknown (the eliminated component: the cells with a diagonal unknown); the whole row on a
  // periodic axis 0 (the passes' wrapped reads are then not confined to a span)
  for (int a = 0; a < Dim; ++a)
    for (int r = 0; r < static_cast<int>(face_row_used[a].size()); ++r)
      if (face_row_used[a][r]) {
        active_rows_[a].push_back(r);
        active_spans_[a].push_back(whole_rows ? std::pair<int, int>(0, fields_[a].dims[0])
                                                : face_row_span[a][r]);
      }
  {
    std::array<std::vector<char>, kFields> row_used;
    std::array<std::vector<std::pair<int, int>>, kFields> row_span;
    for (int field = Dim; field < kFields; ++field) {
      if (num_stress_ == 0 && field < kCellField) continue;
      const Field& f = fields_[field];
      row_used[field].assign(f.dims.prod() / std::max(f.dims[0], 1), 0);
      row_span[field].assign(row_used[field].size(), {f.dims[0], 0});
    }
    const auto use = [&](int field, int e) {
      const int n0 = fields_[field].dims[0], r = e / n0, x = e - r * n0;
      row_used[field][r] = 1;
      std::pair<int, int>& span = row_span[field][r];
      span.first = std::min(span.first, x);
      span.second = std::max(span.second, x + 1);
    };
    for (int i = 0; i < num_stress_; ++i) {
      const int d = location_[i];
      const int k = stress.coord(d).first;
      const int e = d - fields_[Dim + k].offset;
      use(Dim + k, e);
      if (eliminated_ >= 0 && k < Dim - 1) use(Dim + eliminated_, e);
    }
    for (int k = 0; k < dofs.num_pressure(); ++k) use(kCellField, dofs.pressure.cell_of_dof[k]);
    for (int field = Dim; field < kFields; ++field)
      for (int r = 0; r < static_cast<int>(row_used[field].size()); ++r)
        if (row_used[field][r]) {
          active_rows_[field].push_back(r);
          active_spans_[field].push_back(
              whole_rows ? std::pair<int, int>(0, fields_[field].dims[0]) : row_span[field][r]);
        }
  }
  for (int field = 0; field < kFields; ++field)
    active_work_ += static_cast<long>(active_rows_[field].size()) * fields_[field].dims[0];
  // the face rows grid_from_faces reads: the input rows of the stencils of the stress and cell
  // rows it visits (stencil_rows' row arithmetic), for rhs
  {
    std::array<std::vector<char>, Dim> read;
    for (int a = 0; a < Dim; ++a)
      read[a].assign(fields_[a].dims.prod() / std::max(fields_[a].dims[0], 1), 0);
    std::vector<int> visited(layout_field_);
    if (eliminated_ >= 0) visited.push_back(Dim + eliminated_);
    if (has_pressure_) visited.push_back(kCellField);
    for (int field : visited)
      for (int r : active_rows_[field]) {
        VecI<Dim> c = VecI<Dim>::Zero();
        int rest = r;
        for (int a = 1; a < Dim; ++a) {
          c[a] = rest % fields_[field].dims[a];
          rest /= fields_[field].dims[a];
        }
        for (const Term& t : terms_[field]) {
          // the input row of the term (stencil_rows: shifted along axes 1.., wrapped on
          // periodic axes, or outside)
          const VecI<Dim>& dims = fields_[t.field].dims;
          int row = 0;
          bool inside = true;
          for (int a = Dim - 1; a >= 1 && inside; --a) {
            int v = c[a] + (t.axis == a ? t.delta : 0);
            if (v < 0 || v >= dims[a]) {
              inside = periodic_[a];
              v = ((v % dims[a]) + dims[a]) % dims[a];
            }
            row = row * dims[a] + v;
          }
          if (inside) read[t.field][row] = 1;
        }
      }
    for (int a = 0; a < Dim; ++a)
      for (int r = 0; r < static_cast<int>(read[a].size()); ++r)
        if (read[a][r]) read_face_rows_[a].push_back(r);
  }
  if (num_stress_ > 0) {
    if (workspace_)
      workspace_->stress_scratch.lend(num_stress_dofs_, stress_scratch_);
    else
      stress_scratch_.setZero(num_stress_dofs_);
  }
  if (workspace_)
    workspace_->cell_scratch.lend(num_cells_, cell_scratch_);
  else
    cell_scratch_.setZero(num_cells_);
  // the face scratch: zero on the rows any pass reads or writes (the active rows: apply's
  // faces_from_grid and the sweeps, which touch only faces with C_f != 0; the rows
  // grid_from_faces reads: apply and rhs), never touched elsewhere (uninitialised: a fresh
  // allocation's pages there are not even mapped; issue 20, 200 MB at Fig. 2's paper grid).
  // Not kept in the workspace (band18): its values are never reused, so keeping it saves no
  // pass; made here, it takes heap memory the step has freed (the liquid level set's block,
  // released before the solve), and given back in the destructor it leaves that block whole
  // for the next step's level set, instead of lying beside it at the step's peak (202 MB)
  face_scratch_.resize(num_faces_);
  for (int a = 0; a < Dim; ++a) {
    const Field& f = fields_[a];
    const int n0 = f.dims[0];
    for (const std::vector<int>* rows : {&active_rows_[a], &read_face_rows_[a]})
      for (int r : *rows)
        std::fill(face_scratch_.data() + f.offset + static_cast<std::ptrdiff_t>(r) * n0,
                  face_scratch_.data() + f.offset + static_cast<std::ptrdiff_t>(r + 1) * n0, 0.0);
  }
}

template <int Dim>
MatrixFreeStokesOperator<Dim>::~MatrixFreeStokesOperator() {
  if (!workspace_) return;
  // the storage back to the workspace, with the entries this operator may have left non-zero
  // (not -1): C_f on the spans it computed, the maps at its unknowns' DOFs and cells, the stress
  // and cell scratch on the rows the passes write (the active rows of their fields: scatter,
  // grid_from_faces) (the face scratch is not kept: freed with the operator)
  StokesWorkspace& w = *workspace_;
  w.face_coefficient.values.swap(face_coefficient_);
  w.face_coefficient.dirty = std::move(coefficient_spans_);
  auto give_rows = [&](KeptZeros& kept, VectorX& v, int first_field, int last_field) {
    kept.values.swap(v);
    kept.dirty.clear();
    for (int field = first_field; field <= last_field; ++field) {
      const Field& f = fields_[field];
      for (int r : active_rows_[field]) {
        const long begin = f.offset + static_cast<long>(r) * f.dims[0];
        kept.dirty.emplace_back(begin, begin + f.dims[0]);
      }
    }
  };
  if (num_stress_ > 0) {
    give_rows(w.stress_scratch, stress_scratch_, Dim, kCellField - 1);
    w.unknown_of_dof.values.swap(unknown_of_dof_);
    w.unknown_of_dof.dirty.assign(location_.begin(), location_.begin() + num_stress_);
  }
  give_rows(w.cell_scratch, cell_scratch_, kCellField, kCellField);
  w.unknown_of_cell.values.swap(unknown_of_cell_);
  w.unknown_of_cell.dirty.assign(location_.begin() + num_stress_, location_.end());
  w.lent = false;
}

template <int Dim>
int MatrixFreeStokesOperator<Dim>::index_or_outside(int field, VecI<Dim> c, int axis,
                                                    int delta) const {
  const Field& f = fields_[field];
  c[axis] += delta;
  int index = 0;
  for (int a = Dim - 1; a >= 0; --a) {
    int t = c[a];
    if (t < 0 || t >= f.dims[a]) {
      if (!periodic_[a]) return -1;
      t = ((t % f.dims[a]) + f.dims[a]) % f.dims[a];
    }
    index = index * f.dims[a] + t;
  }
  return f.offset + index;
}

template <int Dim>
int MatrixFreeStokesOperator<Dim>::column_faces(int field, const VecI<Dim>& c,
                                                std::array<int, 2 * Dim>& face,
                                                std::array<double, 2 * Dim>& coef) const {
  int count = 0;
  for (const Term& t : terms_[field]) {
    const int f = index_or_outside(t.field, c, t.axis, t.delta);
    if (f < 0) continue;  // a face outside the domain: zero velocity
    face[count] = f;
    coef[count++] = t.coef;
  }
  return count;
}

template <int Dim>
void MatrixFreeStokesOperator<Dim>::scatter(const VectorX& x, double* s, double* q) const {
  // (orphaned omp for without barriers: called inside a parallel region, every loop writes its
  // own entries; only rows with unknowns, the others stay zero)
  // s = M W_L^s tau on the DOFs of unknowns, zero elsewhere
  for (int field : layout_field_) {
    const Field& f = fields_[field];
    const std::vector<int>& rows = active_rows_[field];
    const std::vector<std::pair<int, int>>& spans = active_spans_[field];
    const int count = static_cast<int>(rows.size());
#pragma omp for schedule(dynamic, dynamic_chunk(count)) nowait
    for (int m = 0; m < count; ++m) {
      const int start = f.offset + rows[m] * f.dims[0];
      for (int d = start + spans[m].first; d < start + spans[m].second; ++d) {
        const int u = unknown_of_dof_[d];
        s[d] = u >= 0 ? weight_[u] * x[u] : 0.0;
      }
    }
  }
  if (eliminated_ >= 0) {
    // the eliminated diagonal DOF is minus the sum of the other diagonal unknowns of its cell
    const int base = fields_[Dim + eliminated_].offset;
    const std::vector<int>& rows = active_rows_[Dim + eliminated_];
    const std::vector<std::pair<int, int>>& spans = active_spans_[Dim + eliminated_];
    const int count = static_cast<int>(rows.size());
    const int n0 = fields_[Dim + eliminated_].dims[0];
#pragma omp for schedule(dynamic, dynamic_chunk(count)) nowait
    for (int m = 0; m < count; ++m)
      for (int c = rows[m] * n0 + spans[m].first; c < rows[m] * n0 + spans[m].second; ++c) {
        double sum = 0.0;
        for (int k = 0; k < Dim - 1; ++k) {
          const int u = unknown_of_dof_[fields_[Dim + k].offset + c];
          if (u >= 0) sum += x[u];
        }
        s[base + c] = eliminated_weight_[c] * sum;
      }
  }
  if (!has_pressure_) return;
  // q = W_L^p p
  const std::vector<int>& rows = active_rows_[kCellField];
  const std::vector<std::pair<int, int>>& spans = active_spans_[kCellField];
  const int count = static_cast<int>(rows.size());
  const int n0 = fields_[kCellField].dims[0];
#pragma omp for schedule(dynamic, dynamic_chunk(count)) nowait
  for (int m = 0; m < count; ++m)
    for (int c = rows[m] * n0 + spans[m].first; c < rows[m] * n0 + spans[m].second; ++c) {
      const int u = unknown_of_cell_[c] - 1;
      q[c] = u >= 0 ? weight_[u] * x[u] : 0.0;
    }
}

template <int Dim>
void MatrixFreeStokesOperator<Dim>::faces_from_grid(const double* s, const double* q,
                                                    double* force, bool scale_by_c,
                                                    bool all_rows) const {
  std::array<const double*, kFields> data{};
  for (int k = 0; k < kComponents; ++k) data[Dim + k] = s;
  data[kCellField] = q;
  for (int a = 0; a < Dim; ++a)
    stencil_rows<Dim>(fields_[a], force, terms_[a], fields_, data, periodic_,
                      scale_by_c ? face_coefficient_.data() : nullptr,
                      all_rows ? nullptr : &active_rows_[a],
                      all_rows ? nullptr : &active_spans_[a]);
}

template <int Dim>
void MatrixFreeStokesOperator<Dim>::grid_from_faces(const double* v, double* s, double* q) const {
  std::array<const double*, kFields> data{};
  for (int a = 0; a < Dim; ++a) data[a] = v;
  // D v on the components the unknowns use (and the eliminated one), G^T v on the cells
  // (box26: on the rows' spans of unknowns only; gather reads nothing else, and scatter's
  // zeros beyond them are never overwritten)
  for (int field : layout_field_)
    stencil_rows<Dim>(fields_[field], s, terms_[field], fields_, data, periodic_, nullptr,
                      &active_rows_[field], &active_spans_[field]);
  if (eliminated_ >= 0)
    stencil_rows<Dim>(fields_[Dim + eliminated_], s, terms_[Dim + eliminated_], fields_, data,
                      periodic_, nullptr, &active_rows_[Dim + eliminated_],
                      &active_spans_[Dim + eliminated_]);
  if (has_pressure_)
    stencil_rows<Dim>(fields_[kCellField], q, terms_[kCellField], fields_, data, periodic_,
                      nullptr, &active_rows_[kCellField], &active_spans_[kCellField]);
}

template <int Dim>
void MatrixFreeStokesOperator<Dim>::gather(const double* s, const double* q, const VectorX* x,
                                           VectorX& y) const {
  // (orphaned omp for without barriers, like scatter; y is sized by the caller)
  for (int field : layout_field_) {
    const Field& f = fields_[field];
    const std::vector<int>& rows = active_rows_[field];
    const std::vector<std::pair<int, int>>& spans = active_spans_[field];
    const int count = static_cast<int>(rows.size());
    const int n0 = f.dims[0];
    const bool reduced_diagonal = eliminated_ >= 0 && field - Dim < Dim;
    const int eliminated_base = eliminated_ >= 0 ? fields_[Dim + eliminated_].offset : 0;
    // one writer per unknown: its weight times (D v) at its DOF, plus 1/2 N^-1 W^s x
#pragma omp for schedule(dynamic, dynamic_chunk(count)) nowait
    for (int m = 0; m < count; ++m)
      for (int e = rows[m] * n0 + spans[m].first; e < rows[m] * n0 + spans[m].second; ++e) {
        const int u = unknown_of_dof_[f.offset + e];
        if (u < 0) continue;
        double value = weight_[u] * s[f.offset + e];
        if (x) value += self_[u] * (*x)[u];
        if (reduced_diagonal) {
          // the eliminated DOF of the cell (e is the cell index on diagonal components)
          value += eliminated_weight_[e] * s[eliminated_base + e];
          if constexpr (Dim == 3) {
            if (x) {
              const int partner = unknown_of_dof_[fields_[Dim + 1 - (field - Dim)].offset + e];
              if (partner >= 0) value += eliminated_coupling_[e] * (*x)[partner];
            }
          }
        }
        y[u] = value;
      }
  }
  if (!has_pressure_) return;
  const std::vector<int>& rows = active_rows_[kCellField];
  const std::vector<std::pair<int, int>>& spans = active_spans_[kCellField];
  const int n0 = fields_[kCellField].dims[0];
  const int count = static_cast<int>(rows.size());
#pragma omp for schedule(dynamic, dynamic_chunk(count)) nowait
  for (int m = 0; m < count; ++m)
    for (int c = rows[m] * n0 + spans[m].first; c < rows[m] * n0 + spans[m].second; ++c) {
      const int u = unknown_of_cell_[c] - 1;
      if (u >= 0) y[u] = weight_[u] * q[c];
    }
}

template <int Dim>
void MatrixFreeStokesOperator<Dim>::apply(const VectorX& x, VectorX& y) const {
  double* s = stress_scratch_.data();
  double* q = cell_scratch_.data();
  double* v = face_scratch_.data();
  y.resize(size_);
  // x to the grid, v = C B x per face, B^T v per grid DOF, gathered per unknown: one parallel
  // region, a barrier between the passes; the team size measured (AdaptiveTeam), one thread
  // below kParallelMinWork entries visited
  static AdaptiveTeam site;
  TeamScope team(site, active_work_);
#pragma omp parallel num_threads(team.threads()) if (team.parallel())
  {
    scatter(x, s, q);
#pragma omp barrier
    faces_from_grid(s, q, v, true, false);
#pragma omp barrier
    grid_from_faces(v, s, q);
#pragma omp barrier
    gather(s, q, &x, y);
  }
}

template <int Dim>
void MatrixFreeStokesOperator<Dim>::sweep_block(int field, bool reverse, const VectorX& rhs,
                                                VectorX& x, double omega,
                                                const std::vector<char>* active) const {
  const Field& f = fields_[field];
  const bool is_cell = field == kCellField;
  // (the cells' map holds unknown + 1, the DOFs' map the unknown: band23)
  const int* map = is_cell ? unknown_of_cell_.data() : unknown_of_dof_.data();
  const int bias = is_cell ? 1 : 0;
  const bool reduced_diagonal = eliminated_ >= 0 && !is_cell && field - Dim < Dim;
  const int n0 = f.dims[0];
  double* force = face_scratch_.data();
  // the faces of the column of B of every entry of a row: per stencil term the start of the
  // face row and the shift along axis 0 (eq. (8)'s D or G^T rows, as in stencil_rows)
  struct RowTerm {
    const double* coefficient = nullptr;  // C_f of the face row
    double* force = nullptr;              // B x of the face row
    int shift = 0, length = 0;
    double coef = 0.0;
    bool eliminated = false;
  };
  const double* face_coefficient = face_coefficient_.data();
  const double* diagonal = diagonal_.data();
  const double* self = self_.data();
  const double* weight = weight_.data();
  const double* eliminated_weight = eliminated_weight_.data();
  const double* b_rhs = rhs.data();
  double* xs = x.data();
  const bool periodic0 = periodic_[0];
  const std::vector<std::pair<int, int>>& spans = active_spans_[field];
  auto relax_row = [&](int m_row, int parity) {
    const int r = active_rows_[field][m_row];
    VecI<Dim> c = VecI<Dim>::Zero();
    int rest = r, sum = 0;
    for (int a = 1; a < Dim; ++a) {
      c[a] = rest % f.dims[a];
      rest /= f.dims[a];
      sum += c[a];
    }
    std::array<RowTerm, 2 * Dim + 2> row_terms;
    int num_terms = 0;
    auto add_terms = [&](int of_field, bool eliminated) {
      for (const Term& t : terms_[of_field]) {
        const int start = row_start<Dim>(fields_[t.field], c, t.axis, t.delta, periodic_);
        if (start < 0) continue;  // faces outside the domain: zero velocity
        row_terms[num_terms++] = {face_coefficient + start, force + start,
                                  t.axis == 0 ? t.delta : 0, fields_[t.field].dims[0], t.coef,
                                  eliminated};
      }
    };
    add_terms(field, false);
    if (reduced_diagonal) add_terms(Dim + eliminated_, true);
    // the entries of this colour: coordinate sum of the given parity, in the row's span of
    // unknowns (box26: every entry outside it has none and is skipped below)
    const int span_lo = spans[m_row].first, span_hi = spans[m_row].second;
    const int first = span_lo + (span_lo + parity + sum) % 2;
    if (first >= span_hi) return;
    const int last = first + 2 * ((span_hi - 1 - first) / 2);
    const int base = f.offset + r * n0;
    // within an independent group the order does not matter: ascending (memory order) then
    const bool descending = reverse && !colouring_valid_;
    // the entries of the row, with the term count a compile-time constant (unrolled loops)
    auto relax_entries = [&](auto terms) {
      constexpr int kTerms = decltype(terms)::value;
      if constexpr (kTerms <= 2 * Dim + 2) {  // (at most 2 Dim + 2 terms; 8 only in 3D)
        for (int step = 0; step <= (last - first) / 2; ++step) {
          const int x0 = descending ? last - 2 * step : first + 2 * step;
          const int d = base + x0;
          const int u = map[d] - bias;
          if (u < 0) continue;
          const double diag = diagonal[u];
          if (diag == 0.0 || (active && !(*active)[u])) continue;
          const double xu = xs[u];
          double ax = self[u] * xu;
          if constexpr (Dim == 3) {
            if (reduced_diagonal) {
              // the other diagonal unknown of the cell, through the eliminated DOF's N^-1
              const int cell = d - f.offset;
              const int partner = unknown_of_dof_[fields_[Dim + 1 - (field - Dim)].offset + cell];
              if (partner >= 0) ax += eliminated_coupling_[cell] * xs[partner];
            }
          }
          // (A x)_u = sum_f B_fu C_f (B x)_f + the N part over the faces of u with fluid, in
          // term order; a face without fluid (C_f = 0, it adds nothing to A) or outside the
          // domain keeps its force (apply relies on zeros there): its update goes to `sink`
          const double w_u = weight[u];
          const double w_e = reduced_diagonal ? eliminated_weight[x0 + r * n0] : 0.0;
          double sink = 0.0;
          std::array<double*, 2 * Dim + 2> face;
          std::array<double, 2 * Dim + 2> b;
          for (int m = 0; m < kTerms; ++m) {
            const RowTerm& t = row_terms[m];
            int xi = x0 + t.shift;
            b[m] = (t.eliminated ? w_e : w_u) * t.coef;
            if (xi < 0 || xi >= t.length) {
              if (!periodic0) {
                face[m] = &sink;
                continue;
              }
              xi = ((xi % t.length) + t.length) % t.length;
            }
            const double cf = t.coefficient[xi];
            face[m] = cf != 0.0 ? t.force + xi : &sink;
            if (cf != 0.0) ax += b[m] * cf * t.force[xi];
          }
          // relax, then move the force with x_u
          const double off = ax - diag * xu;
          const double updated = (1.0 - omega) * xu + omega * (b_rhs[u] - off) / diag;
          const double change = updated - xu;
          xs[u] = updated;
          for (int m = 0; m < kTerms; ++m) *face[m] += b[m] * change;
        }
      }
    };
    switch (num_terms) {
      case 0: relax_entries(std::integral_constant<int, 0>()); break;
      case 1: relax_entries(std::integral_constant<int, 1>()); break;
      case 2: relax_entries(std::integral_constant<int, 2>()); break;
      case 3: relax_entries(std::integral_constant<int, 3>()); break;
      case 4: relax_entries(std::integral_constant<int, 4>()); break;
      case 5: relax_entries(std::integral_constant<int, 5>()); break;
      case 6: relax_entries(std::integral_constant<int, 6>()); break;
      case 7: relax_entries(std::integral_constant<int, 7>()); break;
      default: relax_entries(std::integral_constant<int, 8>()); break;
    }
  };
  const int first_colour = reverse ? 1 : 0, second_colour = 1 - first_colour;
  // the rows with unknowns of this field, in grid order
  const std::vector<int>& row_list = active_rows_[field];
  const int count = static_cast<int>(row_list.size());
  if (colouring_valid_) {
    // no two unknowns of one colour share a face: rows shared among the threads of the sweep's
    // region (sweep), a barrier after each colour; each row has one writer, so any split of
    // the rows gives the same result, and chunks taken on demand keep a thread whose core is
    // busy from holding up the other
    for (int parity : {first_colour, second_colour}) {
#pragma omp for schedule(dynamic, dynamic_chunk(count))
      for (int m = 0; m < count; ++m) relax_row(m, parity);
    }
  } else if (!reverse) {
    for (int m = 0; m < count; ++m) relax_row(m, first_colour);
    for (int m = 0; m < count; ++m) relax_row(m, second_colour);
  } else {
    for (int m = count - 1; m >= 0; --m) relax_row(m, first_colour);
    for (int m = count - 1; m >= 0; --m) relax_row(m, second_colour);
  }
}

template <int Dim>
void MatrixFreeStokesOperator<Dim>::sweep(bool reverse, const VectorX& rhs, VectorX& x,
                                          double omega, const std::vector<char>* active,
                                          bool force_current) const {
  // the face force B x of the starting x (zero at the start of an SSOR application; kept from
  // the previous sweep when `force_current`)
  double* force = face_scratch_.data();
  bool zero = !force_current;
  for (int i = 0; i < size_ && zero; ++i) zero = x[i] == 0.0;
  // (only the active face rows: the sweeps read and write the force only at faces with
  // C_f != 0, which lie in them; the rows grid_from_faces reads besides are zero at all times
  // (made zero with the scratch, written by no pass but rhs, which zeroes them again), and no
  // pass reads the others: the same values as a fill of every face, without a pass over the
  // grid's faces per SSOR application)
  if (zero) zero_active_face_rows(force);
  const bool recompute = !zero && !force_current;
  // the whole sweep in one parallel region (one fork and join per sweep, a barrier per colour
  // group), only with a valid colouring (otherwise the sweep is serial) and enough work; the
  // team size measured per call (AdaptiveTeam; separate sites for a start from zero, as in
  // SSOR's forward sweep, and from a given x, which costs an extra pass)
  const int blocks = static_cast<int>(layout_field_.size()) + (has_pressure_ ? 1 : 0);
  static AdaptiveTeam site_from_zero, site_from_x;
  TeamScope team(recompute ? site_from_x : site_from_zero, colouring_valid_ ? active_work_ : 0);
#pragma omp parallel num_threads(team.threads()) if (team.parallel())
  {
    if (recompute) {
      scatter(x, stress_scratch_.data(), cell_scratch_.data());
#pragma omp barrier
      faces_from_grid(stress_scratch_.data(), cell_scratch_.data(), force, false, false);
#pragma omp barrier
    }
    // colour groups: stress components in layout order, then pressure; red then black (the
    // reverse order backward)
    for (int step = 0; step < blocks; ++step) {
      const int block = reverse ? blocks - 1 - step : step;
      const int field =
          block < static_cast<int>(layout_field_.size()) ? layout_field_[block] : kCellField;
      sweep_block(field, reverse, rhs, x, omega, active);
    }
  }
}

template <int Dim>
void MatrixFreeStokesOperator<Dim>::zero_active_face_rows(double* force) const {
  for (int a = 0; a < Dim; ++a) {
    const Field& f = fields_[a];
    const int n0 = f.dims[0];
    // (box26: the spans with C_f != 0 only; beyond them no pass writes the force, which keeps
    // the zeros the scratch was made with)
    for (std::size_t m = 0; m < active_rows_[a].size(); ++m) {
      const int start = f.offset + active_rows_[a][m] * n0;
      std::fill(force + start + active_spans_[a][m].first,
                force + start + active_spans_[a][m].second, 0.0);
    }
  }
}

template <int Dim>
void MatrixFreeStokesOperator<Dim>::forward_sweep(const VectorX& rhs, VectorX& x, double omega,
                                                  const std::vector<char>* active) const {
  sweep(false, rhs, x, omega, active);
}

template <int Dim>
void MatrixFreeStokesOperator<Dim>::backward_sweep(const VectorX& rhs, VectorX& x, double omega,
                                                   const std::vector<char>* active) const {
  sweep(true, rhs, x, omega, active);
}

template <int Dim>
void MatrixFreeStokesOperator<Dim>::forward_sweeps(const VectorX& rhs, VectorX& x, double omega,
                                                   int count) const {
  // every sweep leaves B x of its result in the face scratch (rows with C_f = 0 excepted, which
  // no sweep reads), so the next one starts from it
  for (int s = 0; s < count; ++s) sweep(false, rhs, x, omega, nullptr, s > 0);
}

template <int Dim>
void MatrixFreeStokesOperator<Dim>::backward_sweeps(const VectorX& rhs, VectorX& x, double omega,
                                                    int count) const {
  for (int s = 0; s < count; ++s) sweep(true, rhs, x, omega, nullptr, s > 0);
}

template <int Dim>
VectorX MatrixFreeStokesOperator<Dim>::face_force(const VectorX& x) const {
  VectorX force(num_faces_);
  face_force_into(x, force.data());
  return force;
}

template <int Dim>
void MatrixFreeStokesOperator<Dim>::face_force_into(const VectorX& x, double* force) const {
  // s and q in the scratch vectors: scatter writes the rows with unknowns, which apply
  // overwrites too, and leaves the others at zero (as the zero-filled temporaries were there)
  double* s = stress_scratch_.data();
  double* q = cell_scratch_.data();
#pragma omp parallel num_threads(process_threads()) if (active_work_ > kParallelMin)
  {
    scatter(x, s, q);
#pragma omp barrier
    faces_from_grid(s, q, force, false, true);
  }
}

template <int Dim>
void MatrixFreeStokesOperator<Dim>::updated_velocities_into(const VectorX& x,
                                                            const VectorX& u_star, double dt,
                                                            VectorX& u) const {
  // B x on the face rows with an updated face only (the force is read nowhere else), written
  // into u's storage; then per face row the update (u* - dt force / (rho W_L^u) on the updated
  // faces, u* on the others: the expression of apply_stokes_update) or a copy of u*'s row
  if (u.size() != num_faces_) u.resize(num_faces_);
  const PressureWeights& pw = *pressure_weights_;
  if (stokes_operator_every_face_row()) {
    // (the test switch: B x on every face, then the update per face)
    face_force_into(x, u.data());
#pragma omp parallel for schedule(static) num_threads(team_threads(num_faces_))
    for (int f = 0; f < num_faces_; ++f) {
      if (!(pw.fluid_face[f] * pw.liquid_face[f] > 0.0) || !(pw.face_density[f] > 0.0))
        u[f] = u_star[f];
      else
        u[f] = u_star[f] - dt * u[f] / (pw.face_density[f] * pw.liquid_face[f]);
    }
    return;
  }
  double* s = stress_scratch_.data();
  double* q = cell_scratch_.data();
  double* force = u.data();
  std::array<const double*, kFields> data{};
  for (int k = 0; k < kComponents; ++k) data[Dim + k] = s;
  data[kCellField] = q;
#pragma omp parallel num_threads(process_threads()) if (active_work_ > kParallelMin)
  {
    scatter(x, s, q);
#pragma omp barrier
    // (box26: on the spans of updated faces; every other face gets u* below)
    for (int a = 0; a < Dim; ++a)
      stencil_rows<Dim>(fields_[a], force, terms_[a], fields_, data, periodic_, nullptr,
                        &updated_rows_[a], &updated_spans_[a]);
  }
  for (int a = 0; a < Dim; ++a) {
    const Field& f = fields_[a];
    const int n0 = f.dims[0], rows = f.dims.prod() / std::max(n0, 1);
    // per row: 1 + the index of its span of updated faces, or 0
    std::vector<int> updated(rows, 0);
    for (std::size_t m = 0; m < updated_rows_[a].size(); ++m)
      updated[updated_rows_[a][m]] = static_cast<int>(m) + 1;
#pragma omp parallel for schedule(static) num_threads(team_threads(f.dims.prod()))
    for (int r = 0; r < rows; ++r) {
      const int begin = f.offset + r * n0, end = begin + n0;
      if (!updated[r]) {
        std::copy(u_star.data() + begin, u_star.data() + end, u.data() + begin);
        continue;
      }
      // u* beyond the span (no face there is updated), the update's test on the span
      const std::pair<int, int>& span = updated_spans_[a][updated[r] - 1];
      std::copy(u_star.data() + begin, u_star.data() + begin + span.first, u.data() + begin);
      std::copy(u_star.data() + begin + span.second, u_star.data() + end,
                u.data() + begin + span.second);
      for (int e = begin + span.first; e < begin + span.second; ++e) {
        if (!(pw.fluid_face[e] * pw.liquid_face[e] > 0.0) || !(pw.face_density[e] > 0.0))
          u[e] = u_star[e];
        else
          u[e] = u_star[e] - dt * u[e] / (pw.face_density[e] * pw.liquid_face[e]);
      }
    }
  }
}

bool& stokes_operator_every_face_row() {
  static bool every = false;
  return every;
}

template <int Dim>
std::vector<std::pair<int, double>> MatrixFreeStokesOperator<Dim>::stencil(int i) const {
  std::vector<std::pair<int, double>> column;
  column.reserve(4 * Dim);  // (one allocation: at most two fields' faces)
  std::array<int, 2 * Dim> face;
  std::array<double, 2 * Dim> coef;
  const int loc = location_[i];
  if (i >= num_stress_) {
    const int count = column_faces(kCellField, lattice_coord<Dim>(loc, fields_[kCellField].dims),
                                   face, coef);
    for (int m = 0; m < count; ++m) column.emplace_back(face[m], weight_[i] * coef[m]);
  } else {
    int k = 0;
    while (k + 1 < kComponents && loc >= fields_[Dim + k + 1].offset) ++k;
    const int e = loc - fields_[Dim + k].offset;
    const VecI<Dim> c = lattice_coord<Dim>(e, fields_[Dim + k].dims);
    int count = column_faces(Dim + k, c, face, coef);
    for (int m = 0; m < count; ++m) column.emplace_back(face[m], weight_[i] * coef[m]);
    if (eliminated_ >= 0 && StressGrid<Dim>::is_diagonal(k)) {
      // reduced form: the eliminated DOF of the cell, with E's -1 in its weight
      count = column_faces(Dim + eliminated_, c, face, coef);
      for (int m = 0; m < count; ++m) column.emplace_back(face[m], eliminated_weight_[e] * coef[m]);
    }
  }
  // merge repeated faces (a periodic axis of one or two cells)
  std::sort(column.begin(), column.end());
  std::vector<std::pair<int, double>> merged;
  merged.reserve(column.size());
  for (const auto& entry : column) {
    if (!merged.empty() && merged.back().first == entry.first)
      merged.back().second += entry.second;
    else
      merged.push_back(entry);
  }
  return merged;
}

template <int Dim>
VectorX MatrixFreeStokesOperator<Dim>::rhs(const VectorX& u_star) const {
  // b = B^T W_F^u u*: the gather of apply without C and the N part, in the scratch vectors
  // (grid_from_faces writes the stress and cell rows apply writes); v = W_F^u u* fills every
  // face, and apply relies on zeros in the face rows it does not write, so the face scratch is
  // zeroed again afterwards
  VectorX b(size_);
  double* v = face_scratch_.data();
  double* s = stress_scratch_.data();
  double* q = cell_scratch_.data();
  // (only the face rows grid_from_faces reads: v is read nowhere else, and the scratch's other
  // rows keep their zeros; issue 20)
  const double* wf = fluid_face_->data();
  const double* u = u_star.data();
  const bool every = stokes_operator_every_face_row();
  std::array<int, Dim + 1> first_row{};
  for (int a = 0; a < Dim; ++a)
    first_row[a + 1] =
        first_row[a] + (every ? fields_[a].dims.prod() / std::max(fields_[a].dims[0], 1)
                              : static_cast<int>(read_face_rows_[a].size()));
  auto face_row = [&](int m, int& begin, int& end) {
    int a = 0;
    while (m >= first_row[a + 1]) ++a;
    const int n0 = fields_[a].dims[0];
    const int r = every ? m - first_row[a] : read_face_rows_[a][m - first_row[a]];
    begin = fields_[a].offset + r * n0;
    end = begin + n0;
  };
  const int read_rows = first_row[Dim];
#pragma omp parallel num_threads(process_threads()) if (active_work_ > kParallelMin)
  {
#pragma omp for schedule(static)
    for (int m = 0; m < read_rows; ++m) {
      int begin = 0, end = 0;
      face_row(m, begin, end);
      for (int f = begin; f < end; ++f) v[f] = wf[f] * u[f];
    }
    grid_from_faces(v, s, q);
#pragma omp barrier
    gather(s, q, nullptr, b);
#pragma omp barrier
#pragma omp for schedule(static) nowait
    for (int m = 0; m < read_rows; ++m) {
      int begin = 0, end = 0;
      face_row(m, begin, end);
      for (int f = begin; f < end; ++f) v[f] = 0.0;
    }
  }
  return b;
}

template <int Dim>
std::size_t MatrixFreeStokesOperator<Dim>::memory_bytes() const {
  const std::size_t d = sizeof(double), i = sizeof(int);
  std::size_t bytes = d * (face_coefficient_.size() + weight_.size() +
                           self_.size() + diagonal_.size() + eliminated_weight_.size() +
                           eliminated_coupling_.size() + stress_scratch_.size() +
                           cell_scratch_.size() + face_scratch_.size()) +
                      i * (unknown_of_dof_.size() + unknown_of_cell_.size() + location_.size());
  for (const VectorX& n : null_space_) bytes += d * n.size();
  return bytes;
}

template <int Dim>
double MatrixFreeStokesOperator<Dim>::bytes_per_apply() const {
  // compulsory traffic, the same count as SparseMatrixOperator's: the grid -> unknown maps, C_f
  // per face, per unknown its location, weight and 1/2 N^-1 W^s entry, the eliminated
  // component's arrays, x read once and y written once. The scratch fields (written and read in
  // each of the four passes) are not counted: at the benchmark sizes part of them stays in the
  // cache, and counting them would overstate the bandwidth; this count makes it a lower bound.
  const double d = sizeof(double), i = sizeof(int);
  return i * static_cast<double>(unknown_of_dof_.size() + unknown_of_cell_.size() +
                                 location_.size()) +
         d * static_cast<double>(face_coefficient_.size() + weight_.size() + self_.size() +
                                 eliminated_weight_.size() + eliminated_coupling_.size()) +
         2.0 * d * size_;
}

// --- update, scatter, energy, solve ---------------------------------------------------------


/// D^T (M W_L^s tau) on every face without assembling D (deformation_rate_matrix over the whole
/// grid cost about 0.15 s per step at 64^3, more than the rest of the update): the rows of D
/// with a non-zero stress, in increasing row order, their entries in increasing face order with
/// equal faces merged (as setFromTriplets stores them), scattered into a vector that starts at
/// zero. These are the additions of Eigen's D^T s in the same order, so the result is the same
/// bit for bit (test "apply_stokes_update: ..."); rows with s = 0 add only signed zeros to a sum
/// that starts at +0, which leaves every sum unchanged.
template <int Dim>
VectorX deformation_rate_transpose_product(const StressGrid<Dim>& stress, const VectorX& liquid_stress,
                                           const VectorX& tau_full) {
  VectorX y = VectorX::Zero(stress.grid().num_faces());
  for (int row = 0; row < stress.num_dofs(); ++row) {
    const int k = stress.coord(row).first;
    const double s = StressGrid<Dim>::multiplicity(k) * liquid_stress[row] * tau_full[row];
    if (s == 0.0) continue;
    std::array<std::pair<int, double>, 4> e;
    int m = 0;
    for_each_deformation_rate_entry(stress, row, [&](int col, double v) { e[m++] = {col, v}; });
    // the stored row: sorted by face, duplicates summed in insertion order (stable sort)
    std::stable_sort(e.begin(), e.begin() + m, [](const auto& p, const auto& q) { return p.first < q.first; });
    for (int i = 0; i < m;) {
      double v = e[i].second;
      int j = i + 1;
      for (; j < m && e[j].first == e[i].first; ++j) v += e[j].second;
      y[e[i].first] += v * s;
      i = j;
    }
  }
  return y;
}

template <int Dim>
void apply_stokes_update(const MacGrid<Dim>& grid, const StressLayout<Dim>& layout,
                         const StokesWeights& w, double dt, const VectorX& pressure_cells,
                         const VectorX& tau_full, VectorX& u) {
  const StressGrid<Dim>& stress = layout.grid();
  // force per face: G W_L^p p + D^T M W_L^s tau
  VectorX force = VectorX::Zero(grid.num_faces());
  if (pressure_cells.size() > 0)
    force += apply_gradient(grid, VectorX(w.pressure.liquid_cell.cwiseProduct(pressure_cells)));
  if (tau_full.size() > 0) force += deformation_rate_transpose_product(stress, w.liquid_stress, tau_full);
  const PressureWeights& pw = w.pressure;
#pragma omp parallel for schedule(static) num_threads(team_threads(grid.num_faces()))
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
  if (w.inviscid()) {
    // no stress unknowns and no stress part (the stress vectors may be empty)
    VectorX u = u_star;
    apply_stokes_update(grid, layout, w, dt, scatter_stokes_pressure(dofs, x, grid.num_cells()),
                        VectorX(), u);
    const PressureWeights& pw = w.pressure;
    double kinetic = 0.0;
    for (int f = 0; f < grid.num_faces(); ++f)
      kinetic += pw.face_density[f] * pw.fluid_face[f] * pw.liquid_face[f] * u[f] * u[f];
    return 0.5 * kinetic;
  }
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
  // the dry faces the stress reaches: eq. (8)'s zero traction at the surface (departures item 23)
  if (eta > 0.0)
    clamp_stressed_face_weights(stress, w.fluid_stress, w.liquid_stress, w.viscosity,
                                w.pressure.liquid_face);
  return w;
}

template <int Dim>
void clamp_stressed_face_weights(const StressGrid<Dim>& stress, const VectorX& fluid_stress,
                                 const VectorX& liquid_stress, const VectorX& viscosity,
                                 VectorX& liquid_face, const LatticeSigns<Dim>* signs,
                                 std::array<WrittenBox<Dim>, Dim>* faces) {
  const MacGrid<Dim>& grid = stress.grid();
  const int n = stress.num_dofs();
  if (viscosity.size() != n || fluid_stress.size() != n || liquid_stress.size() != n) return;
  if (signs && !signs->any_negative()) return;  // W_L^s = 0 everywhere
  // the DOF box per axis, the same for every component (conservative): DOF c of component k
  // covers lattice cells 2 c + 2 shift(k) - 1 and 2 c + 2 shift(k) along each axis, mirrored
  // at walls by at most one lattice cell (two DOFs of slack each way); a periodic axis is taken
  // whole (its wrap)
  VecI<Dim> lo = VecI<Dim>::Zero(), hi = grid.cells();
  if (signs)
    for (int a = 0; a < Dim; ++a)
      if (!grid.periodic(a)) {
        lo[a] = std::max(0, signs->lo[a] / 2 - 2);
        hi[a] = std::min(grid.cells()[a], signs->hi[a] / 2 + 2);
      }
  double* w = liquid_face.data();
  for (int k = 0; k < StressGrid<Dim>::num_components(); ++k) {
    const VecI<Dim> dims = stress.dims(k);
    const VecI<Dim> klo = lo, khi = hi.cwiseMin(dims - VecI<Dim>::Ones());
    if ((klo.array() > khi.array()).any()) continue;
    const BoxRows<Dim> rows(dims, klo, khi);
    const int nr = rows.rows();
    // a face may be raised by several DOFs on several threads: atomic reads and writes of one
    // constant, so every order gives the same bits
#pragma omp parallel for schedule(static) num_threads(team_threads(static_cast<long>(nr) * rows.nx))
    for (int r = 0; r < nr; ++r) {
      const int first = stress.offset(k) + rows.first(r);
      for (int x = 0; x < rows.nx; ++x) {
        const int d = first + x;
        if (!(fluid_stress[d] * liquid_stress[d] > 0.0 && viscosity[d] > 0.0)) continue;
        for_each_deformation_rate_entry(stress, d, [&](int f, double) {
          double v;
#pragma omp atomic read
          v = w[f];
          if (v < kMinLiquidFaceFraction) {
#pragma omp atomic write
            w[f] = kMinLiquidFaceFraction;
          }
        });
      }
    }
  }
  if (!faces) return;
  // the faces of the DOFs of the box: within one face of it along every axis
  for (int a = 0; a < Dim; ++a) {
    WrittenBox<Dim>& fb = (*faces)[a];
    if (!fb.valid_for(w + grid.face_offset(a), grid.face_dims(a).prod())) continue;
    const VecI<Dim> fdims = grid.face_dims(a);
    VecI<Dim> flo, fhi;
    for (int b = 0; b < Dim; ++b) {
      flo[b] = grid.periodic(b) ? 0 : std::max(0, lo[b] - 1);
      fhi[b] = grid.periodic(b) ? fdims[b] - 1 : std::min(fdims[b] - 1, hi[b] + 1);
    }
    fb.cover(flo, fhi);
  }
}

template <int Dim>
std::vector<int> stokes_sweep_order(const MacGrid<Dim>& grid, const StressLayout<Dim>& layout,
                                    const StokesDofs& dofs) {
  // buckets (layout component or pressure, colour), each filled in increasing grid index: the
  // stress unknowns by their StressGrid DOF, the pressure unknowns by their cell
  const StressGrid<Dim>& stress = layout.grid();
  const int ns = dofs.num_stress(), np = dofs.num_pressure();
  const int blocks = layout.num_components() + 1;
  std::vector<int> position(StressGrid<Dim>::num_components(), -1);
  for (int j = 0; j < layout.num_components(); ++j) position[layout.component(j)] = j;
  std::vector<std::vector<std::pair<int, int>>> bucket(2 * blocks);  // (grid index, unknown)
  for (int i = 0; i < ns; ++i) {
    const int d = layout.dof_of_unknown(dofs.unknown_of_dof[i]);
    const auto [k, c] = stress.coord(d);
    bucket[2 * position[k] + (c.sum() & 1)].emplace_back(d, i);
  }
  for (int k = 0; k < np; ++k) {
    const int cell = dofs.pressure.cell_of_dof[k];
    bucket[2 * (blocks - 1) + (grid.cell_coord(cell).sum() & 1)].emplace_back(cell, ns + k);
  }
  std::vector<int> order;
  order.reserve(static_cast<std::size_t>(ns + np));
  for (auto& b : bucket) {
    std::sort(b.begin(), b.end());
    for (const auto& entry : b) order.push_back(entry.second);
  }
  return order;
}

#define MONOLITH_INSTANTIATE(D)                                                                  \
  template void clamp_stressed_face_weights<D>(const StressGrid<D>&, const VectorX&,             \
                                               const VectorX&, const VectorX&, VectorX&,         \
                                               const LatticeSigns<D>*,                           \
                                               std::array<WrittenBox<D>, D>*);                   \
  template StokesWeights uniform_stokes_weights<D>(const MacGrid<D>&, const VectorX&,            \
                                                   const VectorX&,                               \
                                                   const std::array<BoundaryType, 2 * D>&,       \
                                                   double, double);                              \
  template StokesDofs select_stokes_dofs<D>(const MacGrid<D>&, const StressLayout<D>&,           \
                                            const StokesWeights&, double, StokesUnknowns,        \
                                            const LiquidBand*);                                  \
  template ExplicitStokesSystem assemble_explicit_stokes<D>(const MacGrid<D>&,                   \
                                                            const StressLayout<D>&,              \
                                                            const StokesWeights&,                \
                                                            const StokesDofs&, double,           \
                                                            const VectorX&);                     \
  template class MatrixFreeStokesOperator<D>;                                                    \
  template std::vector<int> stokes_sweep_order<D>(const MacGrid<D>&, const StressLayout<D>&,     \
                                                  const StokesDofs&);                            \
  template VectorX deformation_rate_transpose_product<D>(const StressGrid<D>&, const VectorX&,      \
                                                        const VectorX&);                          \
  template void apply_stokes_update<D>(const MacGrid<D>&, const StressLayout<D>&,                \
                                       const StokesWeights&, double, const VectorX&,             \
                                       const VectorX&, VectorX&);                                \
  template VectorX scatter_stress<D>(const StressLayout<D>&, const StokesDofs&, const VectorX&); \
  template double stokes_energy<D>(const MacGrid<D>&, const StressLayout<D>&,                    \
                                   const StokesWeights&, const StokesDofs&, double,              \
                                   const VectorX&, const VectorX&);
MONOLITH_INSTANTIATE(2)
MONOLITH_INSTANTIATE(3)
#undef MONOLITH_INSTANTIATE

}  // namespace monolith
