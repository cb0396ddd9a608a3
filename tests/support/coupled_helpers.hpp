#pragma once
/// \file coupled_helpers.hpp
/// The coupled system of one step input and the dense maps the coupled preconditioner's tests
/// compare (test_coupled_preconditioner.cpp, test_near_empty_cells.cpp): M^-1 column by column,
/// the reference M of the exact contact elimination (A with Q^-1 in the fluid block's place)
/// and apply_in_face on a free set against M_FF^-1 (check_in_face_inverse holds Catch assertions:
/// for the tests only).

#include <vector>

#include <Eigen/Dense>
#include <Eigen/Eigenvalues>
#include <catch2/catch.hpp>

#include "reference/contact/contact_system.hpp"
#include "reference/coupling/coupled_schemes.hpp"
#include "reference/coupling/monolithic_system.hpp"
#include "reference/grid/volume_fractions.hpp"
#include "reference/solvers/mprgp.hpp"
#include "reference/solvers/preconditioner.hpp"
#include "tests/support/test_helpers.hpp"

namespace monolith::testing {

/// The system (24)/(26) of a step input (reduced stress form) on `backend`.
template <int Dim>
MonolithicSystem<Dim> make_system(const CoupledStepInput<Dim>& in, Backend backend) {
  const ContactSystem<Dim> contacts(in.bodies, in.contacts, in.contact_params);
  return MonolithicSystem<Dim>(in.grid, StressForm::reduced, in.weights, in.dt, in.u_star,
                               in.bodies, in.solids, contacts, backend);
}

/// The liquid of the coupled preconditioner tests' unit tank, on a step input whose grid, dt,
/// bodies and solids are set: density rho and viscosity eta below y = 0.55 (coupled_stokes_weights),
/// u* = 0.2 x a random vector (seed 7) plus one step of gravity on the vertical faces, and the
/// contact parameters' dt and dx.
template <int Dim>
void fill_tank_liquid(CoupledStepInput<Dim>& in, double rho, double eta) {
  const VectorX phi =
      sample_lattice<Dim>(half_lattice(in.grid), [](const Vec<Dim>& x) { return x[1] - 0.55; });
  in.weights = coupled_stokes_weights<Dim>(in.grid, in.solids, phi, rho, eta);
  in.u_star = 0.2 * random_vector(in.grid.num_faces(), 7);
  in.u_star.segment(in.grid.face_offset(1), in.grid.num_faces(1)).array() += -9.81 * in.dt;
  in.contact_params.dt = in.dt;
  in.contact_params.dx = in.grid.dx();
}

/// M^-1 densely (column by column through apply).
inline Eigen::MatrixXd dense(const Preconditioner& m) {
  const int n = m.size();
  Eigen::MatrixXd d(n, n);
  VectorX e = VectorX::Zero(n), z;
  for (int k = 0; k < n; ++k) {
    e.setZero();
    e[k] = 1.0;
    m.apply(e, z);
    d.col(k) = z;
  }
  return d;
}

/// The exact contact elimination's reference for the dense A of (26) (nf fluid rows, then the
/// contact rows) and Q^-1 of the fluid block densely (qd): M = A with (sym Q)^-1 in the fluid
/// block's place, and the Schur complement S_c = A33' - A_3f Q A_f3 of M.
struct ContactElimination {
  Eigen::MatrixXd m, schur;
};
inline ContactElimination contact_elimination(const Eigen::MatrixXd& a, const Eigen::MatrixXd& qd,
                                              int nf) {
  const Eigen::Index nc = a.rows() - nf;
  ContactElimination r;
  r.m = a;
  r.m.topLeftCorner(nf, nf) = (0.5 * (qd + qd.transpose())).inverse();
  r.schur = a.bottomRightCorner(nc, nc) - a.bottomLeftCorner(nc, nf) * qd * a.topRightCorner(nf, nc);
  return r;
}

/// apply_in_face on the free set densely (applied: k x k over the k free unknowns, column c the
/// application to the unit vector of the c-th free unknown) and M_FF^-1 of the dense M on the
/// same set (expected); outside: how many entries off the free set the applications left non-zero.
struct InFaceMaps {
  Eigen::MatrixXd applied, expected;
  long outside = 0;
};
inline InFaceMaps in_face_maps(const FacePreconditioner& p, const Eigen::MatrixXd& m,
                               const std::vector<char>& free) {
  const int nt = static_cast<int>(free.size());
  std::vector<int> f;
  for (int i = 0; i < nt; ++i)
    if (free[i]) f.push_back(i);
  const int k = static_cast<int>(f.size());
  InFaceMaps r;
  Eigen::MatrixXd mff(k, k);
  r.applied.resize(k, k);
  for (int row = 0; row < k; ++row)
    for (int c = 0; c < k; ++c) mff(row, c) = m(f[row], f[c]);
  VectorX e = VectorX::Zero(nt), z;
  for (int c = 0; c < k; ++c) {
    e.setZero();
    e[f[c]] = 1.0;
    p.apply_in_face(e, free, z);
    for (int i = 0; i < nt; ++i)
      if (!free[i] && z[i] != 0.0) ++r.outside;
    for (int row = 0; row < k; ++row) r.applied(row, c) = z[f[row]];
  }
  r.expected = mff.inverse();
  return r;
}

/// The checks of apply_in_face on one free set (Catch assertions): zero off the set, M_FF^-1 of
/// the dense M to 1e-6 (relative, Frobenius), symmetric to 1e-9, positive definite. Returns the
/// relative error.
inline double check_in_face_inverse(const FacePreconditioner& p, const Eigen::MatrixXd& m,
                                    const std::vector<char>& free) {
  const InFaceMaps maps = in_face_maps(p, m, free);
  CHECK(maps.outside == 0);
  const Eigen::MatrixXd& zd = maps.applied;
  const double err = (zd - maps.expected).norm() / maps.expected.norm();
  CHECK(err < 1e-6);
  const double asym = (zd - zd.transpose()).norm() / zd.norm();
  CHECK(asym < 1e-9);
  const Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> es(0.5 * (zd + zd.transpose()),
                                                          Eigen::EigenvaluesOnly);
  CHECK(es.eigenvalues().minCoeff() > 0.0);
  return err;
}

}  // namespace monolith::testing
