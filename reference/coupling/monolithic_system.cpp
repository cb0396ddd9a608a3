#include "reference/coupling/monolithic_system.hpp"

#include "reference/core/parallel.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <array>
#include <map>
#include <unordered_map>
#include <memory>
#include <stdexcept>
#include <utility>

#include "reference/contact/staggered_projections.hpp"
#include "reference/solvers/colouring.hpp"
#include "reference/solvers/mprgp.hpp"
#include "reference/coupling/coupled_preconditioner.hpp"

namespace monolith {

namespace {

/// The explicit fluid part F = stokes().A as a LinearOperator without a second copy of A: rows
/// in index order for the sweeps, as SparseMatrixOperator does (same arithmetic, same iterates).
/// explicit_matrix() exposes A, so the block preconditioner sweeps it in the matrix-free
/// operator's order, as it does SparseMatrixOperator's (docs/preconditioners.md, section 25).
class ExplicitStokesOperator : public LinearOperator {
 public:
  explicit ExplicitStokesOperator(std::shared_ptr<const ExplicitStokesSystem> system)
      : system_(std::move(system)), diagonal_(system_->A.diagonal()) {}
  int size() const override { return static_cast<int>(system_->A.rows()); }
  void apply(const VectorX& x, VectorX& y) const override { sparse_row_product(system_->A, x, y); }
  VectorX diagonal() const override { return diagonal_; }
  const SparseMatrix* explicit_matrix() const override { return &system_->A; }
  void forward_sweep(const VectorX& rhs, VectorX& x, double omega,
                     const std::vector<char>* active = nullptr) const override {
    for (int i = 0; i < size(); ++i)
      if (!active || (*active)[i]) relax_row(i, rhs, x, omega);
  }
  void backward_sweep(const VectorX& rhs, VectorX& x, double omega,
                      const std::vector<char>* active = nullptr) const override {
    for (int i = size() - 1; i >= 0; --i)
      if (!active || (*active)[i]) relax_row(i, rhs, x, omega);
  }

 private:
  void relax_row(int i, const VectorX& rhs, VectorX& x, double omega) const {
    if (diagonal_[i] == 0.0) return;
    double off = 0.0;
    for (SparseMatrix::InnerIterator it(system_->A, i); it; ++it)
      if (it.col() != i) off += it.value() * x[it.col()];
    x[i] = (1.0 - omega) * x[i] + omega * (rhs[i] - off) / diagonal_[i];
  }
  std::shared_ptr<const ExplicitStokesSystem> system_;
  VectorX diagonal_;
};

}  // namespace

template <int Dim>
MonolithicSystem<Dim>::MonolithicSystem(const MacGrid<Dim>& grid, StressForm form,
                                        const StokesWeights& w, double dt, const VectorX& u_star,
                                        const std::vector<RigidBody<Dim>>& bodies,
                                        const SolidWeights<Dim>& solids,
                                        const ContactSystem<Dim>& contacts,
                                        Backend backend, StokesUnknowns unknowns)
    : MonolithicSystem(grid, form, std::make_shared<const StokesWeights>(w), dt, u_star, bodies,
                       solids, contacts, backend, unknowns) {}

template <int Dim>
MonolithicSystem<Dim>::MonolithicSystem(const MacGrid<Dim>& grid, StressForm form,
                                        std::shared_ptr<const StokesWeights> weights, double dt,
                                        const VectorX& u_star,
                                        const std::vector<RigidBody<Dim>>& bodies,
                                        const SolidWeights<Dim>& solids,
                                        const ContactSystem<Dim>& contacts,
                                        Backend backend, StokesUnknowns unknowns)
    : MonolithicSystem(grid, form, std::move(weights), dt, std::make_shared<const VectorX>(u_star),
                       bodies, solids, contacts, backend, unknowns) {}

template <int Dim>
MonolithicSystem<Dim>::MonolithicSystem(const MacGrid<Dim>& grid, StressForm form,
                                        std::shared_ptr<const StokesWeights> weights, double dt,
                                        std::shared_ptr<const VectorX> u_star_shared,
                                        const std::vector<RigidBody<Dim>>& bodies,
                                        const SolidWeights<Dim>& solids,
                                        const ContactSystem<Dim>& contacts,
                                        Backend backend, StokesUnknowns unknowns,
                                        StokesWorkspace* workspace)
    : grid_(grid), stress_(grid), layout_(stress_, form), w_owner_(std::move(weights)),
      w_(*w_owner_), dt_(dt), u_star_owner_(std::move(u_star_shared)), u_star_(*u_star_owner_),
      backend_(backend), unknowns_(unknowns),
      matrix_free_(backend == Backend::matrix_free), contacts_(contacts) {
  const VectorX& u_star = u_star_;
  const StokesWeights& w = w_;
  // alpha = 1 / dx^Dim, shared with the contact blocks (section 4.1)
  alpha_ = 1.0 / std::pow(grid.dx(), Dim);
  if (std::abs(contacts.alpha - alpha_) > 1e-12 * alpha_)
    throw std::invalid_argument("MonolithicSystem: ContactSystem alpha differs from 1/dx^Dim");
  // the liquid blocks: eq. (8) restricted to the active DOFs
  dofs_ = select_stokes_dofs<Dim>(grid, layout_, w, dt, unknowns,
                                  workspace ? &workspace->band : nullptr);
  const int nd = contacts.num_body_dofs();
  const std::vector<CouplingBody<Dim>> view = coupling_bodies(bodies);
  // J_p's columns only at the pressure unknowns' cells and J_s only with stress unknowns: the
  // system reads no other column (add_body_rhs and build_rigid_columns select the unknowns; the
  // explicit products go through S_p^T and S_tau), and the surface search then costs the
  // unknowns, not the bodies' boxes (issue 20: Fig. 17's basin spans half the lattice)
  //
  // Likewise J_s's columns only at the stress DOFs the system reads (issue 20, Fig. 18): the
  // stress unknowns' DOFs and, in the reduced form, the eliminated component's DOF of each
  // cell with a diagonal unknown (add_body_rhs reads it through E^T, build_rigid_columns
  // through E's row of that DOF); every other column meets no unknown in E S_tau^T.
  std::vector<int> stress_wanted;
  if (num_stress() > 0) {
    const bool reduced = layout_.form() == StressForm::reduced;
    const int eliminated = stress_.offset(Dim - 1);
    stress_wanted.reserve(static_cast<std::size_t>(num_stress()) * (reduced ? 2 : 1));
    for (int k = 0; k < num_stress(); ++k) {
      const int u = dofs_.unknown_of_dof[k];
      const int d = layout_.dof_of_unknown(u);
      stress_wanted.push_back(d);
      const int comp = layout_.component(layout_.component_of_unknown(u));
      if (reduced && StressGrid<Dim>::is_diagonal(comp))
        stress_wanted.push_back(eliminated + (d - stress_.offset(comp)));
    }
    std::sort(stress_wanted.begin(), stress_wanted.end());
    stress_wanted.erase(std::unique(stress_wanted.begin(), stress_wanted.end()),
                        stress_wanted.end());
  }
  typename BodyCouplingOperator<Dim>::Columns wanted;
  wanted.cells = &dofs_.pressure.cell_of_dof;
  wanted.stress = num_stress() > 0;
  wanted.stress_dofs = &stress_wanted;
  if (search_every_column) wanted = typename BodyCouplingOperator<Dim>::Columns{};
  const BodyCouplingOperator<Dim> two(grid, view, solids, BodyGroup::two_way, wanted);
  const BodyCouplingOperator<Dim> one(grid, view, solids, BodyGroup::one_way, wanted);
  if (two.num_rows() != nd)
    throw std::invalid_argument("MonolithicSystem: bodies and ContactSystem disagree");
  j_lambda_t_ = contacts.j_lambda.transpose();
  j_z_t_ = contacts.j_z.transpose();

  const VectorX v_one = group_velocities(bodies, BodyGroup::one_way);
  // rhs_round_off(): the bound (2 Dim / dx) U on the terms of b1, b2 (header)
  {
    // (over the workspace's speed boxes when it promises u* = 0 outside them: the same value)
    double speed = weighted_face_speed(grid, w.pressure.fluid_face, u_star,
                                       workspace ? &workspace->band : nullptr);
    for (const VectorX* v : {&contacts.v_star, &v_one})
      for (int k = 0; k < v->size(); ++k)
        if (k % kBodyDofs<Dim> < Dim) speed = std::max(speed, std::abs((*v)[k]));
    rhs_round_off_ = kRhsRoundOffUlps * kEpsilon * (2.0 * Dim / grid.dx()) * speed;
  }

  if (matrix_free_) {
    // the fluid part by stencils; b = B^T W_F^u u* by the same stencils
    auto op = std::make_shared<MatrixFreeStokesOperator<Dim>>(grid, layout_, w, dofs_, dt,
                                                              workspace);
    const VectorX b = op->rhs(u_star);
    matrix_free_stokes_ = op;
    stokes_operator_ = op;
    b1_ = b.head(num_stress());
    b2_ = b.tail(num_pressure());
    add_body_rhs(two, one, contacts.v_star, v_one);
    build_rigid_columns(two);
    return;
  }

  // the body part of b1, b2: alpha W_L J^T v* of both groups (subtracted; section 4.4.4), over
  // all stress DOFs and cells
  VectorX body_stress = VectorX::Zero(stress_.num_dofs());
  VectorX body_cells = VectorX::Zero(grid.num_cells());
  // (inviscid weights may come without W_L^s: zeros then)
  VectorX zeros;
  if (w.liquid_stress.size() == 0) zeros.setZero(stress_.num_dofs());
  const VectorX& liquid_stress = w.liquid_stress.size() > 0 ? w.liquid_stress : zeros;
  subtract_body_stress_rhs<Dim>(two, grid, liquid_stress, contacts.v_star, body_stress);
  subtract_body_pressure_rhs<Dim>(two, grid, w.pressure.liquid_cell, contacts.v_star, body_cells);
  if (one.num_rows() > 0) {
    subtract_body_stress_rhs<Dim>(one, grid, liquid_stress, v_one, body_stress);
    subtract_body_pressure_rhs<Dim>(one, grid, w.pressure.liquid_cell, v_one, body_cells);
  }

  // explicit: every matrix of eq. (8) by name
  auto explicit_system = std::make_shared<ExplicitStokesSystem>(
      assemble_explicit_stokes<Dim>(grid, layout_, w, dofs_, dt, u_star));
  stokes_ = explicit_system;
  stokes_operator_ = std::make_shared<ExplicitStokesOperator>(stokes_);
  const ExplicitStokesSystem& st = *stokes_;
  // B_1 = Jh_s W_L^s E S_tau^T, B_2 = Jh_p W_L^p S_p^T over the two-way bodies
  const SparseMatrix b_tau = SparseMatrix(two.stress_jacobian() * st.W_L_s) * st.E *
                             SparseMatrix(st.S_tau.transpose());
  const SparseMatrix b_p =
      SparseMatrix(two.pressure_jacobian() * st.W_L_p) * SparseMatrix(st.S_p.transpose());
  std::vector<Triplet> t;
  for (int k = 0; k < b_tau.outerSize(); ++k)
    for (SparseMatrix::InnerIterator it(b_tau, k); it; ++it)
      t.emplace_back(it.row(), it.col(), it.value());
  for (int k = 0; k < b_p.outerSize(); ++k)
    for (SparseMatrix::InnerIterator it(b_p, k); it; ++it)
      t.emplace_back(it.row(), num_stress() + it.col(), it.value());
  b_fluid_.resize(nd, num_fluid());
  b_fluid_.setFromTriplets(t.begin(), t.end());
  b_fluid_t_ = b_fluid_.transpose();
  b1_ = st.b1 + st.S_tau * (st.E.transpose() * body_stress);
  b2_ = st.b2 + st.S_p * body_cells;
}

template <int Dim>
void MonolithicSystem<Dim>::add_body_rhs(const BodyCouplingOperator<Dim>& two,
                                         const BodyCouplingOperator<Dim>& one,
                                         const VectorX& v_two, const VectorX& v_one) {
  // The body part of b1, b2 of eq. (24) (section 4.4.4): b -= S E^T (alpha W_L J^T v) over both
  // groups, as subtract_body_stress_rhs / subtract_body_pressure_rhs and expand_transpose compute
  // it over every stress DOF and cell (the explicit back end still does), here over the bodies'
  // surface DOFs only: per touched DOF the sums J^T v of each group in the same order (bodies,
  // then their surface DOFs), combined as 0 - alpha (W_L t_two) - alpha (W_L t_one); every other
  // DOF is +0 there. Each active unknown then adds its value (+0 when untouched, as before: the
  // bits of a -0 entry of b change under + 0 exactly as they did).
  const double alpha = 1.0 / grid_.cell_volume();
  const bool with_one = one.num_rows() > 0;
  // touched DOF -> (t_two, t_one)
  auto sums = [&](bool stress) {
    std::unordered_map<int, std::array<double, 2>> t;
    auto add = [&](const BodyCouplingOperator<Dim>& op, const VectorX& v, int g) {
      for (const auto& c : stress ? op.stress_columns() : op.pressure_columns()) {
        auto& e = t.try_emplace(c.index, std::array<double, 2>{0.0, 0.0}).first->second;
        e[g] += c.column.dot(v.template segment<kBodyDofs<Dim>>(c.row));
      }
    };
    add(two, v_two, 0);
    if (with_one) add(one, v_one, 1);
    return t;
  };
  auto value = [&](const std::unordered_map<int, std::array<double, 2>>& t, int index,
                   double wl) {
    const auto it = t.find(index);
    const double t_two = it == t.end() ? 0.0 : it->second[0];
    double v = 0.0;
    v -= alpha * (wl * t_two);
    if (with_one) v -= alpha * (wl * (it == t.end() ? 0.0 : it->second[1]));
    return v;
  };
  if (num_pressure() > 0) {
    const auto t = sums(false);
    const VectorX& wl = w_.pressure.liquid_cell;
    for (int k = 0; k < num_pressure(); ++k) {
      const int c = dofs_.pressure.cell_of_dof[k];
      b2_[k] += value(t, c, wl[c]);
    }
  }
  if (num_stress() > 0) {
    const auto t = sums(true);
    const VectorX& wl = w_.liquid_stress;
    const bool reduced = layout_.form() == StressForm::reduced;
    const int eliminated = stress_.offset(Dim - 1);
    for (int k = 0; k < num_stress(); ++k) {
      // (E^T s)_u = s at the unknown's DOF, minus s at the eliminated DOF of its cell (reduced
      // form, diagonal components)
      const int u = dofs_.unknown_of_dof[k];
      const int j = layout_.component_of_unknown(u);
      const int comp = layout_.component(j);
      const int local = u - layout_.offset(j);
      const int d = stress_.offset(comp) + local;
      double e = value(t, d, wl[d]);
      if (reduced && StressGrid<Dim>::is_diagonal(comp))
        e -= value(t, eliminated + local, wl[eliminated + local]);
      b1_[k] += e;
    }
  }
}

template <int Dim>
void MonolithicSystem<Dim>::build_rigid_columns(const BodyCouplingOperator<Dim>& two) {
  // column u of B_f, body block at `row`: sum over the body's J columns that reach unknown u,
  // with W_L and E folded in; keyed by (unknown, row) so repeated contributions add up
  std::map<std::pair<int, int>, BodyVec<Dim>> blocks;
  auto add = [&](int unknown, int row, const BodyVec<Dim>& column) {
    auto [it, inserted] = blocks.emplace(std::make_pair(unknown, row), column);
    if (!inserted) it->second += column;
  };
  // B_2 = Jh_p W_L^p S_p^T: active pressure cells only
  if (num_pressure() > 0)
    for (const auto& c : two.pressure_columns()) {
      const int k = dofs_.pressure.dof_of_cell[c.index];
      const double wl = w_.pressure.liquid_cell[c.index];
      if (k < 0 || wl == 0.0) continue;
      add(num_stress() + k, c.row, wl * c.column);
    }
  // B_1 = Jh_s W_L^s E S_tau^T: the stress DOF's row of E (the unknown itself, or in the reduced
  // form minus every diagonal unknown of the cell for the eliminated component), then S_tau
  if (num_stress() > 0)
    for (const auto& c : two.stress_columns()) {
      const double wl = w_.liquid_stress[c.index];
      if (wl == 0.0) continue;
      const int unknown = layout_.unknown_of_dof(c.index);
      auto add_unknown = [&](int u, double coef) {
        const int k = dofs_.dof_of_unknown[u];
        if (k >= 0) add(k, c.row, (coef * wl) * c.column);
      };
      if (unknown >= 0) {
        add_unknown(unknown, 1.0);
        continue;
      }
      const int local = c.index - stress_.offset(Dim - 1);
      for (int j = 0; j < layout_.num_components(); ++j)
        if (StressGrid<Dim>::is_diagonal(layout_.component(j)))
          add_unknown(layout_.offset(j) + local, -1.0);
    }
  rigid_columns_.clear();
  rigid_columns_.reserve(blocks.size());
  for (const auto& [key, column] : blocks) {
    RigidColumn r;
    r.unknown = key.first;
    r.row = key.second;
    r.column = column;
    rigid_columns_.push_back(r);
  }
}

template <int Dim>
const ExplicitStokesSystem& MonolithicSystem<Dim>::stokes() const {
  static const ExplicitStokesSystem empty;
  return stokes_ ? *stokes_ : empty;
}

template <int Dim>
void MonolithicSystem<Dim>::fluid_body_force_into(const Eigen::Ref<const VectorX>& x_fluid,
                                                  VectorX& force) const {
  if (!matrix_free_) {
    force.noalias() = b_fluid_ * x_fluid;
    return;
  }
  // serial over the surface: a fixed summation order for any thread count
  force.setZero();
  for (const RigidColumn& c : rigid_columns_)
    force.template segment<kBodyDofs<Dim>>(c.row) += c.column * x_fluid[c.unknown];
}

template <int Dim>
void MonolithicSystem<Dim>::add_fluid_body_force_transpose(const VectorX& f, double scale,
                                                           Eigen::Ref<VectorX> y) const {
  if (!matrix_free_) {
    y += scale * (b_fluid_t_ * f);
    return;
  }
  for (const RigidColumn& c : rigid_columns_)
    y[c.unknown] += scale * c.column.dot(f.template segment<kBodyDofs<Dim>>(c.row));
}

template <int Dim>
VectorX MonolithicSystem<Dim>::fluid_body_force(const VectorX& x_fluid) const {
  if (!matrix_free_) return b_fluid_ * x_fluid;
  VectorX force(num_body_dofs());
  fluid_body_force_into(x_fluid, force);
  return force;
}

template <int Dim>
VectorX MonolithicSystem<Dim>::fluid_body_force_transpose(const VectorX& f) const {
  if (!matrix_free_) return b_fluid_t_ * f;
  VectorX y = VectorX::Zero(num_fluid());
  add_fluid_body_force_transpose(f, 1.0, y);
  return y;
}

template <int Dim>
void MonolithicSystem<Dim>::add_rigid_diagonal(double scale, Eigen::Ref<VectorX> diagonal) const {
  if (num_body_dofs() == 0) return;
  if (!matrix_free_) {
    // sum_r B_ru (M_r^-1 B)_ru, column by column of B_f
    const SparseMatrix mb = contacts_.m_r_inverse * b_fluid_;
    const SparseMatrix prod = b_fluid_.cwiseProduct(mb);
    for (int k = 0; k < prod.outerSize(); ++k)
      for (SparseMatrix::InnerIterator it(prod, k); it; ++it)
        diagonal[it.col()] += scale * it.value();
    return;
  }
  // M_r^-1 is block diagonal per body: c^T M_b^-1 c per column block
  using Block = Eigen::Matrix<double, kBodyDofs<Dim>, kBodyDofs<Dim>>;
  const Eigen::MatrixXd m_inv(contacts_.m_r_inverse);
  for (const RigidColumn& c : rigid_columns_) {
    const Block m = m_inv.block<kBodyDofs<Dim>, kBodyDofs<Dim>>(c.row, c.row);
    diagonal[c.unknown] += scale * c.column.dot(m * c.column);
  }
}

template <int Dim>
double MonolithicSystem<Dim>::fluid_body_jacobian_abs_sum() const {
  if (!matrix_free_) return b_fluid_.cwiseAbs().sum();
  double sum = 0.0;
  for (const RigidColumn& c : rigid_columns_) sum += c.column.cwiseAbs().sum();
  return sum;
}

template <int Dim>
int MonolithicSystem<Dim>::block_size(int i) const {
  switch (i) {
    case 1: return num_stress();
    case 2: return num_pressure();
    case 3: return num_contacts();
    case 4: return num_friction();
    default: throw std::invalid_argument("MonolithicSystem: block index outside 1..4");
  }
}

template <int Dim>
VectorX MonolithicSystem<Dim>::body_force(int j, const VectorX& x) const {
  // B_j x in body space (nd)
  if (matrix_free_ && j <= 2) {
    VectorX xf = VectorX::Zero(num_fluid());
    xf.segment(j == 1 ? 0 : num_stress(), x.size()) = x;
    return fluid_body_force(xf);
  }
  switch (j) {
    case 1: return b_fluid_.leftCols(num_stress()) * x;
    case 2: return b_fluid_.rightCols(num_pressure()) * x;
    case 3: return j_lambda_t_ * x;
    case 4: return j_z_t_ * x;
    default: throw std::invalid_argument("MonolithicSystem: block index outside 1..4");
  }
}

template <int Dim>
VectorX MonolithicSystem<Dim>::body_force_transpose(int i, const VectorX& f) const {
  if (matrix_free_ && i <= 2) {
    const VectorX y = fluid_body_force_transpose(f);
    return i == 1 ? VectorX(y.head(num_stress())) : VectorX(y.tail(num_pressure()));
  }
  switch (i) {
    case 1: return b_fluid_t_.topRows(num_stress()) * f;
    case 2: return b_fluid_t_.bottomRows(num_pressure()) * f;
    case 3: return contacts_.j_lambda * f;
    case 4: return contacts_.j_z * f;
    default: throw std::invalid_argument("MonolithicSystem: block index outside 1..4");
  }
}

template <int Dim>
VectorX MonolithicSystem<Dim>::apply_block(int i, int j, const VectorX& x) const {
  if (x.size() != block_size(j)) throw std::invalid_argument("MonolithicSystem: block size");
  // rigid part by sequential multiplication: dt alpha B_i^T (M_r^-1 (B_j x))
  VectorX y = VectorX::Zero(block_size(i));
  if (num_body_dofs() > 0) {
    const VectorX f = contacts_.m_r_inverse * body_force(j, x);
    y = (dt_ * alpha_) * body_force_transpose(i, f);
  }
  // fluid part (stokes_system.hpp): the (tau, p) blocks of A
  if (i <= 2 && j <= 2) {
    const int ns = num_stress();
    const int row0 = i == 1 ? 0 : ns, col0 = j == 1 ? 0 : ns;
    VectorX xf = VectorX::Zero(num_fluid());
    xf.segment(col0, x.size()) = x;
    VectorX yf;
    if (matrix_free_)
      stokes_operator_->apply(xf, yf);
    else
      yf = stokes_->A * xf;
    y += yf.segment(row0, y.size());
  }
  return y;
}

template <int Dim>
Eigen::MatrixXd MonolithicSystem<Dim>::dense_matrix() const {
  int offset[5] = {0, 0, 0, 0, 0};
  for (int i = 1; i <= 4; ++i) offset[i] = offset[i - 1] + block_size(i);
  Eigen::MatrixXd a = Eigen::MatrixXd::Zero(offset[4], offset[4]);
  for (int j = 1; j <= 4; ++j)
    for (int c = 0; c < block_size(j); ++c) {
      VectorX e = VectorX::Zero(block_size(j));
      e[c] = 1.0;
      for (int i = 1; i <= 4; ++i)
        if (block_size(i) > 0) a.block(offset[i - 1], offset[j - 1] + c, block_size(i), 1) = apply_block(i, j, e);
    }
  return a;
}

template <int Dim>
VectorX MonolithicSystem<Dim>::rhs() const {
  VectorX b(num_fluid() + num_contacts() + num_friction());
  b << b1_, b2_, b3(), b4();
  return b;
}

template <int Dim>
VectorX MonolithicSystem<Dim>::mlcp_rhs(const VectorX& z) const {
  VectorX b(num_fluid() + num_contacts());
  b << b1_, b2_, b3();
  if (num_friction() > 0 && num_body_dofs() > 0) {
    // (A14 z, A24 z, A34 z) = dt alpha (B_1, B_2, J_lambda)^T M_r^-1 J_z^T z
    const VectorX f = contacts_.m_r_inverse * (j_z_t_ * z);
    if (matrix_free_)
      add_fluid_body_force_transpose(f, -dt_ * alpha_, b.head(num_fluid()));
    else
      b.head(num_fluid()) -= (dt_ * alpha_) * (b_fluid_t_ * f);
    b.tail(num_contacts()) -= (dt_ * alpha_) * (contacts_.j_lambda * f);
  }
  return b;
}

template <int Dim>
VectorX MonolithicSystem<Dim>::friction_rhs(const VectorX& x) const {
  VectorX b = b4();
  if (num_friction() == 0 || num_body_dofs() == 0) return b;
  // b4 - dt alpha J_z M_r^-1 (B_f x_f + J_lambda^T lambda)
  const VectorX force =
      fluid_body_force(x.head(num_fluid())) + j_lambda_t_ * x.segment(num_fluid(), num_contacts());
  b -= (dt_ * alpha_) * (contacts_.j_z * (contacts_.m_r_inverse * force));
  return b;
}

template <int Dim>
VectorX MonolithicSystem<Dim>::fluid_rhs(const VectorX& lambda, const VectorX& z) const {
  VectorX b(num_fluid());
  b << b1_, b2_;
  if (num_body_dofs() == 0 || num_fluid() == 0) return b;
  // dt alpha B_f^T M_r^-1 (J_lambda^T lambda + J_z^T z), in body space first
  VectorX force = VectorX::Zero(num_body_dofs());
  if (lambda.size() == num_contacts() && num_contacts() > 0) force += j_lambda_t_ * lambda;
  if (z.size() == num_friction() && num_friction() > 0) force += j_z_t_ * z;
  if (matrix_free_)
    add_fluid_body_force_transpose(contacts_.m_r_inverse * force, -dt_ * alpha_, b);
  else
    b -= (dt_ * alpha_) * (b_fluid_t_ * (contacts_.m_r_inverse * force));
  return b;
}

template <int Dim>
VectorX MonolithicSystem<Dim>::contact_rhs(const VectorX& x_fluid, const VectorX& z) const {
  VectorX b = b3();
  if (num_body_dofs() == 0 || num_contacts() == 0) return b;
  // b3 - dt alpha J_lambda M_r^-1 (B_f x_f + J_z^T z)
  VectorX force = VectorX::Zero(num_body_dofs());
  if (x_fluid.size() == num_fluid() && num_fluid() > 0) force += fluid_body_force(x_fluid);
  if (z.size() == num_friction() && num_friction() > 0) force += j_z_t_ * z;
  b -= (dt_ * alpha_) * (contacts_.j_lambda * (contacts_.m_r_inverse * force));
  return b;
}

template <int Dim>
VectorX MonolithicSystem<Dim>::body_velocities(const VectorX& x_fluid, const VectorX& lambda,
                                               const VectorX& z) const {
  // eq. (21): the contact impulses (ContactSystem) plus the liquid's force
  const VectorX lam = lambda.size() == num_contacts() ? lambda : VectorX(VectorX::Zero(num_contacts()));
  const VectorX zz = z.size() == num_friction() ? z : VectorX(VectorX::Zero(num_friction()));
  VectorX v = contacts_.velocity_update(lam, zz);
  if (num_body_dofs() > 0) v += dt_ * (contacts_.m_r_inverse * fluid_body_force(x_fluid));
  return v;
}

template <int Dim>
VectorX MonolithicSystem<Dim>::pressure_cells(const VectorX& x_fluid) const {
  VectorX p;
  pressure_cells_into(x_fluid, p);
  return p;
}

template <int Dim>
void MonolithicSystem<Dim>::pressure_cells_into(const VectorX& x_fluid, VectorX& out,
                                                ZerosOutsideCells* kept) const {
  // scatter_stokes_pressure into a kept buffer. (band23) A buffer that is +0 outside the cells
  // `kept` lists has only those set to +0: every other cell already holds +0, the bits setZero
  // writes, so the buffer is +0 everywhere before the DOFs' cells are written either way
  // (docs/derivations.md, "Passes restricted to boxes", "The pressure zeroed where it was
  // written")
  const std::vector<int>& cells = dofs_.pressure.cell_of_dof;
  if (kept && kept->holds(out) && out.size() == grid_.num_cells()) {
    for (int c : kept->cells) out[c] = 0.0;
  } else {
    out.setZero(grid_.num_cells());
  }
  const int ns = num_stress();
  for (int k = 0; k < num_pressure(); ++k) out[cells[k]] = x_fluid[ns + k];
  if (kept) {
    kept->data = out.data();
    kept->size = static_cast<long>(out.size());
    kept->cells.assign(cells.begin(), cells.begin() + num_pressure());
  }
}

template <int Dim>
VectorX MonolithicSystem<Dim>::stress_full(const VectorX& x_fluid) const {
  VectorX tau;
  stress_full_into(x_fluid, tau);
  return tau;
}

template <int Dim>
void MonolithicSystem<Dim>::stress_full_into(const VectorX& x_fluid, VectorX& out) const {
  // tau_full = E S_tau^T tau (scatter_stress) without the unknown-sized and full-sized
  // temporaries: each active unknown writes its own DOF and, in the reduced form, a diagonal
  // unknown subtracts itself from the eliminated component of its cell. The active unknowns come
  // in increasing order (component blocks in order), so the eliminated component is
  // 0 - tau_xx - tau_yy (3D) in the order StressLayout::expand sums it; the inactive unknowns
  // it skips are +0 there, and 0 - 0 = +0, so the bits are expand's.
  // inviscid weights (StokesWeights::inviscid): no stress field at all, `out` left empty
  if (w_.inviscid()) {
    out.resize(0);
    return;
  }
  out.setZero(stress_.num_dofs());
  const int ns = num_stress();
  if (ns == 0) return;
  const bool reduced = layout_.form() == StressForm::reduced;
  const int eliminated = stress_.offset(Dim - 1);
  for (int k = 0; k < ns; ++k) {
    const int u = dofs_.unknown_of_dof[k];
    const int j = layout_.component_of_unknown(u);
    const int c = layout_.component(j);
    const int local = u - layout_.offset(j);
    out[stress_.offset(c) + local] = x_fluid[k];
    if (reduced && StressGrid<Dim>::is_diagonal(c)) out[eliminated + local] -= x_fluid[k];
  }
}

template <int Dim>
VectorX MonolithicSystem<Dim>::fluid_velocities(const VectorX& x_fluid) const {
  VectorX u;
  fluid_velocities_into(x_fluid, u);
  return u;
}

template <int Dim>
void MonolithicSystem<Dim>::fluid_velocities_into(const VectorX& x_fluid, VectorX& u) const {
  if (!matrix_free_) {
    u = u_star_;
    apply_stokes_update<Dim>(grid_, layout_, w_, dt_, pressure_cells(x_fluid), stress_full(x_fluid), u);
    return;
  }
  // the face force B x = G W_L^p p + D^T M W_L^s tau by the stencils, written into u's own
  // storage (no face-sized temporary), then per face the update of apply_stokes_update on faces
  // with W_F^u W_L^u > 0 (u* - dt force / (rho W_L^u), the same expression) and u* elsewhere
  // (the operator was built with w_; it computes the force only on the face rows holding an
  // updated face and copies u* elsewhere: issue 20)
  matrix_free_stokes_->updated_velocities_into(x_fluid, u_star_, dt_, u);
}

// ---------------------------------------------------------------------------------------------

namespace {

/// A33 + gamma diag(A33) (section 4.4.5), nc x nc.
template <int Dim>
SparseMatrix boosted_a33(const MonolithicSystem<Dim>& s, double gamma) {
  SparseMatrix a33 = s.contacts().a33();
  a33.makeCompressed();
  for (int k = 0; k < a33.outerSize(); ++k)
    for (SparseMatrix::InnerIterator it(a33, k); it; ++it)
      if (it.row() == it.col()) it.valueRef() = (1.0 + gamma) * it.value();
  return a33;
}

/// true when the bodies do not feel the Stokes null vector n: no body DOFs, or
/// max |B_f n| <= 1e-12 max(1, sum |B_f|).
template <int Dim>
bool bodies_blind_to(const MonolithicSystem<Dim>& system, const VectorX& n) {
  if (system.num_body_dofs() == 0) return true;
  const double scale = std::max(1.0, system.fluid_body_jacobian_abs_sum());
  return system.fluid_body_force(n).cwiseAbs().maxCoeff() <= 1e-12 * scale;
}

}  // namespace

template <int Dim>
CoupledOperator<Dim>::CoupledOperator(const MonolithicSystem<Dim>& system, bool with_contacts,
                                      double contact_boost)
    : system_(system),
      num_fluid_(system.num_fluid()),
      num_contacts_(with_contacts ? system.num_contacts() : 0) {
  size_ = num_fluid_ + num_contacts_;
  // the contact block of S: row order (explicit) or Welsh-Powell colours of the contact graph
  // (matrixfree; contacts sharing no dynamic body share no entry of A33)
  if (num_contacts_ > 0) {
    SparseMatrix a33 = boosted_a33(system, contact_boost);
    if (system.matrix_free()) {
      const ContactSystem<Dim>& c = system.contacts();
      Colouring colours = welsh_powell(contact_adjacency(c.dynamic_pairs, c.num_dynamic_bodies));
      contact_ = std::make_shared<ColouredSparseOperator>(std::move(a33), std::move(colours));
    } else {
      contact_ = std::make_shared<SparseMatrixOperator>(std::move(a33));
    }
  }
  // diagonal: diag(S) + dt alpha diag(B_f^T M_r^-1 B_f), column by column of B_f
  sweep_diagonal_.resize(size_);
  sweep_diagonal_.head(num_fluid_) = system.stokes_operator().sweep_diagonal();
  if (num_contacts_ > 0) sweep_diagonal_.tail(num_contacts_) = contact_->sweep_diagonal();
  diagonal_.resize(size_);
  diagonal_.head(num_fluid_) = system.stokes_operator().diagonal();
  if (num_contacts_ > 0) diagonal_.tail(num_contacts_) = contact_->diagonal();
  system.add_rigid_diagonal(system.dt() * system.alpha(), diagonal_.head(num_fluid_));
  // the Stokes null vectors the bodies do not feel
  for (const VectorX& n : system.dofs().null_space) {
    if (!bodies_blind_to(system, n)) continue;
    VectorX v = VectorX::Zero(size_);
    v.head(num_fluid_) = n;
    null_space_.push_back(v);
  }
  // scratch of apply and the sweeps
  const int nd = system.num_body_dofs();
  force_.resize(nd);
  g_.resize(nd);
  h_.resize(nd);
  if (num_contacts_ > 0) {
    x_fluid_.resize(num_fluid_);
    y_fluid_.resize(num_fluid_);
    rhs_fluid_.resize(num_fluid_);
    x_contact_.resize(num_contacts_);
    y_contact_.resize(num_contacts_);
    rhs_contact_.resize(num_contacts_);
    active_fluid_.resize(num_fluid_);
    active_contact_.resize(num_contacts_);
  }
}

template <int Dim>
void CoupledOperator<Dim>::apply(const VectorX& x, VectorX& y) const {
  const int nf = num_fluid_, nc = num_contacts_;
  const LinearOperator& fluid = system_.stokes_operator();
  // S x: the fluid part, then the contact block
  if (nc == 0) {
    fluid.apply(x, y);
  } else {
    x_fluid_ = x.head(nf);
    x_contact_ = x.tail(nc);
    fluid.apply(x_fluid_, y_fluid_);
    contact_->apply(x_contact_, y_contact_);
    y.resize(size_);
    y.head(nf) = y_fluid_;
    y.tail(nc) = y_contact_;
  }
  if (system_.num_body_dofs() == 0) return;
  // R x by sequential multiplication (section 4.4.3), in body space: g = M_r^-1 B_f x_f,
  // h = M_r^-1 J_lambda^T lambda
  const ContactSystem<Dim>& c = system_.contacts();
  const double scale = system_.dt() * system_.alpha();
  if (!system_.matrix_free()) {
    // the reference arithmetic (kept bit for bit)
    const VectorX g = c.m_r_inverse * system_.fluid_body_force(x.head(nf));
    if (nc > 0) {
      const VectorX h = c.m_r_inverse * (c.j_lambda.transpose() * x.tail(nc));
      y.head(nf) += scale * (system_.fluid_body_jacobian().transpose() * (g + h));
      y.tail(nc) += scale * (c.j_lambda * g);
    } else {
      y.head(nf) += scale * (system_.fluid_body_jacobian().transpose() * g);
    }
    return;
  }
  // matrixfree: scratch only; the rigid loops are serial (a fixed order for any thread count)
  system_.fluid_body_force_into(x.head(nf), force_);
  g_.noalias() = c.m_r_inverse * force_;
  if (nc > 0) {
    force_.noalias() = system_.j_lambda_transpose() * x_contact_;
    h_.noalias() = c.m_r_inverse * force_;
    h_ += g_;
    system_.add_fluid_body_force_transpose(h_, scale, y.head(nf));
    y_contact_.noalias() = c.j_lambda * g_;
    y.tail(nc) += scale * y_contact_;
  } else {
    system_.add_fluid_body_force_transpose(g_, scale, y.head(nf));
  }
}

template <int Dim>
void CoupledOperator<Dim>::sweep(const VectorX& rhs, VectorX& x, double omega,
                                 const std::vector<char>* active, bool backward) const {
  const LinearOperator& fluid = system_.stokes_operator();
  if (num_contacts_ == 0) {
    if (backward)
      fluid.backward_sweep(rhs, x, omega, active);
    else
      fluid.forward_sweep(rhs, x, omega, active);
    return;
  }
  // S is block diagonal: the fluid rows and the contact rows are relaxed separately, each in
  // its operator's order (forward: fluid then contacts; backward: contacts then fluid)
  const int nf = num_fluid_, nc = num_contacts_;
  if (active) {
    std::copy(active->begin(), active->begin() + nf, active_fluid_.begin());
    std::copy(active->begin() + nf, active->end(), active_contact_.begin());
  }
  auto fluid_rows = [&]() {
    rhs_fluid_ = rhs.head(nf);
    x_fluid_ = x.head(nf);
    const std::vector<char>* mask = active ? &active_fluid_ : nullptr;
    if (backward)
      fluid.backward_sweep(rhs_fluid_, x_fluid_, omega, mask);
    else
      fluid.forward_sweep(rhs_fluid_, x_fluid_, omega, mask);
    x.head(nf) = x_fluid_;
  };
  auto contact_rows = [&]() {
    rhs_contact_ = rhs.tail(nc);
    x_contact_ = x.tail(nc);
    const std::vector<char>* mask = active ? &active_contact_ : nullptr;
    if (backward)
      contact_->backward_sweep(rhs_contact_, x_contact_, omega, mask);
    else
      contact_->forward_sweep(rhs_contact_, x_contact_, omega, mask);
    x.tail(nc) = x_contact_;
  };
  if (backward) {
    contact_rows();
    fluid_rows();
  } else {
    fluid_rows();
    contact_rows();
  }
}

template <int Dim>
void CoupledOperator<Dim>::forward_sweep(const VectorX& rhs, VectorX& x, double omega,
                                         const std::vector<char>* active) const {
  sweep(rhs, x, omega, active, false);
}

template <int Dim>
void CoupledOperator<Dim>::backward_sweep(const VectorX& rhs, VectorX& x, double omega,
                                          const std::vector<char>* active) const {
  sweep(rhs, x, omega, active, true);
}

template <int Dim>
Eigen::MatrixXd CoupledOperator<Dim>::dense_matrix() const {
  Eigen::MatrixXd a(size_, size_);
  VectorX e = VectorX::Zero(size_), y;
  for (int j = 0; j < size_; ++j) {
    e[j] = 1.0;
    apply(e, y);
    a.col(j) = y;
    e[j] = 0.0;
  }
  return a;
}

template <int Dim>
MonolithicOperator<Dim>::MonolithicOperator(const MonolithicSystem<Dim>& system,
                                            double contact_boost)
    : CoupledOperator<Dim>(system, true, contact_boost), contact_boost_(contact_boost) {}

template <int Dim>
SparseMatrix MonolithicOperator<Dim>::sparse_part() const {
  const MonolithicSystem<Dim>& s = this->system();
  if (s.matrix_free())
    throw std::logic_error(
        "MonolithicOperator::sparse_part: the matrixfree back end forms no matrix");
  // S = blockdiag(A_stokes, A33 + gamma diag(A33)), row by row (both blocks row-major)
  const int nf = s.num_fluid(), nc = s.num_contacts();
  const SparseMatrix& a = s.stokes().A;
  const SparseMatrix a33 = nc > 0 ? boosted_a33(s, contact_boost_) : SparseMatrix(0, 0);
  Eigen::VectorXi row_sizes(nf + nc);
  for (int i = 0; i < nf; ++i) row_sizes[i] = static_cast<int>(a.innerVector(i).nonZeros());
  for (int i = 0; i < nc; ++i) row_sizes[nf + i] = static_cast<int>(a33.innerVector(i).nonZeros());
  SparseMatrix m(nf + nc, nf + nc);
  m.reserve(row_sizes);
  for (int i = 0; i < nf; ++i)
    for (SparseMatrix::InnerIterator it(a, i); it; ++it) m.insert(i, it.col()) = it.value();
  for (int i = 0; i < nc; ++i)
    for (SparseMatrix::InnerIterator it(a33, i); it; ++it)
      m.insert(nf + i, nf + it.col()) = it.value();
  m.makeCompressed();
  return m;
}

template <int Dim>
FluidBodyOperator<Dim>::FluidBodyOperator(const MonolithicSystem<Dim>& system)
    : CoupledOperator<Dim>(system, false, 0.0) {}

template <int Dim>
SparseMatrixOperator friction_operator(const MonolithicSystem<Dim>& system, double contact_boost) {
  SparseMatrix a44 = system.contacts().a44();
  for (int k = 0; k < a44.outerSize(); ++k)
    for (SparseMatrix::InnerIterator it(a44, k); it; ++it)
      if (it.row() == it.col()) it.valueRef() *= 1.0 + contact_boost;
  return SparseMatrixOperator(a44);
}

JacobiScaledOperator::JacobiScaledOperator(const LinearOperator& a) : a_(a) {
  const VectorX d = a.diagonal();
  scale_.resize(d.size());
  diagonal_.resize(d.size());
  scaled_x_.resize(d.size());
  scaled_rhs_.resize(d.size());
  for (int i = 0; i < d.size(); ++i) {
    scale_[i] = d[i] > 0.0 ? 1.0 / std::sqrt(d[i]) : 1.0;
    diagonal_[i] = d[i] > 0.0 ? 1.0 : d[i];
  }
  for (const VectorX& n : a.null_space()) {
    const VectorX m = n.cwiseQuotient(scale_);
    null_space_.push_back(m / m.norm());
  }
}

void JacobiScaledOperator::apply(const VectorX& x, VectorX& y) const {
  scaled_x_ = scale_.cwiseProduct(x);
  a_.apply(scaled_x_, y);
  y.array() *= scale_.array();
}

void JacobiScaledOperator::forward_sweep(const VectorX& rhs, VectorX& x, double omega,
                                         const std::vector<char>* active) const {
  // a sweep of S A S on (rhs, x) is a sweep of A on (S^-1 rhs, S x)
  scaled_x_ = scale_.cwiseProduct(x);
  scaled_rhs_ = rhs.cwiseQuotient(scale_);
  a_.forward_sweep(scaled_rhs_, scaled_x_, omega, active);
  x = scaled_x_.cwiseQuotient(scale_);
}

void JacobiScaledOperator::backward_sweep(const VectorX& rhs, VectorX& x, double omega,
                                          const std::vector<char>* active) const {
  scaled_x_ = scale_.cwiseProduct(x);
  scaled_rhs_ = rhs.cwiseQuotient(scale_);
  a_.backward_sweep(scaled_rhs_, scaled_x_, omega, active);
  x = scaled_x_.cwiseQuotient(scale_);
}

template <int Dim>
PvcUnifiedResult solve_pvc_unified(const MonolithicSystem<Dim>& system,
                                   const StaggeredSettings& settings,
                                   const PvcUnifiedOptions& options,
                                   KeptCoupledPreconditioner<Dim>* kept) {
  const double inf = std::numeric_limits<double>::infinity();
  const int nf = system.num_fluid(), nc = system.num_contacts(), nz = system.num_friction();
  const double gamma = settings.diagonal_boost;
  const MonolithicOperator<Dim> unscaled(system, gamma);
  // MPRGP runs on S A S (options.jacobi_scaling) or on A (S = I)
  const JacobiScaledOperator scaled(unscaled);
  const LinearOperator& op = options.jacobi_scaling ? static_cast<const LinearOperator&>(scaled)
                                                    : static_cast<const LinearOperator&>(unscaled);
  const VectorX s = options.jacobi_scaling ? scaled.scale() : VectorX(VectorX::Ones(nf + nc));
  // bounds of (26): tau, p free, lambda >= 0
  VectorX lower = VectorX::Constant(nf + nc, -inf), upper = VectorX::Constant(nf + nc, inf);
  lower.tail(nc).setZero();
  PvcUnifiedResult r;
  r.x = VectorX::Zero(nf + nc);
  r.z = VectorX::Zero(nz);
  // ||A|| once per operator for all the staggered solves (each would estimate it again)
  MprgpSettings mlcp_settings = with_norm_estimate(op, settings.mprgp);
  // the block preconditioner in face (built on its first application, shared by the staggered
  // solves), seen through the Jacobi scaling when MPRGP runs on S A S
  std::unique_ptr<LazyCoupledFacePreconditioner<Dim>> block;
  if (options.preconditioner == PreconditionerKind::multigrid && nf > 0 && settings.mprgp.precondition) {
    const VectorX contact_diagonal = unscaled.diagonal().tail(nc);
    const bool body_correction = options.body_correction;
    const int max_exact_contacts = options.exact_contacts ? CoupledPreconditionerOptions().max_exact_contacts : 0;
    block = std::make_unique<LazyCoupledFacePreconditioner<Dim>>(
        nf + nc,
        [&system, contact_diagonal, body_correction, max_exact_contacts, kept]() {
          if (kept && kept->mlcp && kept->fits(system)) return kept->mlcp;
          CoupledPreconditionerOptions o;
          o.body_correction = body_correction;
          o.max_exact_contacts = max_exact_contacts;
          auto built = std::make_shared<CoupledPreconditioner<Dim>>(system, true, contact_diagonal, o);
          if (kept) kept->keep(system, nullptr, built);
          return built;
        },
        options.jacobi_scaling ? &scaled.scale() : nullptr);
    mlcp_settings.face_preconditioner = block.get();
  }
  auto record = [&r](const MprgpResult& m) {
    r.mprgp_iterations += m.iterations;
    r.cg_steps += m.cg_steps;
    r.expansion_steps += m.expansion_steps;
    r.proportioning_steps += m.proportioning_steps;
    r.converged = r.converged && m.converged;
    r.max_relative_residual = std::max(r.max_relative_residual, m.relative_residual);
    if (m.breakdown && !r.breakdown) {
      r.breakdown = true;
      r.message = m.message;
    }
  };
  // eq. (26) given z
  auto solve_mlcp = [&]() {
    // in y = S^-1 x with right-hand side S b (the bounds 0 and +-inf are unchanged)
    VectorX y = r.x.cwiseQuotient(s);
    const MprgpResult m =
        mprgp_solve(op, s.cwiseProduct(system.mlcp_rhs(r.z)), lower, upper, y, mlcp_settings);
    r.x = s.cwiseProduct(y);
    record(m);
    ++r.staggered_iterations;
  };
  solve_mlcp();
  const bool friction = nc > 0 && system.contacts().mu.maxCoeff() > 0.0;
  if (friction) {
    // staggered projections: eq. (25), z given (tau, p, lambda), then (26) given z
    const SparseMatrixOperator fop = friction_operator(system, gamma);
    MprgpSettings friction_settings = with_norm_estimate(fop, settings.mprgp);
    friction_settings.stagnation = StagnationRule{};  // the attempt's rule is for the MLCP (26)
    auto solve_friction = [&](const VectorX& zl, const VectorX& zu) {
      record(mprgp_solve(fop, system.friction_rhs(r.x), zl, zu, r.z, friction_settings));
    };
    r.last_change = staggered_rounds<Dim>(system.contacts().mu, settings.max_iterations, 1,
                                          settings.tolerance,
                                          [&]() { return VectorX(r.x.tail(nc)); }, solve_friction,
                                          solve_mlcp)
                        .last_change;
  }
  // eq. (8) and eq. (21) updates
  const VectorX xf = r.x.head(nf);
  r.lambda = r.x.tail(nc);
  if (!options.compute_updates) return r;
  r.stress = system.stress_full(xf);
  r.pressure = system.pressure_cells(xf);
  r.u = system.fluid_velocities(xf);
  r.body_velocity = system.body_velocities(xf, r.lambda, r.z);
  return r;
}

template class MonolithicSystem<2>;
template class MonolithicSystem<3>;
template class CoupledOperator<2>;
template class CoupledOperator<3>;
template class MonolithicOperator<2>;
template class MonolithicOperator<3>;
template class FluidBodyOperator<2>;
template class FluidBodyOperator<3>;
template SparseMatrixOperator friction_operator<2>(const MonolithicSystem<2>&, double);
template SparseMatrixOperator friction_operator<3>(const MonolithicSystem<3>&, double);
template PvcUnifiedResult solve_pvc_unified<2>(const MonolithicSystem<2>&, const StaggeredSettings&,
                                               const PvcUnifiedOptions&, KeptCoupledPreconditioner<2>*);
template PvcUnifiedResult solve_pvc_unified<3>(const MonolithicSystem<3>&, const StaggeredSettings&,
                                               const PvcUnifiedOptions&, KeptCoupledPreconditioner<3>*);

}  // namespace monolith
