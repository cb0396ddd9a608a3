#pragma once
/// \file test_helpers.hpp
/// Analytic shapes and random data shared by the tests: each test depends only on the library
/// code under test plus these exact, independent definitions.

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <random>
#include <string>
#include <vector>

#include "reference/app/scene_file.hpp"
#include "reference/core/common.hpp"
#include "reference/fluid/pressure_projection.hpp"
#include "reference/fluid/stokes_system.hpp"
#include "reference/geometry/shape.hpp"
#include "reference/grid/stress_weights.hpp"
#include "reference/grid/volume_fractions.hpp"

namespace monolith::testing {

constexpr double kPi = 3.14159265358979323846;

/// Whether two doubles have the same bits (+0 and -0 differ, a NaN equals its own bits).
inline bool same_bits(double a, double b) { return std::memcmp(&a, &b, sizeof(double)) == 0; }

/// How many entries of a and b differ in their bits; -1 when the sizes differ.
inline long differing(const VectorX& a, const VectorX& b) {
  if (a.size() != b.size()) return -1;
  long n = 0;
  for (Eigen::Index i = 0; i < a.size(); ++i) n += !same_bits(a[i], b[i]);
  return n;
}

/// The unit square / cube split into n cells per axis (periodic along x when asked).
template <int Dim>
MacGrid<Dim> unit_grid(int n, bool periodic_x = false) {
  std::array<bool, Dim> periodic{};
  periodic[0] = periodic_x;
  return MacGrid<Dim>(Vec<Dim>::Zero(), 1.0 / n, VecI<Dim>::Constant(n), periodic);
}

/// f(position) at every point of a sample lattice (a level set on the half lattice).
template <int Dim, class F>
VectorX sample_lattice(const SampleLattice<Dim>& lattice, F&& f) {
  VectorX phi(lattice.size());
  for (int k = 0; k < lattice.size(); ++k) phi[k] = f(lattice.position(lattice.coord(k)));
  return phi;
}

/// Face velocities (MacGrid face numbering) equal to component a of u on every face of axis a.
template <int Dim>
VectorX uniform_face_velocity(const MacGrid<Dim>& grid, const Vec<Dim>& u) {
  VectorX v(grid.num_faces());
  for (int a = 0; a < Dim; ++a) v.segment(grid.face_offset(a), grid.num_faces(a)).setConstant(u[a]);
  return v;
}

/// The same boundary type on every side of the domain.
template <int Dim>
std::array<BoundaryType, 2 * Dim> all_boundaries(BoundaryType type) {
  std::array<BoundaryType, 2 * Dim> b;
  b.fill(type);
  return b;
}

/// A vector as the std::vector a ShapeSpec field holds.
template <int Dim>
std::vector<double> as_std(const Vec<Dim>& v) {
  return std::vector<double>(v.data(), v.data() + Dim);
}

/// The scene spec of a box (centre c, half sizes h, optional rotation value).
template <int Dim>
ShapeSpec box_spec(const Vec<Dim>& c, const Vec<Dim>& h, std::vector<double> rotation = {}) {
  ShapeSpec s;
  s.type = ShapeType::box;
  s.center = as_std<Dim>(c);
  s.half_size = as_std<Dim>(h);
  s.rotation = std::move(rotation);
  return s;
}

/// The scene spec of a round shape (sphere, bowl, shell) of radius r and thickness t.
template <int Dim>
ShapeSpec round_spec(ShapeType type, const Vec<Dim>& c, double r, double t = 0.0) {
  ShapeSpec s;
  s.type = type;
  s.center = as_std<Dim>(c);
  s.radius = r;
  s.thickness = t;
  return s;
}

/// A ball (a disk in 2D) with its exact signed distance.
template <int Dim>
class TestBall : public Shape<Dim> {
 public:
  TestBall(const Vec<Dim>& c, double r) : c_(c), r_(r) {}
  double distance(const Vec<Dim>& x) const override { return (x - c_).norm() - r_; }
  Vec<Dim> gradient(const Vec<Dim>& x) const override {
    const Vec<Dim> d = x - c_;
    return d.norm() > 0 ? Vec<Dim>(d.normalized()) : Vec<Dim>(Vec<Dim>::UnitX());
  }
  Box<Dim> bounds() const override {
    return Box<Dim>(c_ - Vec<Dim>::Constant(r_), c_ + Vec<Dim>::Constant(r_));
  }

 private:
  Vec<Dim> c_;
  double r_;
};

/// An axis-aligned box with its exact signed distance.
template <int Dim>
class TestBox : public Shape<Dim> {
 public:
  TestBox(const Vec<Dim>& c, const Vec<Dim>& half) : c_(c), half_(half) {}
  double distance(const Vec<Dim>& x) const override {
    const Vec<Dim> q = (x - c_).cwiseAbs() - half_;
    return q.cwiseMax(0.0).norm() + std::min(q.maxCoeff(), 0.0);
  }
  Box<Dim> bounds() const override { return Box<Dim>(c_ - half_, c_ + half_); }

 private:
  Vec<Dim> c_, half_;
};

/// n numbers uniform in [-1, 1], reproducible for a seed.
inline VectorX random_vector(int n, unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  VectorX v(n);
  for (int i = 0; i < n; ++i) v[i] = u(rng);
  return v;
}

/// uniform_face_velocity with every face moved by -2..2 ulps (floor(2.5 r), r of random_vector
/// with `seed`): u* as a particle transfer leaves a uniform motion, b = 0 in exact arithmetic and
/// round-off in floating point (the round-off rules of docs/preconditioners.md sections 26, 33, 35).
template <int Dim>
VectorX uniform_face_velocity_with_ulps(const MacGrid<Dim>& grid, const Vec<Dim>& u, unsigned seed) {
  VectorX v = uniform_face_velocity(grid, u);
  const VectorX r = random_vector(grid.num_faces(), seed);  // in [-1, 1]
  for (Eigen::Index f = 0; f < v.size(); ++f) {
    const int ulps = static_cast<int>(std::floor(2.5 * r[f]));
    for (int k = 0; k < std::abs(ulps); ++k) v[f] = std::nextafter(v[f], ulps > 0 ? 10.0 : -10.0);
  }
  return v;
}

/// The weights of eq. (8) for liquid of density rho below the flat surface y = h, no solids
/// (walls and open faces as `boundary` says); the liquid level set is y - h on the half lattice.
template <int Dim>
PressureWeights flat_surface_weights(const MacGrid<Dim>& grid,
                                     const std::array<BoundaryType, 2 * Dim>& boundary, double h,
                                     double rho) {
  const SampleLattice<Dim> lattice = half_lattice(grid);
  PressureWeights w;
  w.fluid_face = fluid_face_weights(grid, lattice,
                                    solid_phi_on_lattice<Dim>(grid, lattice, {}, 0.0), boundary);
  VectorX phi(lattice.size());
  for (int k = 0; k < lattice.size(); ++k) phi[k] = lattice.position(lattice.coord(k))[1] - h;
  w.liquid_cell = liquid_cell_weights(grid, lattice, phi);
  w.liquid_face = liquid_face_weights(grid, lattice, phi, w.liquid_cell);
  w.face_density = VectorX::Constant(grid.num_faces(), rho);
  return w;
}

/// The weights of eq. (8) with one density and one viscosity: uniform_stokes_weights
/// (reference/fluid/stokes_system.hpp).
template <int Dim>
StokesWeights stokes_weights(const MacGrid<Dim>& grid, const VectorX& solid_phi,
                             const VectorX& liquid_phi,
                             const std::array<BoundaryType, 2 * Dim>& boundary, double rho,
                             double eta) {
  return uniform_stokes_weights(grid, solid_phi, liquid_phi, boundary, rho, eta);
}

/// The point (x, y) of the unit box, in 3D at the box's middle along z (0.5).
template <int Dim>
Vec<Dim> centre_at(double x, double y) {
  Vec<Dim> p = Vec<Dim>::Constant(0.5);
  p[0] = x;
  p[1] = y;
  return p;
}

}  // namespace monolith::testing
