/// \file system_export.cpp
/// One step's eq. (24) as named explicit objects and the checks of a candidate solution
/// (system_export.hpp).

#include "reference/coupling/system_export.hpp"

#include <algorithm>
#include <cmath>
#include <memory>
#include <random>
#include <stdexcept>

#include "reference/coupling/monolithic_system.hpp"
#include "reference/fluid/viscosity.hpp"
#include "reference/grid/stress_grid.hpp"
#include "reference/grid/volume_fractions.hpp"

namespace monolith {

namespace {

SparseMatrix diagonal_matrix(const VectorX& d) {
  SparseMatrix m(d.size(), d.size());
  std::vector<Triplet> t;
  t.reserve(d.size());
  for (int i = 0; i < d.size(); ++i)
    if (d[i] != 0.0) t.emplace_back(i, i, d[i]);
  m.setFromTriplets(t.begin(), t.end());
  return m;
}

/// [a b ...] side by side (all with the same number of rows).
SparseMatrix hstack(const std::vector<const SparseMatrix*>& parts, int rows) {
  std::vector<Triplet> t;
  int col0 = 0;
  for (const SparseMatrix* p : parts) {
    for (int k = 0; k < p->outerSize(); ++k)
      for (SparseMatrix::InnerIterator it(*p, k); it; ++it)
        t.emplace_back(it.row(), col0 + it.col(), it.value());
    col0 += static_cast<int>(p->cols());
  }
  SparseMatrix m(rows, col0);
  m.setFromTriplets(t.begin(), t.end());
  return m;
}

SparseMatrix sub_block(const SparseMatrix& a, int r0, int c0, int rows, int cols) {
  return SparseMatrix(a.block(r0, c0, rows, cols));
}

template <int Dim>
std::vector<int> coord_of(const VecI<Dim>& c) {
  std::vector<int> v(Dim);
  for (int d = 0; d < Dim; ++d) v[d] = c[d];
  return v;
}

template <int Dim>
std::vector<double> vec_of(const Vec<Dim>& c) {
  std::vector<double> v(Dim);
  for (int d = 0; d < Dim; ++d) v[d] = c[d];
  return v;
}

const char* kAxisNames = "xyz";

}  // namespace

const ExportedMatrix* SystemExport::matrix(const std::string& name) const {
  for (const auto& m : matrices)
    if (m.name == name) return &m;
  return nullptr;
}

const ExportedVector* SystemExport::vector(const std::string& name) const {
  for (const auto& v : vectors)
    if (v.name == name) return &v;
  return nullptr;
}

template <int Dim>
SystemExport export_system(const MonolithicSystem<Dim>& system,
                           const std::vector<RigidBody<Dim>>& bodies,
                           const SolidWeights<Dim>& solids,
                           const std::vector<Contact<Dim>>& contacts, const VectorX& x,
                           double diagonal_boost) {
  const ContactSystem<Dim>& cs = system.contacts();
  if (static_cast<int>(contacts.size()) != cs.num_contacts())
    throw std::invalid_argument("export_system: contacts and the ContactSystem disagree");
  SystemExport e;
  e.dim = Dim;
  e.dx = system.grid().dx();
  e.dt = system.dt();
  e.alpha = system.alpha();
  e.diagonal_boost = diagonal_boost;
  e.backend = enum_name(system.backend());
  e.stress_form = system.layout().form() == StressForm::reduced ? "reduced" : "full";
  e.num_tau = system.num_stress();
  e.num_p = system.num_pressure();
  e.num_lambda = system.num_contacts();
  e.num_z = system.num_friction();
  if (x.size() != e.size()) throw std::invalid_argument("export_system: x has the wrong size");
  e.x = x;

  // the explicit twin of a matrix-free system: the same inputs, assembled matrices
  std::unique_ptr<MonolithicSystem<Dim>> twin;
  if (system.matrix_free())
    twin = std::make_unique<MonolithicSystem<Dim>>(
        system.grid(), system.layout().form(), system.weights(), system.dt(), system.u_star(),
        bodies, solids, cs, Backend::explicit_matrices, system.unknowns());
  const MonolithicSystem<Dim>& ex = twin ? *twin : system;
  const ExplicitStokesSystem& st = ex.stokes();
  const StokesWeights& w = system.weights();
  const MacGrid<Dim>& grid = system.grid();
  const double alpha = e.alpha, dt = e.dt;

  // --- the whole of eq. (24): A = blockdiag(F, gamma diag(A33), gamma diag(A44)) + R with the
  // fluid part F = [A11 A12; A12^T A22] without bodies and the rigid part
  // R = dt alpha Bh^T M_r^-1 Bh, Bh = [B_1 B_2 J_lambda^T J_z^T] (monolithic_system.hpp)
  const int nf = e.num_tau + e.num_p, n = e.size(), nd = cs.num_body_dofs();
  const SparseMatrix jlt = cs.j_lambda.transpose(), jzt = cs.j_z.transpose();
  const SparseMatrix bh = hstack({&ex.fluid_body_jacobian(), &jlt, &jzt}, nd);
  const SparseMatrix rigid = SparseMatrix(dt * alpha * SparseMatrix(bh.transpose()) *
                                          (cs.m_r_inverse * bh));
  std::vector<Triplet> t;
  for (int k = 0; k < st.A.outerSize(); ++k)
    for (SparseMatrix::InnerIterator it(st.A, k); it; ++it) t.emplace_back(it.row(), it.col(), it.value());
  for (int k = 0; k < rigid.outerSize(); ++k)
    for (SparseMatrix::InnerIterator it(rigid, k); it; ++it) {
      t.emplace_back(it.row(), it.col(), it.value());
      // section 4.4.5: the contact rows' diagonal scaled by (1 + gamma)
      if (it.row() == it.col() && it.row() >= nf) t.emplace_back(it.row(), it.col(), diagonal_boost * it.value());
    }
  SparseMatrix assembled(n, n);
  assembled.setFromTriplets(t.begin(), t.end());
  // A is symmetric; the sparse products leave round-off asymmetry (summation order), which
  // the mean removes, so A_ji = A_ij^T bit for bit in the files
  SparseMatrix a = 0.5 * (assembled + SparseMatrix(assembled.transpose()));
  a.prune(0.0);
  const VectorX b = system.rhs();

  // the matrix-free operator against the assembled twin on random vectors
  if (system.matrix_free() && n > 0) {
    std::mt19937 rng(17);
    std::uniform_real_distribution<double> u(-1.0, 1.0);
    for (int trial = 0; trial < 3; ++trial) {
      VectorX v(n);
      for (int i = 0; i < n; ++i) v[i] = u(rng);
      VectorX y = VectorX::Zero(n);
      int r0 = 0;
      for (int i = 1; i <= 4; ++i) {
        int c0 = 0;
        for (int j = 1; j <= 4; ++j) {
          if (system.block_size(i) > 0 && system.block_size(j) > 0)
            y.segment(r0, system.block_size(i)) +=
                system.apply_block(i, j, v.segment(c0, system.block_size(j)));
          c0 += system.block_size(j);
        }
        r0 += system.block_size(i);
      }
      // the boost is not part of apply_block
      y.tail(n - nf) += diagonal_boost * rigid.diagonal().tail(n - nf).cwiseProduct(v.tail(n - nf));
      const VectorX ya = a * v;
      e.backend_difference = std::max(
          e.backend_difference, (y - ya).lpNorm<Eigen::Infinity>() / std::max(ya.lpNorm<Eigen::Infinity>(), 1e-300));
    }
    const VectorX db = b - ex.rhs();
    e.backend_difference = std::max(
        e.backend_difference, db.size() ? db.lpNorm<Eigen::Infinity>() / std::max(b.lpNorm<Eigen::Infinity>(), 1e-300) : 0.0);
  }

  // --- the named objects --------------------------------------------------------------------
  auto add = [&](const std::string& name, const std::string& eq, const std::string& meaning,
                 SparseMatrix m) { e.matrices.push_back({name, eq, meaning, std::move(m)}); };
  auto addv = [&](const std::string& name, const std::string& eq, const std::string& meaning,
                  VectorX v) { e.vectors.push_back({name, eq, meaning, std::move(v)}); };
  const StressGrid<Dim> stress(grid);
  const std::vector<CouplingBody<Dim>> view = coupling_bodies(bodies);
  const BodyCouplingOperator<Dim> two(grid, view, solids, BodyGroup::two_way);

  add("G", "(8)", "gradient: faces x cells (1/dx differences; the fluid force is -W_F^u G W_L^p p)", st.G);
  add("D", "(8)", "deformation rate: stress DOFs (all components, StressGrid order) x faces", st.D);
  add("M", "(8)", "stress multiplicity, stress DOFs square, diagonal (1 diagonal, 2 off-diagonal components)", st.M);
  add("N", "(8), section 4.4.2",
      "viscosity matrix with H merged (N <- H^-1 N), stress unknowns (reduced form: the last diagonal "
      "component eliminated) square; A11's term is 1/2 N^-1 W_F^s W_L^s",
      viscosity_matrix<Dim>(system.layout(), w.viscosity));
  add("E", "section 4.4.2", "expansion: stress DOFs x stress unknowns, tau_full = E tau", st.E);
  add("S_tau", "(24)", "selection: rows of x's tau block x stress unknowns", st.S_tau);
  add("S_p", "(24)", "selection: rows of x's p block x cells", st.S_p);
  add("W_F_u", "(8)", "fluid face fractions W_F^u, faces square, diagonal", diagonal_matrix(w.pressure.fluid_face));
  add("W_S_u", "section 4.4.1", "solid face fractions W_S^u = 1 - W_F^u (all solids), faces square, diagonal",
      diagonal_matrix(solid_face_weights(w.pressure.fluid_face)));
  add("W_L_u", "(8)", "liquid face fractions W_L^u (clamped), faces square, diagonal", diagonal_matrix(w.pressure.liquid_face));
  add("W_L_p", "(8)", "liquid cell fractions W_L^p, cells square, diagonal", diagonal_matrix(w.pressure.liquid_cell));
  add("W_F_s", "(8)", "fluid fractions of the stress control volumes W_F^s, stress DOFs square, diagonal",
      diagonal_matrix(w.fluid_stress));
  add("W_L_s", "(8)", "liquid fractions of the stress control volumes W_L^s, stress DOFs square, diagonal",
      diagonal_matrix(w.liquid_stress));
  add("P", "(8)", "face densities (kg/m^3), faces square, diagonal", diagonal_matrix(w.pressure.face_density));
  add("J_p", "(17), section 4.4.1",
      "pressure Jacobian of the two-way bodies, J_p = alpha Jh_p (Jh_p integrates over the control "
      "volumes dx^dim): body DOFs (kBodyDofs per dynamic body, translation then rotation) x cells",
      SparseMatrix(alpha * two.pressure_jacobian()));
  add("J_s", "(19), section 4.4.1",
      "stress Jacobian of the two-way bodies, J_s = alpha Jh_s: body DOFs x stress DOFs (all components)",
      SparseMatrix(alpha * two.stress_jacobian()));
  add("J_lambda", "(9), (10)", "normal contact Jacobian: contacts x body DOFs (positive = separating)", cs.j_lambda);
  add("J_z", "(13)", "friction Jacobian: friction rows (dim - 1 per contact) x body DOFs", cs.j_z);
  add("M_r", "(10)", "rigid mass matrix: body DOFs square, block diagonal (m I, world inertia)", cs.m_r);
  add("C", "(11), (24)", "restitution C = I + R per contact row (1 + e on bouncing contacts): contacts square, diagonal",
      diagonal_matrix(cs.restitution_scale));
  const int sizes[4] = {e.num_tau, e.num_p, e.num_lambda, e.num_z};
  int offsets[5] = {0, 0, 0, 0, 0};
  for (int i = 0; i < 4; ++i) offsets[i + 1] = offsets[i] + sizes[i];
  const char* names[4] = {"tau", "p", "lambda", "z"};
  for (int i = 0; i < 4; ++i)
    for (int j = i; j < 4; ++j) {
      const std::string name = "A" + std::to_string(i + 1) + std::to_string(j + 1);
      std::string meaning = std::string(names[i]) + " rows x " + names[j] + " columns of A";
      if ((i == 2 && j == 2) || (i == 3 && j == 3))
        meaning += ", its diagonal scaled by (1 + diagonal_boost) as solved (section 4.4.5)";
      add(name, "(24)", meaning, sub_block(a, offsets[i], offsets[j], sizes[i], sizes[j]));
    }
  for (int i = 1; i < 4; ++i)
    for (int j = 0; j < i; ++j) {
      const std::string name = "A" + std::to_string(i + 1) + std::to_string(j + 1);
      add(name, "(24)", std::string(names[i]) + " rows x " + names[j] + " columns of A (the transpose of A" +
                            std::to_string(j + 1) + std::to_string(i + 1) + ")",
          sub_block(a, offsets[i], offsets[j], sizes[i], sizes[j]));
    }
  add("A", "(24)", "the whole system over x = (tau, p, lambda, z), symmetric", a);
  for (int i = 0; i < 4; ++i)
    addv("b" + std::to_string(i + 1), "(24)", std::string("right-hand side of the ") + names[i] + " rows",
         b.segment(offsets[i], sizes[i]));
  addv("b", "(24)", "the whole right-hand side (b1, b2, b3, b4)", b);
  addv("x", "(24)", "the reference solution (tau, p, lambda, z)", x);
  addv("u_star", "(8)", "face velocities u* before the solve (m/s)", system.u_star());
  addv("v_star", "(21)", "two-way bodies' generalised velocities v* before the solve", cs.v_star);
  addv("mu", "(14), (22)", "friction coefficient per contact", cs.mu);

  // --- the rows of x ------------------------------------------------------------------------
  const StokesDofs& dofs = system.dofs();
  const StressLayout<Dim>& layout = system.layout();
  for (int k = 0; k < e.num_tau; ++k) {
    const int unknown = dofs.unknown_of_dof[k];
    const int dof = layout.dof_of_unknown(unknown);
    const auto [component, c] = stress.coord(dof);
    const auto [ax, bx] = StressGrid<Dim>::component_axes(component);
    e.tau_component.push_back(component);
    e.tau_dof.push_back(dof);
    e.tau_name.push_back(std::string(1, kAxisNames[ax]) + kAxisNames[bx]);
    e.tau_location.push_back(StressGrid<Dim>::is_diagonal(component) ? "cell" : (Dim == 2 ? "node" : "edge"));
    e.tau_coord.push_back(coord_of<Dim>(c));
  }
  for (int k = 0; k < e.num_p; ++k) {
    const int cell = dofs.pressure.cell_of_dof[k];
    e.p_cell.push_back(cell);
    e.p_coord.push_back(coord_of<Dim>(grid.cell_coord(cell)));
  }
  e.mu = cs.mu;
  for (const auto& c : contacts) {
    e.contact_body_a.push_back(c.body_a);
    e.contact_body_b.push_back(c.body_b);
    e.contact_wall_face.push_back(c.body_b < 0 ? c.wall_face : -1);
    e.contact_normal.push_back(vec_of<Dim>(c.normal));
    e.contact_point.push_back(vec_of<Dim>(c.point));
  }
  for (int r = 0; r < e.num_z; ++r) {
    e.z_contact.push_back(r / (Dim - 1));
    e.z_direction.push_back(r % (Dim - 1));
    e.z_tangent.push_back(vec_of<Dim>(cs.tangents[r]));
  }
  return e;
}

SolutionCheck check_solution(const SparseMatrix& a, const VectorX& b, int num_tau, int num_p,
                             int num_lambda, int num_z, const VectorX& mu, const VectorX& x,
                             const VectorX& x_ref, bool jacobi_scaled, double tolerance) {
  const int n = static_cast<int>(a.rows());
  if (a.cols() != n || b.size() != n || x.size() != n || x_ref.size() != n ||
      num_tau + num_p + num_lambda + num_z != n || mu.size() != num_lambda ||
      (num_lambda > 0 && num_z % num_lambda != 0))
    throw std::invalid_argument("check_solution: sizes disagree");
  const int nm = num_tau + num_p + num_lambda;  // the rows of the MLCP (26)
  // S on the MLCP rows (the solver's Jacobi scaling), 1 on the friction rows
  VectorX s = VectorX::Ones(n);
  if (jacobi_scaled) {
    const VectorX d = a.diagonal();
    for (int i = 0; i < nm; ++i)
      if (d[i] > 0.0) s[i] = 1.0 / std::sqrt(d[i]);
  }
  const VectorX w = a * x - b;
  const VectorX g = s.cwiseProduct(w);
  const VectorX y = x.cwiseQuotient(s);
  // the right-hand sides the two solves compare with: (26) given z, (25) given (tau, p, lambda)
  VectorX z_part = VectorX::Zero(n), mlcp_part = VectorX::Zero(n);
  z_part.tail(num_z) = x.tail(num_z);
  mlcp_part.head(nm) = x.head(nm);
  const VectorX rhs_mlcp = (b - a * z_part).head(nm);
  const VectorX rhs_friction = (b - a * mlcp_part).tail(num_z);
  const double scale_mlcp =
      std::max(nm ? s.head(nm).cwiseProduct(rhs_mlcp).lpNorm<Eigen::Infinity>() : 0.0, 1e-300);
  // the friction rows as the friction MPRGP measures them (unscaled, relative to the
  // right-hand side of (25)); the cone relative to the largest bound mu lambda (the staggered
  // rounds stop on the relative change of lambda, so the bounds lag by that fraction)
  const double scale_friction =
      std::max(num_z ? rhs_friction.lpNorm<Eigen::Infinity>() : 0.0, 1e-300);
  const int per = num_lambda > 0 ? num_z / num_lambda : 1;
  double scale_cone = 0.0;
  for (int k = 0; k < num_z; ++k)
    scale_cone = std::max(scale_cone, mu[k / per] * std::max(x[num_tau + num_p + k / per], 0.0));
  scale_cone = std::max(scale_cone, 1e-300);
  SolutionCheck c;
  const int nf = num_tau + num_p;
  for (int i = 0; i < nf; ++i) c.free_residual = std::max(c.free_residual, std::abs(g[i]));
  for (int i = nf; i < nm; ++i) {
    c.complementarity = std::max(c.complementarity, std::abs(std::min(y[i], g[i])));
    c.bound_violation = std::max(c.bound_violation, -y[i]);
  }
  for (int k = 0; k < num_z; ++k) {
    const int i = nm + k;
    const int contact = k / per;
    const double bound = mu[contact] * std::max(x[nf + contact], 0.0);
    const double projected = std::clamp(x[i] - w[i], -bound, bound);
    c.friction = std::max(c.friction, std::abs(x[i] - projected));
    c.cone_violation = std::max(c.cone_violation, std::abs(x[i]) - bound);
  }
  c.free_residual /= scale_mlcp;
  c.complementarity /= scale_mlcp;
  c.bound_violation = std::max(c.bound_violation, 0.0) / scale_mlcp;
  c.friction /= scale_friction;
  c.cone_violation = std::max(c.cone_violation, 0.0) / scale_cone;
  const double ref = x_ref.size() ? x_ref.lpNorm<Eigen::Infinity>() : 0.0;
  c.difference = n ? (x - x_ref).lpNorm<Eigen::Infinity>() / std::max(ref, 1e-300) : 0.0;
  c.passed = c.free_residual <= tolerance && c.complementarity <= tolerance &&
             c.friction <= tolerance && c.bound_violation <= tolerance &&
             c.cone_violation <= tolerance;
  return c;
}

template SystemExport export_system<2>(const MonolithicSystem<2>&, const std::vector<RigidBody<2>>&,
                                       const SolidWeights<2>&, const std::vector<Contact<2>>&,
                                       const VectorX&, double);
template SystemExport export_system<3>(const MonolithicSystem<3>&, const std::vector<RigidBody<3>>&,
                                       const SolidWeights<3>&, const std::vector<Contact<3>>&,
                                       const VectorX&, double);

}  // namespace monolith
