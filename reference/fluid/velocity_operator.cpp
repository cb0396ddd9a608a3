#include "reference/fluid/velocity_operator.hpp"
#include "reference/core/parallel.hpp"

#include <Eigen/Dense>
#include <algorithm>
#include <array>
#include <memory>
#include <stdexcept>

namespace monolith {

namespace {

constexpr int kParallelRows = 4096;

/// The StressGrid DOF of the eliminated component in the cell of diagonal DOF d of component k.
template <int Dim>
int eliminated_dof(const StressGrid<Dim>& stress, int k, int d) {
  return stress.offset(Dim - 1) + (d - stress.offset(k));
}

/// Pressure data and stress elements shared by both builders.
template <int Dim>
void fill_common(const StressLayout<Dim>& layout, const StokesWeights& w, const StokesDofs& dofs,
                 double min_fluid_fraction, StokesFactors& f) {
  const StressGrid<Dim>& stress = layout.grid();
  f.num_stress = dofs.num_stress();
  f.num_pressure = dofs.num_pressure();
  f.compliance = stress_compliance(layout, dofs, w, min_fluid_fraction);
  // K without the floor differs from K only if some W_F^s lies strictly between 0 and the floor
  const bool floored = min_fluid_fraction > 0.0 &&
                       (w.fluid_stress.array() > 0.0 && w.fluid_stress.array() < min_fluid_fraction).any();
  if (floored) f.compliance_exact = stress_compliance(layout, dofs, w, 0.0);
  f.stress_fluid.resize(f.num_stress);
  for (int i = 0; i < f.num_stress; ++i) {
    const int d = layout.dof_of_unknown(dofs.unknown_of_dof[i]);
    const int k = stress.coord(d).first;
    double wf = w.fluid_stress[d];
    if (layout.form() == StressForm::reduced && StressGrid<Dim>::is_diagonal(k))
      wf = std::min(wf, w.fluid_stress[eliminated_dof(stress, k, d)]);
    f.stress_fluid[i] = wf;
  }
  f.pressure_cell = dofs.pressure.cell_of_dof;
  f.pressure_liquid.resize(f.num_pressure);
  f.pressure_viscosity.resize(f.num_pressure);
  for (int k = 0; k < f.num_pressure; ++k) {
    const int cell = f.pressure_cell[k];
    f.pressure_liquid[k] = w.pressure.liquid_cell[cell];
    f.pressure_viscosity[k] = w.viscosity.size() ? w.viscosity[stress.offset(0) + cell] : 0.0;
  }
  // elements: the diagonal unknowns of a cell together in the 3D reduced form, else one each
  const bool pair = Dim == 3 && layout.form() == StressForm::reduced;
  std::vector<int> element_of(f.num_stress, -1);
  for (int i = 0; i < f.num_stress; ++i) {
    if (element_of[i] >= 0) continue;
    const int d = layout.dof_of_unknown(dofs.unknown_of_dof[i]);
    const auto [k, c] = stress.coord(d);
    std::vector<int> members{i};
    if (pair && k == 0) {
      // the yy unknown of the same cell
      const int yy = layout.unknown_of_dof(stress.offset(1) + (d - stress.offset(0)));
      const int j = yy >= 0 ? dofs.dof_of_unknown[yy] : -1;
      if (j >= 0) members.push_back(j);
    } else if (pair && k == 1) {
      const int xx = layout.unknown_of_dof(stress.offset(0) + (d - stress.offset(1)));
      const int j = xx >= 0 ? dofs.dof_of_unknown[xx] : -1;
      if (j >= 0) continue;  // grouped with its xx unknown
    }
    for (int m : members) element_of[m] = static_cast<int>(f.element_unknowns.size());
    f.element_unknowns.push_back(members);
    f.element_component.push_back(k);
    VecI<3> coord = VecI<3>::Zero();
    for (int a = 0; a < Dim; ++a) coord[a] = c[a];
    f.element_coord.push_back(coord);
  }
}

/// B^T from its columns and the active faces: b_transpose row i = column i of B restricted to
/// the active faces (mapped through active_of_face), b its transpose.
void finish_b(std::vector<Triplet>& columns, int n, StokesFactors& f) {
  f.b_transpose.resize(n, static_cast<int>(f.face.size()));
  f.b_transpose.setFromTriplets(columns.begin(), columns.end());
  f.b_transpose.makeCompressed();
  f.b = f.b_transpose.transpose();
  f.b.makeCompressed();
}


/// m (n x cols, row-major) from its rows: `make_row()` is called once per thread and returns a
/// function row(r, list) that fills `list` (cleared by the caller) with output row r's (column,
/// value) pairs, columns distinct and in the order they are to be stored. Each thread assembles its block of consecutive rows into one
/// buffer of its own, then copies it into the compressed storage at its offset: no list per row
/// (a separate allocation for each of up to millions of rows, most of them fresh pages). Every
/// row is formed by one thread: any thread count gives the same bits.
template <class MakeRow>
void assemble_rows(int n, int cols, SparseMatrix& m, const MakeRow& make_row) {
  std::vector<int> outer(static_cast<std::size_t>(n) + 1, 0);
  m.resize(n, cols);
  m.resizeNonZeros(0);
#pragma omp parallel if (n > kParallelRows) num_threads(process_threads())
  {
    auto row = make_row();
    std::vector<std::pair<int, double>> list;
    list.reserve(64);
    std::vector<int> inner;
    std::vector<double> value;
    int first = -1;
#pragma omp for schedule(static)
    for (int r = 0; r < n; ++r) {
      if (first < 0) {
        first = r;
        // (a guess of the block's entries; the vectors grow past it if needed)
        const std::size_t guess = static_cast<std::size_t>(n) * 12 / static_cast<std::size_t>(omp_get_num_threads()) + 16;
        inner.reserve(guess);
        value.reserve(guess);
      }
      list.clear();
      row(r, list);
      for (const auto& [g, x] : list) {
        inner.push_back(g);
        value.push_back(x);
      }
      outer[static_cast<std::size_t>(r) + 1] = static_cast<int>(list.size());
    }
#pragma omp single
    {
      for (int r = 0; r < n; ++r) outer[static_cast<std::size_t>(r) + 1] += outer[r];
      m.resizeNonZeros(outer[n]);
    }
    // (the single's barrier: offsets and storage ready)
    if (first >= 0) {
      std::copy(inner.begin(), inner.end(), m.innerIndexPtr() + outer[first]);
      std::copy(value.begin(), value.end(), m.valuePtr() + outer[first]);
    }
  }
  std::copy(outer.begin(), outer.end(), m.outerIndexPtr());
}

}  // namespace

template <int Dim>
SparseMatrix stress_compliance(const StressLayout<Dim>& layout, const StokesDofs& dofs,
                               const StokesWeights& w, double min_fluid_fraction) {
  const StressGrid<Dim>& stress = layout.grid();
  const int n = dofs.num_stress();
  auto h = [&](int d) {
    const double wf = w.fluid_stress[d] > 0.0 ? std::max(w.fluid_stress[d], min_fluid_fraction) : 0.0;
    return 0.5 * StressGrid<Dim>::multiplicity(stress.coord(d).first) *
           reciprocal_or_zero(w.viscosity[d]) * wf * w.liquid_stress[d];
  };
  std::vector<Triplet> t;
  t.reserve(2 * n);
  const bool reduced = layout.form() == StressForm::reduced;
  for (int i = 0; i < n; ++i) {
    const int d = layout.dof_of_unknown(dofs.unknown_of_dof[i]);
    const int k = stress.coord(d).first;
    double self = h(d);
    if (reduced && StressGrid<Dim>::is_diagonal(k)) {
      const int e = eliminated_dof(stress, k, d);
      self += h(e);
      if constexpr (Dim == 3) {
        // the other diagonal unknown of the cell couples through the eliminated DOF (E^T N^-1 E)
        const int other = stress.offset(1 - k) + (d - stress.offset(k));
        const int u = layout.unknown_of_dof(other);
        const int j = u >= 0 ? dofs.dof_of_unknown[u] : -1;
        if (j >= 0) t.emplace_back(i, j, h(e));
      }
    }
    t.emplace_back(i, i, self);
  }
  SparseMatrix kmat(n, n);
  kmat.setFromTriplets(t.begin(), t.end());
  kmat.makeCompressed();
  return kmat;
}

template <int Dim>
StokesFactors stokes_factors(const MacGrid<Dim>& grid, const StressLayout<Dim>& layout,
                             const StokesWeights& w, const StokesDofs& dofs, double dt,
                             const ExplicitStokesSystem& s, double min_fluid_fraction) {
  StokesFactors f;
  fill_common(layout, w, dofs, min_fluid_fraction, f);
  f.sweep_order = stokes_sweep_order(grid, layout, dofs);
  // C = dt W_F^u P^-1 (W_L^u)^-1 and its active faces
  const VectorX c_all = dt * VectorX(s.W_F_u.diagonal().cwiseProduct(s.P_inv.diagonal())
                                          .cwiseProduct(s.W_L_u_inv.diagonal()));
  std::vector<int> active_of_face(c_all.size(), -1);
  for (int face = 0; face < c_all.size(); ++face)
    if (c_all[face] > 0.0) {
      active_of_face[face] = static_cast<int>(f.face.size());
      f.face.push_back(face);
    }
  f.c.resize(f.face.size());
  for (std::size_t q = 0; q < f.face.size(); ++q) f.c[q] = c_all[f.face[q]];
  // B = [D^T M W_L^s E S_tau^T, G W_L^p S_p^T] by their paper names, as B^T row by row
  const SparseMatrix bt_stress =
      SparseMatrix(s.S_tau * SparseMatrix(s.E.transpose())) * SparseMatrix(s.W_L_s * s.M * s.D);
  const SparseMatrix bt_pressure = s.S_p.rows() > 0
                                       ? SparseMatrix(SparseMatrix(s.S_p * s.W_L_p) * SparseMatrix(s.G.transpose()))
                                       : SparseMatrix(0, c_all.size());
  std::vector<Triplet> t;
  for (int i = 0; i < bt_stress.outerSize(); ++i)
    for (SparseMatrix::InnerIterator it(bt_stress, i); it; ++it)
      if (active_of_face[it.col()] >= 0 && it.value() != 0.0) t.emplace_back(i, active_of_face[it.col()], it.value());
  for (int i = 0; i < bt_pressure.outerSize(); ++i)
    for (SparseMatrix::InnerIterator it(bt_pressure, i); it; ++it)
      if (active_of_face[it.col()] >= 0 && it.value() != 0.0)
        t.emplace_back(f.num_stress + i, active_of_face[it.col()], it.value());
  finish_b(t, f.size(), f);
  return f;
}

template <int Dim>
StokesFactors stokes_factors(const MacGrid<Dim>& grid, const StressLayout<Dim>& layout,
                             const StokesWeights& w, const StokesDofs& dofs, double dt,
                             const MatrixFreeStokesOperator<Dim>& op, double min_fluid_fraction) {
  (void)dt;
  StokesFactors f;
  fill_common(layout, w, dofs, min_fluid_fraction, f);
  const VectorX& c_all = op.face_coefficients();
  std::vector<int> active_of_face(grid.num_faces(), -1);
  for (int face = 0; face < c_all.size(); ++face)
    if (c_all[face] > 0.0) {
      active_of_face[face] = static_cast<int>(f.face.size());
      f.face.push_back(face);
    }
  f.c.resize(f.face.size());
  for (std::size_t q = 0; q < f.face.size(); ++q) f.c[q] = c_all[f.face[q]];
  // the columns of B from the operator's stencils, per unknown (parallel, merged in order)
  const int n = f.size();
  assemble_rows(n, static_cast<int>(f.face.size()), f.b_transpose, [&]() {
    return [&](int i, std::vector<std::pair<int, double>>& row) {
      // row i of B^T: the active faces, sorted, a repeated face summed in the stencil's order (the
      // matrix setFromTriplets built from these entries, without the triplet list)
      row = op.stencil(i);
      std::size_t kept = 0;
      for (const auto& [face, coef] : row)
        if (active_of_face[face] >= 0 && coef != 0.0) row[kept++] = {active_of_face[face], coef};
      row.resize(kept);
      std::stable_sort(row.begin(), row.end(), [](const auto& x, const auto& y) { return x.first < y.first; });
      std::size_t out = 0;
      for (std::size_t q = 0; q < row.size(); ++q) {
        if (out > 0 && row[out - 1].first == row[q].first) row[out - 1].second += row[q].second;
        else row[out++] = row[q];
      }
      row.resize(out);
    };
  });
  f.b = f.b_transpose.transpose();
  f.b.makeCompressed();
  return f;
}

SparseMatrix block_diagonal_inverse(const SparseMatrix& k) {
  const int n = static_cast<int>(k.rows());
  std::vector<Triplet> t;
  t.reserve(k.nonZeros());
  std::vector<char> done(n, 0);
  for (int i = 0; i < n; ++i) {
    if (done[i]) continue;
    std::array<int, 3> member{};
    int m = 0;
    for (SparseMatrix::InnerIterator it(k, i); it; ++it) {
      if (m == 3) throw std::invalid_argument("block_diagonal_inverse: a block larger than 3");
      member[m++] = static_cast<int>(it.col());
    }
    if (m == 0) continue;
    Eigen::Matrix3d block = Eigen::Matrix3d::Identity();
    for (int a = 0; a < m; ++a)
      for (int b = 0; b < m; ++b) block(a, b) = k.coeff(member[a], member[b]);
    const Eigen::Matrix3d inv = block.inverse();
    for (int a = 0; a < m; ++a) {
      done[member[a]] = 1;
      for (int b = 0; b < m; ++b) t.emplace_back(member[a], member[b], 0.5 * (inv(a, b) + inv(b, a)));
    }
  }
  SparseMatrix r(n, n);
  r.setFromTriplets(t.begin(), t.end());
  r.makeCompressed();
  return r;
}

SparseMatrix velocity_operator(const StokesFactors& f, const VectorX& penalty, const SparseMatrix* kinv_given) {
  const int nf = static_cast<int>(f.face.size());
  const int ns = f.num_stress;
  if (penalty.size() != f.num_pressure)
    throw std::invalid_argument("velocity_operator: one penalty per pressure unknown expected");
  SparseMatrix kinv_own;
  if (!kinv_given) kinv_own = block_diagonal_inverse(f.compliance);
  const SparseMatrix& kinv = kinv_given ? *kinv_given : kinv_own;
  // D^-1 per unknown as (column, value) lists: K^-1 blocks, then 1/penalty
  auto dinv_row = [&](int i, const auto& visit) {
    if (i < ns) {
      for (SparseMatrix::InnerIterator it(kinv, i); it; ++it) visit(static_cast<int>(it.col()), it.value());
    } else {
      visit(i, 1.0 / penalty[i - ns]);
    }
  };
  const int* b_outer = f.b.outerIndexPtr();
  const int* b_inner = f.b.innerIndexPtr();
  const double* b_value = f.b.valuePtr();
  const int* t_outer = f.b_transpose.outerIndexPtr();
  const int* t_inner = f.b_transpose.innerIndexPtr();
  const double* t_value = f.b_transpose.valuePtr();
  SparseMatrix v;
  assemble_rows(nf, nf, v, [&]() {
    // slot[g]: the position of column g in the current row (-1: none yet), the linear search's
    // answer in one load; contributions are summed in the same order (one array per thread)
    auto slot = std::make_shared<std::vector<int>>(static_cast<std::size_t>(nf), -1);
    return [&, slot](int r, std::vector<std::pair<int, double>>& row) {
      int* sl = slot->data();
      row.emplace_back(r, 1.0 / f.c[r]);
      sl[r] = 0;
      for (int q = b_outer[r]; q < b_outer[r + 1]; ++q) {
        const int i = b_inner[q];
        const double bri = b_value[q];
        dinv_row(i, [&](int j, double dij) {
          const double s = bri * dij;
          for (int p = t_outer[j]; p < t_outer[j + 1]; ++p) {
            const int g = t_inner[p];
            const double x = s * t_value[p];
            if (sl[g] < 0) {
              sl[g] = static_cast<int>(row.size());
              row.emplace_back(g, x);
            } else {
              row[sl[g]].second += x;
            }
          }
        });
      }
      for (const auto& e : row) sl[e.first] = -1;
      std::sort(row.begin(), row.end());
    };
  });
  return v;
}

template <int Dim>
ExtraPatches<Dim> stress_element_patches(const StokesFactors& f) {
  ExtraPatches<Dim> extra;
  const std::size_t ne = f.element_unknowns.size();
  extra.unknowns.reserve(ne);
  std::vector<int> faces;
  for (std::size_t e = 0; e < ne; ++e) {
    // a diagonal element's faces are those of its cell, whose patch the hierarchy has already
    if (f.element_component[e] < Dim) continue;
    faces.clear();
    for (int i : f.element_unknowns[e])
      for (SparseMatrix::InnerIterator it(f.b_transpose, i); it; ++it) faces.push_back(static_cast<int>(it.col()));
    std::sort(faces.begin(), faces.end());
    faces.erase(std::unique(faces.begin(), faces.end()), faces.end());
    if (faces.empty() || static_cast<int>(faces.size()) > PatchSet::kMaxPatchSize) continue;
    extra.unknowns.push_back(faces);
    VecI<Dim> pos;
    for (int a = 0; a < Dim; ++a) pos[a] = f.element_coord[e][a];
    extra.position.push_back(pos);
    extra.kind.push_back(f.element_component[e]);
  }
  return extra;
}

#define MONOLITH_INSTANTIATE(D)                                                                   \
  template SparseMatrix stress_compliance<D>(const StressLayout<D>&, const StokesDofs&,            \
                                             const StokesWeights&, double);                       \
  template StokesFactors stokes_factors<D>(const MacGrid<D>&, const StressLayout<D>&,              \
                                           const StokesWeights&, const StokesDofs&, double,        \
                                           const ExplicitStokesSystem&, double);                  \
  template StokesFactors stokes_factors<D>(const MacGrid<D>&, const StressLayout<D>&,              \
                                           const StokesWeights&, const StokesDofs&, double,        \
                                           const MatrixFreeStokesOperator<D>&, double);           \
  template ExtraPatches<D> stress_element_patches<D>(const StokesFactors&);
MONOLITH_INSTANTIATE(2)
MONOLITH_INSTANTIATE(3)
#undef MONOLITH_INSTANTIATE

}  // namespace monolith
