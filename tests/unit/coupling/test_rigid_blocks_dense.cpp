// Independent dense references for the rigid blocks of eq. (24): the rigid terms of A11, A12,
// A22 and the blocks A13, A14, A23, A24 (and A33, A34, A44), built here densely from the paper's
// definitions, J_p = -Q W_S^u G and J_s = -Q W_S^u D^T M (section 4.4.1, Q written out per body
// from the face centres and the centres of mass), J_lambda and J_z per contact from its point,
// normal and tangents (eqs. (9), (10), (13)), M_r per box from its density and half sizes
// (eq. (10)), and the products of eq. (24) with their factors dt / alpha, dt, dt alpha. Nothing
// of the library's block code (apply_block, the fluid-body Jacobian B, BodyCouplingOperator,
// ContactSystem's matrices) enters a reference; they are compared with the blocks the library
// assembles (export_system, both back ends) and applies (dense_matrix). Several bodies, rotated,
// with friction and restitution, 2D and 3D.
#include <catch2/catch.hpp>

#include <cmath>
#include <vector>

#include "reference/contact/contact_system.hpp"
#include "reference/coupling/coupled_schemes.hpp"
#include "reference/coupling/coupling.hpp"
#include "reference/coupling/monolithic_system.hpp"
#include "reference/coupling/system_export.hpp"
#include "reference/grid/volume_fractions.hpp"
#include "tests/support/body_helpers.hpp"
#include "tests/support/test_helpers.hpp"

using namespace monolith;
using Dense = Eigen::MatrixXd;

namespace {

constexpr double kDt = 0.01;

/// Rotation of the box by `angle` about z (2D) or about the axis (1, 2, 3)/|.| (3D).
template <int Dim>
void rotate(RigidBody<Dim>& b, double angle) {
  if constexpr (Dim == 2)
    b.orientation = angle;
  else
    b.orientation = Eigen::Quaterniond(Eigen::AngleAxisd(angle, Eigen::Vector3d(1, 2, 3).normalized()));
}

/// The rotation matrix of the same angle, written out.
template <int Dim>
Mat<Dim> rotation_of(double angle) {
  if constexpr (Dim == 2) {
    Mat<2> r;
    r << std::cos(angle), -std::sin(angle), std::sin(angle), std::cos(angle);
    return r;
  } else {
    return Eigen::AngleAxisd(angle, Eigen::Vector3d(1, 2, 3).normalized()).toRotationMatrix();
  }
}

/// The angular part of a force f at lever r: r x f (2D: the scalar r_x f_y - r_y f_x).
template <int Dim>
Eigen::VectorXd lever(const Vec<Dim>& r, const Vec<Dim>& f) {
  Eigen::VectorXd t(Dim == 2 ? 1 : 3);
  if constexpr (Dim == 2)
    t[0] = r[0] * f[1] - r[1] * f[0];
  else
    t = r.cross(f);
  return t;
}

struct BoxSpec {
  std::vector<double> centre, half;
  double density, angle;
};

template <int Dim>
void check_rigid_blocks(int n) {
  constexpr int kDofs = Dim == 2 ? 3 : 6;
  const MacGrid<Dim> grid = testing::unit_grid<Dim>(n);
  const double dx = grid.dx(), alpha = 1.0 / std::pow(dx, Dim);
  // two dynamic boxes, rotated, partly submerged in a liquid of depth 0.55, moving
  std::vector<BoxSpec> specs = {{{0.36, 0.24, 0.5}, {0.13, 0.1, 0.12}, 600.0, 0.3},
                                {{0.7, 0.52, 0.45}, {0.1, 0.08, 0.09}, 900.0, -0.5}};
  std::vector<RigidBody<Dim>> bodies;
  for (std::size_t i = 0; i < specs.size(); ++i) {
    Vec<Dim> c, h;
    for (int d = 0; d < Dim; ++d) {
      c[d] = specs[i].centre[d];
      h[d] = specs[i].half[d];
    }
    RigidBody<Dim> b = testing::make_box<Dim>(c, h, specs[i].density, 0.4);
    rotate<Dim>(b, specs[i].angle);
    BodyVec<Dim> v = BodyVec<Dim>::Zero();
    v[0] = 0.2 * (i ? -1.0 : 1.0);
    v[1] = -0.4;
    v[Dim] = 0.7;
    b.set_generalized_velocity(v);
    bodies.push_back(b);
  }
  std::array<BoundaryType, 2 * Dim> boundary;
  boundary.fill(BoundaryType::wall);
  boundary[3] = BoundaryType::open;
  const SolidWeights<Dim> solids =
      solid_weights<Dim>(grid, coupling_bodies(bodies), {}, boundary, 0.01 * dx);
  const VectorX phi = testing::sample_lattice<Dim>(half_lattice(grid), [](const Vec<Dim>& x) { return x[1] - 0.55; });
  const StokesWeights w = coupled_stokes_weights<Dim>(grid, solids, phi, 1000.0, 2.0);
  VectorX u_star = testing::uniform_face_velocity<Dim>(grid, Vec<Dim>::Unit(1) * (-9.81 * kDt));
  // contacts: box 0 on the floor (two of its lower points), box 1 against box 0 (one point),
  // with friction and restitution; the points and normals are data for J_lambda, J_z
  std::vector<Contact<Dim>> contacts;
  auto contact = [&](int a, int b, Vec<Dim> point, Vec<Dim> normal, double gap) {
    Contact<Dim> k;
    k.body_a = a;
    k.body_b = b;
    k.wall_face = b < 0 ? 2 : -1;
    k.point = point;
    k.normal = normal.normalized();
    k.phi = gap;
    k.friction = 0.4;
    k.restitution = 0.5;
    contacts.push_back(k);
  };
  Vec<Dim> p = bodies[0].position, up = Vec<Dim>::Unit(1);
  p[1] = 0.0;
  p[0] -= 0.1;
  contact(0, -1, p, up, Dim == 2 ? -0.002 : -0.012);
  p[0] += 0.22;
  if constexpr (Dim == 3) p[2] += 0.05;
  contact(0, -1, p, up, 0.001);
  Vec<Dim> between = 0.5 * (bodies[0].position + bodies[1].position), normal = bodies[1].position - bodies[0].position;
  if constexpr (Dim == 3) normal[2] += 0.2;
  contact(1, 0, between, normal, -0.001);
  ContactParameters params;
  params.dt = kDt;
  params.dx = dx;
  const ContactSystem<Dim> cs(bodies, contacts, params);
  const int nc = static_cast<int>(contacts.size()), nz = (Dim - 1) * nc, nd = kDofs * 2;
  REQUIRE(cs.num_contacts() == nc);
  REQUIRE(cs.num_body_dofs() == nd);

  const double gamma = 1e-4;
  const MonolithicSystem<Dim> sys(grid, StressForm::reduced, w, kDt, u_star, bodies, solids, cs,
                                  Backend::explicit_matrices);
  const MonolithicSystem<Dim> mf(grid, StressForm::reduced, w, kDt, u_star, bodies, solids, cs,
                                 Backend::matrix_free);
  const int nt = sys.num_stress(), np = sys.num_pressure();
  REQUIRE(nt > 0);
  REQUIRE(np > 0);
  const ExplicitStokesSystem& st = sys.stokes();

  // --- the references, from the definitions ----------------------------------------------
  // Q W_S^u (paper units, no control volume): per body i, face f normal to axis a at x_f,
  // W_{S,i}^u(f) [e_a; (x_f - c_i) x e_a]
  Dense qw = Dense::Zero(nd, grid.num_faces());
  for (int i = 0; i < 2; ++i)
    for (int f = 0; f < grid.num_faces(); ++f) {
      const double ws = solids.body_face[i][f];
      if (ws == 0.0) continue;
      const auto [axis, coord] = grid.face_coord(f);
      const Vec<Dim> e = Vec<Dim>::Unit(axis);
      qw.block(kDofs * i, f, Dim, 1) = ws * e;
      qw.block(kDofs * i + Dim, f, kDofs - Dim, 1) = ws * lever<Dim>(grid.face_center(axis, coord) - bodies[i].position, e);
    }
  const Dense jp = -qw * st.G;  // section 4.4.1
  const Dense js = -qw * SparseMatrix(SparseMatrix(st.D.transpose()) * st.M);  // D^T M: the fluid's stress force
  // M_r per box from density and half sizes: m I and R I_body R^T
  Dense mr = Dense::Zero(nd, nd);
  for (int i = 0; i < 2; ++i) {
    double volume = 1.0;
    for (int d = 0; d < Dim; ++d) volume *= 2.0 * specs[i].half[d];
    const double m = specs[i].density * volume;
    mr.block(kDofs * i, kDofs * i, Dim, Dim) = m * Dense::Identity(Dim, Dim);
    auto w2 = [&](int d) { return 4.0 * specs[i].half[d] * specs[i].half[d]; };
    if constexpr (Dim == 2) {
      mr(kDofs * i + 2, kDofs * i + 2) = m * (w2(0) + w2(1)) / 12.0;
    } else {
      Mat<3> ib = Mat<3>::Zero();
      ib(0, 0) = m * (w2(1) + w2(2)) / 12.0;
      ib(1, 1) = m * (w2(0) + w2(2)) / 12.0;
      ib(2, 2) = m * (w2(0) + w2(1)) / 12.0;
      const Mat<3> r = rotation_of<3>(specs[i].angle);
      mr.block(kDofs * i + 3, kDofs * i + 3, 3, 3) = r * ib * r.transpose();
    }
  }
  const Dense mr_inv = mr.inverse();
  // J_lambda, J_z: relative velocity of a minus b at the contact point along n, t_k
  Dense jl = Dense::Zero(nc, nd), jz = Dense::Zero(nz, nd);
  for (int c = 0; c < nc; ++c) {
    const Contact<Dim>& k = contacts[c];
    std::vector<Vec<Dim>> dirs = {k.normal};
    for (int j = 0; j < Dim - 1; ++j) {
      const Vec<Dim> t = cs.tangents[(Dim - 1) * c + j];
      // the tangents are the library's basis choice: check they are one
      CHECK(std::abs(t.norm() - 1.0) < 1e-12);
      CHECK(std::abs(t.dot(k.normal)) < 1e-12);
      if (j == 1) CHECK(std::abs(t.dot(cs.tangents[(Dim - 1) * c])) < 1e-12);
      dirs.push_back(t);
    }
    for (std::size_t r = 0; r < dirs.size(); ++r) {
      Eigen::RowVectorXd row = Eigen::RowVectorXd::Zero(nd);
      for (int side = 0; side < 2; ++side) {
        const int body = side == 0 ? k.body_a : k.body_b;
        if (body < 0) continue;
        const double sign = side == 0 ? 1.0 : -1.0;
        row.segment(kDofs * body, Dim) += sign * dirs[r].transpose();
        row.segment(kDofs * body + Dim, kDofs - Dim) +=
            sign * lever<Dim>(k.point - bodies[body].position, dirs[r]).transpose();
      }
      if (r == 0)
        jl.row(c) = row;
      else
        jz.row((Dim - 1) * c + static_cast<int>(r) - 1) = row;
    }
  }
  // the unknowns' columns: B_1 = J_s W_L^s E S_tau^T, B_2 = J_p W_L^p S_p^T
  const Dense b1 = js * SparseMatrix(st.W_L_s * st.E * SparseMatrix(st.S_tau.transpose()));
  const Dense b2 = jp * SparseMatrix(st.W_L_p * SparseMatrix(st.S_p.transpose()));
  REQUIRE(b1.cwiseAbs().maxCoeff() > 0.0);
  REQUIRE(b2.cwiseAbs().maxCoeff() > 0.0);
  const double dt = kDt;
  const Dense r11 = dt / alpha * b1.transpose() * mr_inv * b1;
  const Dense r12 = dt / alpha * b1.transpose() * mr_inv * b2;
  const Dense r22 = dt / alpha * b2.transpose() * mr_inv * b2;
  const Dense r13 = dt * b1.transpose() * mr_inv * jl.transpose();
  const Dense r14 = dt * b1.transpose() * mr_inv * jz.transpose();
  const Dense r23 = dt * b2.transpose() * mr_inv * jl.transpose();
  const Dense r24 = dt * b2.transpose() * mr_inv * jz.transpose();
  Dense r33 = dt * alpha * jl * mr_inv * jl.transpose();
  const Dense r34 = dt * alpha * jl * mr_inv * jz.transpose();
  Dense r44 = dt * alpha * jz * mr_inv * jz.transpose();
  r33.diagonal() *= 1.0 + gamma;
  r44.diagonal() *= 1.0 + gamma;

  // --- the library's blocks: exported (both back ends) and applied --------------------------
  const VectorX zero = VectorX::Zero(nt + np + nc + nz);
  const SystemExport ex = export_system<Dim>(sys, bodies, solids, contacts, zero, gamma);
  const SystemExport em = export_system<Dim>(mf, bodies, solids, contacts, zero, gamma);
  CHECK(em.backend_difference < 1e-12);
  const Dense applied = sys.dense_matrix();
  const int off[4] = {0, nt, nt + np, nt + np + nc}, size[4] = {nt, np, nc, nz};
  struct Case {
    int i, j;
    Dense reference;
    Dense fluid;  // the fluid part F_ij (zero outside the (tau, p) blocks)
  };
  std::vector<Case> cases = {{1, 1, r11, Dense(st.A11)}, {1, 2, r12, Dense(st.A12)},
                             {2, 2, r22, Dense(st.A22)}, {1, 3, r13, Dense()},
                             {1, 4, r14, Dense()},       {2, 3, r23, Dense()},
                             {2, 4, r24, Dense()},       {3, 3, r33, Dense()},
                             {3, 4, r34, Dense()},       {4, 4, r44, Dense()}};
  for (const Case& c : cases) {
    const std::string name = "A" + std::to_string(c.i) + std::to_string(c.j);
    INFO(Dim << "D block " << name);
    const double scale = std::max(c.reference.cwiseAbs().maxCoeff(), 1e-300);
    REQUIRE(scale > 1e-300);
    const Dense fluid = c.fluid.size() ? c.fluid : Dense::Zero(c.reference.rows(), c.reference.cols());
    const Dense exported = Dense(ex.matrix(name)->value) - fluid;
    const Dense exported_mf = Dense(em.matrix(name)->value) - fluid;
    Dense from_apply = applied.block(off[c.i - 1], off[c.j - 1], size[c.i - 1], size[c.j - 1]) - fluid;
    if (c.i == c.j && c.i >= 3) from_apply.diagonal() *= 1.0 + gamma;  // dense_matrix has no boost
    CHECK((exported - c.reference).cwiseAbs().maxCoeff() <= 1e-11 * scale);
    CHECK((exported_mf - c.reference).cwiseAbs().maxCoeff() <= 1e-11 * scale);
    CHECK((from_apply - c.reference).cwiseAbs().maxCoeff() <= 1e-11 * scale);
    // and the transposed block of the export
    const std::string mirror = "A" + std::to_string(c.j) + std::to_string(c.i);
    CHECK((Dense(ex.matrix(mirror)->value) - Dense(ex.matrix(name)->value).transpose()).cwiseAbs().maxCoeff() == 0.0);
  }
  // M_r and the Jacobians themselves (the exported J_p, J_s are the paper's, alpha Jh)
  CHECK((Dense(ex.matrix("M_r")->value) - mr).cwiseAbs().maxCoeff() <= 1e-12 * mr.cwiseAbs().maxCoeff());
  CHECK((Dense(ex.matrix("J_p")->value) - jp).cwiseAbs().maxCoeff() <= 1e-11 * jp.cwiseAbs().maxCoeff());
  CHECK((Dense(ex.matrix("J_s")->value) - js).cwiseAbs().maxCoeff() <= 1e-11 * js.cwiseAbs().maxCoeff());
  CHECK((Dense(ex.matrix("J_lambda")->value) - jl).cwiseAbs().maxCoeff() <= 1e-13);
  CHECK((Dense(ex.matrix("J_z")->value) - jz).cwiseAbs().maxCoeff() <= 1e-13);
  // restitution: C = I + R on the contacts that approach faster than the threshold (0 here)
  const VectorX c_diag = Dense(ex.matrix("C")->value).diagonal();
  int bouncing = 0;
  for (int c = 0; c < nc; ++c) {
    bouncing += c_diag[c] != 1.0;
    const double approach = (jl.row(c) * cs.v_star)(0);
    INFO("contact " << c << " approach " << approach << " gap " << contacts[c].phi);
    if (approach < 0.0 && contacts[c].phi + params.margin_cells * dx + dt * approach <= 0.0)
      CHECK(c_diag[c] == Approx(1.5));
    else
      CHECK(c_diag[c] == 1.0);
  }
  CHECK(bouncing >= 1);  // restitution is among the cases
}

}  // namespace

TEST_CASE("rigid blocks of eq. (24) equal dense references from the paper's definitions, 2D",
          "[coupling][oracle]") {
  check_rigid_blocks<2>(16);
}

TEST_CASE("rigid blocks of eq. (24) equal dense references from the paper's definitions, 3D",
          "[coupling][oracle]") {
  check_rigid_blocks<3>(8);
}
