// Fig. 18's viscous coupled systems in proportion to the bodies (issue 20): W_F^s made with the
// solids' union kept per body (SolidWeightsScratch::union_in_parts, stress wanted) against the
// dense union of solid_weights, over several poses (the calls after the first make only the
// stress DOFs near the moving bodies again), and the system of eq. (24) with J_s searched only
// at the unknowns' stress DOFs and W_F^s kept per body against the dense construction: the same
// bits, the explicit back end's matrices and the matrix-free back end's products.
#include <catch2/catch.hpp>

#include <memory>
#include <vector>

#include "reference/contact/contact_system.hpp"
#include "reference/coupling/coupled_schemes.hpp"
#include "reference/coupling/coupling.hpp"
#include "reference/coupling/monolithic_system.hpp"
#include "reference/grid/stress_grid.hpp"
#include "tests/support/body_helpers.hpp"
#include "tests/support/test_helpers.hpp"

using namespace monolith;
using monolith::testing::all_boundaries;
using monolith::testing::differing;
using monolith::testing::same_bits;
using monolith::testing::TestBall;
using monolith::testing::TestBox;
using monolith::testing::unit_grid;

namespace {

/// A ball whose level set is `steep` times its distance: not a distance (its values beside the
/// surface exceed 2 dx), so the kept fixed body fails the test of the W_F^s in parts.
template <int Dim>
class SteepBall : public Shape<Dim> {
 public:
  SteepBall(const Vec<Dim>& c, double r, double steep) : c_(c), r_(r), steep_(steep) {}
  double distance(const Vec<Dim>& x) const override { return steep_ * ((x - c_).norm() - r_); }
  Box<Dim> bounds() const override {
    return Box<Dim>(c_ - Vec<Dim>::Constant(r_), c_ + Vec<Dim>::Constant(r_));
  }

 private:
  Vec<Dim> c_;
  double r_, steep_;
};

template <int Dim>
CouplingBody<Dim> body(ShapePtr<Dim> shape, const Vec<Dim>& c, bool two_way) {
  CouplingBody<Dim> b;
  b.shape = std::move(shape);
  b.center = c;
  b.two_way = two_way;
  return b;
}

enum class Fixed { slab, none, steep, two };

/// Four poses of two moving balls (one reaching into the fixed body, one crossing the domain's
/// edge) beside a fixed body as the scratch's `fixed` says: W_F^s, W_F^u and every W_{S,i}^u of
/// the call with the union kept per body equal those of a dense call bit for bit. Pose 3 gets
/// another W_F^s buffer (every DOF made again).
template <int Dim>
void check_stress_parts(int n, double shrink_cells, const std::array<BoundaryType, 2 * Dim>& boundary,
                        bool periodic_x, Fixed fixed) {
  const MacGrid<Dim> grid = unit_grid<Dim>(n, periodic_x);
  const SampleLattice<Dim> lattice = half_lattice(grid);
  const StressGrid<Dim> stress(grid);
  const double shrink = shrink_cells * grid.dx();
  SolidWeights<Dim> kept;
  SolidWeightsScratch<Dim> scratch;
  scratch.parts = false;
  scratch.stress = true;
  scratch.union_in_parts = true;
  long made_again = 0;
  for (int pose = 0; pose < 4; ++pose) {
    Vec<Dim> slab_half = Vec<Dim>::Constant(0.45);
    slab_half[1] = 0.3;
    Vec<Dim> slab_centre = Vec<Dim>::Constant(0.5);
    slab_centre[1] = 0.3;
    // steps longer than the balls' boxes' margin (far + two lattice points): faces of the last
    // call's box are left behind
    const double t = 0.16 * pose;
    const Vec<Dim> c1 = Vec<Dim>::Constant(0.3 + (pose == 3 ? 0.0 : t)) +
                        Vec<Dim>::LinSpaced(0.011, 0.029);
    const Vec<Dim> c2 = Vec<Dim>::Constant(0.88 - 0.5 * t);
    std::vector<CouplingBody<Dim>> bodies;
    if (fixed == Fixed::slab || fixed == Fixed::two)
      bodies.push_back(body<Dim>(std::make_shared<TestBox<Dim>>(slab_centre, slab_half),
                                 slab_centre, false));
    if (fixed == Fixed::steep)
      bodies.push_back(body<Dim>(std::make_shared<SteepBall<Dim>>(slab_centre, 0.3, 8.0),
                                 slab_centre, false));
    bodies.push_back(body<Dim>(std::make_shared<TestBall<Dim>>(c1, 0.13), c1, true));
    if (fixed == Fixed::two)
      bodies.push_back(body<Dim>(std::make_shared<TestBall<Dim>>(Vec<Dim>::Constant(0.1), 0.08),
                                 Vec<Dim>::Constant(0.1), false));
    bodies.push_back(body<Dim>(std::make_shared<TestBall<Dim>>(c2, 0.12), c2, true));
    scratch.fixed.clear();
    for (const auto& b : bodies) scratch.fixed.push_back(!b.two_way);

    SolidWeights<Dim> dense;
    SolidWeightsScratch<Dim> dense_scratch;
    dense_scratch.parts = false;
    solid_weights<Dim>(grid, bodies, {}, boundary, shrink, dense, dense_scratch);
    REQUIRE(dense.fluid_stress.size() == stress.num_dofs());
    REQUIRE(dense.lattice_phi.size() == lattice.size());

    if (pose == 3) {
      VectorX other = VectorX::Constant(stress.num_dofs(), 7.0);
      kept.fluid_stress.swap(other);
    }
    const bool incremental = scratch.kept_stress && pose != 3;
    kept.lattice_phi = VectorX();
    solid_weights<Dim>(grid, bodies, {}, boundary, shrink, kept, scratch);
    if (fixed == Fixed::two) {
      // W_F^s with two fixed bodies: the dense union, not kept per part
      CHECK_FALSE(scratch.union_parts.valid());
    } else {
      REQUIRE(scratch.union_parts.valid());
      CHECK(scratch.kept_stress == (fixed != Fixed::steep));
      // the fallback writes the union densely from its parts
      CHECK(kept.lattice_phi.size() == (fixed == Fixed::steep ? lattice.size() : 0));
      if (fixed == Fixed::steep) CHECK(scratch.fixed_stress_test[0] == 2);
      if (fixed == Fixed::slab) CHECK(scratch.fixed_stress_test[0] == 1);
      CHECK(scratch.signs.lo == dense_scratch.signs.lo);
      CHECK(scratch.signs.hi == dense_scratch.signs.hi);
      if (incremental && fixed != Fixed::steep) {
        long listed = 0;
        for (const auto& list : scratch.stress_near) listed += static_cast<long>(list.size());
        CHECK(listed > 0);
        CHECK(listed < stress.num_dofs());
        made_again += listed;
      }
    }
    REQUIRE(kept.fluid_stress.size() == stress.num_dofs());
    CHECK(differing(kept.fluid_stress, dense.fluid_stress) == 0);
    CHECK(differing(kept.fluid_face, dense.fluid_face) == 0);
    REQUIRE(kept.body_face.size() == bodies.size());
    for (std::size_t i = 0; i < bodies.size(); ++i)
      CHECK(differing(kept.body_face[i], dense.body_face[i]) == 0);
    // the comparison can fail: the moving balls change W_F^s between the poses
    if (pose > 0) {
      SolidWeights<Dim> first;
      std::vector<CouplingBody<Dim>> moved = bodies;
      for (auto& b : moved)
        if (b.two_way) b.shape = std::make_shared<TestBall<Dim>>(b.center + Vec<Dim>::Constant(0.05), 0.13);
      solid_weights<Dim>(grid, moved, {}, boundary, shrink, first, dense_scratch);
      CHECK(differing(first.fluid_stress, dense.fluid_stress) > 0);
    }
  }
  if (fixed == Fixed::slab || fixed == Fixed::none) CHECK(made_again > 0);
}

/// A viscous coupled step (eta 50, liquid below y = 0.55, walls and an open top) with a fixed
/// floor slab reaching a third of the way up, a dynamic ball half in the liquid and a dynamic
/// box at its surface: the system built from W_F^s kept per body (the second pose of a scratch
/// that saw the bodies elsewhere first) and J_s at the unknowns' DOFs equals the system built
/// from the dense weights with every column of the bodies' boxes searched, bit for bit: the
/// dense matrix of eq. (24), its right-hand side and the fluid-body force of unit vectors, on
/// both back ends and both stress forms.
template <int Dim>
void check_system(int n) {
  const MacGrid<Dim> grid = unit_grid<Dim>(n);
  const double dx = grid.dx();
  const double dt = 0.01;
  ShapeSpec ball;
  ball.type = ShapeType::sphere;
  ball.radius = 0.17;
  ball.center = testing::as_std<Dim>(testing::centre_at<Dim>(0.62, 0.52));
  // the floor slab (y from -0.2 to 0.3, wider than the domain), the ball, the box
  Vec<Dim> floor_half = Vec<Dim>::Constant(0.6);
  floor_half[1] = 0.25;
  std::vector<RigidBody<Dim>> bodies = {
      testing::make_box<Dim>(testing::centre_at<Dim>(0.5, 0.05), floor_half, 1000.0, 0.0,
                             BodyMotion::fixed),
      testing::make_body<Dim>(ball, 2500.0),
      testing::make_box<Dim>(testing::centre_at<Dim>(0.27, 0.55), Vec<Dim>::Constant(0.1), 600.0)};
  for (int b = 1; b < 3; ++b) {
    BodyVec<Dim> v = BodyVec<Dim>::Zero();
    v[0] = 0.05 * b;
    v[1] = -9.81 * dt - 0.1;
    v[Dim] = 0.3;
    bodies[b].set_generalized_velocity(v);
  }
  std::array<BoundaryType, 2 * Dim> boundary = all_boundaries<Dim>(BoundaryType::wall);
  boundary[3] = BoundaryType::open;
  const double shrink = 0.01 * dx;
  const std::vector<CouplingBody<Dim>> view = coupling_bodies(bodies);

  // dense: the union written over the lattice
  const SolidWeights<Dim> dense = solid_weights<Dim>(grid, view, {}, boundary, shrink);
  // kept per body: a first call with the moving bodies elsewhere, then this pose
  SolidWeights<Dim> band;
  SolidWeightsScratch<Dim> scratch;
  scratch.fixed = {1, 0, 0};
  scratch.parts = false;
  scratch.stress = true;
  scratch.union_in_parts = true;
  std::vector<CouplingBody<Dim>> before = view;
  for (std::size_t i = 1; i < before.size(); ++i) {
    ShapeSpec s = i == 1 ? ball
                         : testing::box_spec<Dim>(testing::centre_at<Dim>(0.27, 0.55),
                                                  Vec<Dim>::Constant(0.1));
    s.center = testing::as_std<Dim>(Vec<Dim>(Eigen::Map<const Vec<Dim>>(s.center.data()) +
                                             Vec<Dim>::Constant(0.06)));
    before[i].shape = make_shape<Dim>(s, "test");
  }
  solid_weights<Dim>(grid, before, {}, boundary, shrink, band, scratch);
  solid_weights<Dim>(grid, view, {}, boundary, shrink, band, scratch);
  REQUIRE(scratch.union_parts.valid());
  REQUIRE(scratch.kept_stress);
  REQUIRE(differing(band.fluid_stress, dense.fluid_stress) == 0);

  const VectorX phi = testing::sample_lattice<Dim>(
      half_lattice(grid), [](const Vec<Dim>& x) { return x[1] - 0.55; });
  const StokesWeights w_dense = coupled_stokes_weights<Dim>(grid, dense, phi, 1000.0, 50.0);
  const StokesWeights w_band = coupled_stokes_weights<Dim>(grid, band, phi, 1000.0, 50.0);
  VectorX u_star = 0.2 * testing::random_vector(grid.num_faces(), 7);
  u_star.segment(grid.face_offset(1), grid.num_faces(1)).array() += -9.81 * dt;
  ContactParameters params;
  params.dt = dt;
  params.dx = dx;
  const ContactSystem<Dim> contacts(bodies, {}, params);

  for (const StressForm form : {StressForm::reduced, StressForm::full})
    for (const Backend backend : {Backend::explicit_matrices, Backend::matrix_free}) {
      MonolithicSystem<Dim>::search_every_column = true;
      const MonolithicSystem<Dim> full(grid, form, w_dense, dt, u_star, bodies, dense, contacts,
                                       backend);
      MonolithicSystem<Dim>::search_every_column = false;
      const MonolithicSystem<Dim> restricted(grid, form, w_band, dt, u_star, bodies, band,
                                             contacts, backend);
      REQUIRE(full.num_stress() > 0);
      REQUIRE(full.num_stress() == restricted.num_stress());
      REQUIRE(full.num_pressure() == restricted.num_pressure());
      const Eigen::MatrixXd a = full.dense_matrix(), b = restricted.dense_matrix();
      long matrix_differs = 0;
      for (Eigen::Index i = 0; i < a.size(); ++i)
        matrix_differs += !same_bits(a.data()[i], b.data()[i]);
      CHECK(matrix_differs == 0);
      CHECK(differing(full.rhs(), restricted.rhs()) == 0);
      // B_f column by column (the rigid columns of the matrix-free back end, b_fluid of the
      // explicit one)
      long force_differs = 0;
      double force_sum = 0.0;
      VectorX e = VectorX::Zero(full.num_fluid());
      for (int k = 0; k < full.num_fluid(); ++k) {
        e.setZero();
        e[k] = 1.0;
        const VectorX f1 = full.fluid_body_force(e), f2 = restricted.fluid_body_force(e);
        force_differs += differing(f1, f2);
        force_sum += f1.cwiseAbs().sum();
      }
      CHECK(force_differs == 0);
      // the bodies feel the liquid's stress (else the comparison of J_s would be empty)
      double stress_force = 0.0;
      for (int k = 0; k < full.num_stress(); ++k) {
        e.setZero();
        e[k] = 1.0;
        stress_force += full.fluid_body_force(e).cwiseAbs().sum();
      }
      CHECK(stress_force > 0.0);
      CHECK(force_sum > stress_force);
    }
}

}  // namespace

TEST_CASE("W_F^s with the union kept per body equals the dense union's bits",
          "[unit][dense-reference]") {
  auto walls2 = all_boundaries<2>(BoundaryType::wall);
  auto open2 = walls2;
  open2[3] = BoundaryType::open;
  open2[0] = BoundaryType::open;
  check_stress_parts<2>(40, 0.01, walls2, false, Fixed::slab);
  check_stress_parts<2>(32, 0.0, open2, false, Fixed::slab);
  check_stress_parts<2>(32, 0.01, walls2, true, Fixed::slab);
  check_stress_parts<2>(32, 0.01, open2, false, Fixed::none);
  check_stress_parts<2>(32, 0.01, walls2, false, Fixed::steep);
  check_stress_parts<2>(32, 0.01, walls2, false, Fixed::two);
  auto walls3 = all_boundaries<3>(BoundaryType::wall);
  auto open3 = walls3;
  open3[3] = BoundaryType::open;
  check_stress_parts<3>(20, 0.01, walls3, false, Fixed::slab);
  check_stress_parts<3>(16, 0.01, open3, false, Fixed::slab);
  check_stress_parts<3>(16, 0.01, walls3, false, Fixed::none);
}

TEST_CASE("the viscous coupled system with J_s at the unknowns and W_F^s per body equals the "
          "dense construction bit for bit",
          "[unit][dense-reference]") {
  check_system<2>(20);
  check_system<3>(10);
}
