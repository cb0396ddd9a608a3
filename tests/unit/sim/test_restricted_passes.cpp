// The per-step passes restricted to the liquid's band and the moving bodies (issue 20, Fig. 17;
// docs/benchmarks.md "eleventh part") against their dense forms: the search for negative points
// in a box, the liquid level set's band, and whole simulations with StageSwitches::
// restricted_passes on and off (faces in solids kept for the fixed bodies with their normals'
// share, the extension into the solids and the classification in the liquid's band): the same
// bits.
#include <catch2/catch.hpp>
#include <omp.h>

#include <cstring>
#include <limits>
#include <memory>
#include <random>

#include "reference/app/scene_file.hpp"
#include "reference/fluid/pressure_projection.hpp"
#include "reference/grid/stress_weights.hpp"
#include "reference/grid/volume_fractions.hpp"
#include "reference/particles/particles.hpp"
#include "reference/sim/simulation.hpp"
#include "tests/support/test_helpers.hpp"

using namespace monolith;
using monolith::testing::all_boundaries;
using monolith::testing::TestBall;
using monolith::testing::unit_grid;
using monolith::testing::same_bits;

namespace {

template <int Dim>
LiquidSpec water_at(const Vec<Dim>& centre, double radius) {
  LiquidSpec spec;
  spec.name = "water";
  spec.density = 1000.0;
  spec.shape.type = ShapeType::sphere;
  spec.shape.center.assign(centre.data(), centre.data() + Dim);
  spec.shape.radius = radius;
  return spec;
}

/// A field with negative values only in [lo, hi] (random signs there), positive elsewhere.
template <int Dim>
VectorX field_negative_in(const SampleLattice<Dim>& lattice, const VecI<Dim>& lo,
                          const VecI<Dim>& hi, unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  VectorX phi(lattice.size());
  for (int k = 0; k < lattice.size(); ++k) {
    const VecI<Dim> c = lattice.coord(k);
    const bool inside = (c.array() >= lo.array()).all() && (c.array() <= hi.array()).all();
    const double v = u(rng);
    phi[k] = inside && v < -0.6 ? v : std::abs(v) + 0.01;
  }
  return phi;
}

template <int Dim>
void check_negative_point_search(int n) {
  const MacGrid<Dim> grid = unit_grid<Dim>(n);
  const SampleLattice<Dim> lattice = half_lattice(grid);
  VecI<Dim> lo = VecI<Dim>::Constant(3), hi = VecI<Dim>::Constant(2 * n - 5);
  hi[0] = n;  // not symmetric
  const VectorX phi = field_negative_in<Dim>(lattice, lo, hi, 17u);
  const auto [dense_lo, dense_hi] = negative_point_box(lattice, phi);
  REQUIRE((dense_lo.array() <= dense_hi.array()).all());
  // any search box that holds every negative point finds the same box
  for (int grow : {0, 1, 5}) {
    const auto [box_lo, box_hi] = negative_point_box_in<Dim>(
        lattice, phi, (dense_lo - VecI<Dim>::Constant(grow)).eval(),
        (dense_hi + VecI<Dim>::Constant(grow)).eval());
    CHECK(box_lo == dense_lo);
    CHECK(box_hi == dense_hi);
  }
  // a box that leaves out the last negative row finds less (the search reads only its box)
  VecI<Dim> cut_hi = dense_hi;
  cut_hi[Dim - 1] -= 1;
  const auto [cut_lo2, cut_hi2] = negative_point_box_in<Dim>(lattice, phi, dense_lo, cut_hi);
  CHECK(cut_hi2[Dim - 1] < dense_hi[Dim - 1]);
  (void)cut_lo2;
  // an empty search box finds nothing
  const auto [none_lo, none_hi] =
      negative_point_box_in<Dim>(lattice, phi, VecI<Dim>::Constant(2), VecI<Dim>::Constant(1));
  CHECK((none_lo.array() > none_hi.array()).any());
  // the classes of a search in the box equal those of the whole lattice
  LatticeSigns<Dim> dense, searched;
  classify_lattice_cells(grid, lattice, phi, dense);
  classify_lattice_cells_searching(grid, lattice, phi, lo, hi, searched);
  CHECK(searched.lo == dense.lo);
  CHECK(searched.hi == dense.hi);
  const VecI<Dim> cells = 2 * grid.cells();
  long differ = 0;
  for (int j = 0; j < cells.prod(); ++j) {
    const VecI<Dim> l = lattice_coord<Dim>(j, cells);
    differ += searched.class_of(l) != dense.class_of(l);
  }
  CHECK(differ == 0);
}

template <int Dim>
void check_liquid_band(int n) {
  const MacGrid<Dim> grid = unit_grid<Dim>(n);
  const SampleLattice<Dim> lattice = half_lattice(grid);
  const Vec<Dim> centre = Vec<Dim>::Constant(0.3);
  auto ball = std::make_shared<TestBall<Dim>>(centre, 0.12);
  const Particles<Dim> particles = seed_particles<Dim>(
      grid, {water_at<Dim>(centre, 0.12)}, {ball}, SolidField<Dim>{}, Dim == 2 ? 4 : 8, 3u);
  REQUIRE(particles.size() > 0);
  const auto boundary = all_boundaries<Dim>(BoundaryType::wall);
  const VectorX plain = liquid_phi_on_lattice(particles, grid, lattice, boundary);
  VectorX phi;
  LiquidPhiBand<Dim> band;
  liquid_phi_on_lattice(particles, grid, lattice, boundary, SolidField<Dim>{}, phi, band);
  REQUIRE(phi.size() == plain.size());
  long differ = 0, outside = 0, outside_not_background = 0;
  for (int k = 0; k < lattice.size(); ++k) {
    differ += !same_bits(phi[k], plain[k]);
    const VecI<Dim> c = lattice.coord(k);
    if ((c.array() < band.lo.array()).any() || (c.array() > band.hi.array()).any()) {
      ++outside;
      outside_not_background += !same_bits(phi[k], band.background);
    }
  }
  CHECK(differ == 0);
  CHECK(outside_not_background == 0);
  // the band is a small part of the lattice here, and covers the liquid
  CHECK(outside > lattice.size() / 2);
  CHECK(band.background >= kLiquidSolidReach * grid.dx());
  const auto [neg_lo, neg_hi] = negative_point_box(lattice, phi);
  CHECK((neg_lo.array() >= band.lo.array()).all());
  CHECK((neg_hi.array() <= band.hi.array()).all());
  // no particle: the background everywhere and an empty band
  liquid_phi_on_lattice(Particles<Dim>{}, grid, lattice, boundary, SolidField<Dim>{}, phi, band);
  CHECK(band.empty());
  CHECK(same_bits(phi[0], band.background));
}

/// The level set stored over its band (band19): the box is the band grown by `margin` points
/// (clamped), the values there and the background elsewhere are the dense vector's bits, and
/// the classes and the cell, face and stress fractions read through the box's view are those of
/// the dense vector (a reader reading outside the box would read another point's entry).
template <int Dim>
void check_boxed_liquid_phi(int n) {
  const MacGrid<Dim> grid = unit_grid<Dim>(n);
  const SampleLattice<Dim> lattice = half_lattice(grid);
  const Vec<Dim> centre = Vec<Dim>::Constant(0.3);
  auto ball = std::make_shared<TestBall<Dim>>(centre, 0.12);
  const Particles<Dim> particles = seed_particles<Dim>(
      grid, {water_at<Dim>(centre, 0.12)}, {ball}, SolidField<Dim>{}, Dim == 2 ? 4 : 8, 5u);
  REQUIRE(particles.size() > 0);
  const auto boundary = all_boundaries<Dim>(BoundaryType::wall);
  VectorX plain;
  LiquidPhiBand<Dim> plain_band, band;
  liquid_phi_on_lattice(particles, grid, lattice, boundary, SolidField<Dim>{}, plain, plain_band);
  const int margin = 2;
  const double reach = kLiquidSolidReach * grid.dx();
  BoxedLattice<Dim> boxed;
  liquid_phi_on_lattice(particles, grid, lattice, boundary, SolidField<Dim>{}, boxed, band, margin,
                        reach);
  REQUIRE(!band.empty());
  CHECK((band.lo.array() == plain_band.lo.array()).all());
  CHECK((band.hi.array() == plain_band.hi.array()).all());
  CHECK(same_bits(band.background, plain_band.background));
  const VecI<Dim> last = lattice.dims - VecI<Dim>::Ones();
  CHECK((boxed.lo.array() == (band.lo - VecI<Dim>::Constant(margin)).cwiseMax(VecI<Dim>::Zero()).array()).all());
  CHECK((boxed.hi.array() == (band.hi + VecI<Dim>::Constant(margin)).cwiseMin(last).array()).all());
  CHECK(boxed.values.size() < lattice.size() / 2);
  CHECK(!boxed.whole());
  CHECK(monolith::testing::differing(boxed.materialise(), plain) == 0);
  // the readers through the view: the same classes and fractions as through the dense vector
  LatticeSigns<Dim> dense_signs, boxed_signs;
  classify_lattice_cells_searching(grid, lattice, plain, band.lo, band.hi, dense_signs);
  classify_lattice_cells_searching<Dim>(grid, lattice, boxed.view(), band.lo, band.hi, boxed_signs);
  REQUIRE(dense_signs.any_negative());
  CHECK(dense_signs.all_classes() == boxed_signs.all_classes());
  VectorX dense_cells, boxed_cells, dense_faces, boxed_faces, dense_stress, boxed_stress;
  cell_negative_fractions(grid, lattice, plain, dense_signs, dense_cells);
  cell_negative_fractions<Dim>(grid, lattice, boxed.view(), boxed_signs, boxed_cells);
  face_negative_fractions(grid, lattice, plain, dense_signs, dense_faces);
  face_negative_fractions<Dim>(grid, lattice, boxed.view(), boxed_signs, boxed_faces);
  const StressGrid<Dim> stress(grid);
  stress_negative_fractions(stress, lattice, plain, dense_signs, dense_stress);
  stress_negative_fractions<Dim>(stress, lattice, boxed.view(), boxed_signs, boxed_stress);
  CHECK(dense_cells.sum() > 0.0);
  CHECK(monolith::testing::differing(dense_cells, boxed_cells) == 0);
  CHECK(monolith::testing::differing(dense_faces, boxed_faces) == 0);
  CHECK(monolith::testing::differing(dense_stress, boxed_stress) == 0);
  // below the background's threshold: the whole lattice, the dense vector's bits
  liquid_phi_on_lattice(particles, grid, lattice, boundary, SolidField<Dim>{}, boxed, band, margin,
                        std::numeric_limits<double>::infinity());
  CHECK(boxed.whole());
  CHECK(monolith::testing::differing(boxed.values, plain) == 0);
  // no particle: an empty box, the background everywhere
  liquid_phi_on_lattice(Particles<Dim>{}, grid, lattice, boundary, SolidField<Dim>{}, boxed, band,
                        margin, reach);
  CHECK(boxed.box_empty());
  CHECK(boxed.values.size() == 0);
  const VectorX empty = boxed.materialise();
  REQUIRE(empty.size() == lattice.size());
  CHECK(same_bits(empty[lattice.size() - 1], 3.0 * grid.dx()));
  boxed.release();
  CHECK(boxed.materialise().size() == 0);
}

using monolith::testing::differing;  // and, for particle positions:

template <int Dim>
long differing(const std::vector<Vec<Dim>>& a, const std::vector<Vec<Dim>>& b) {
  if (a.size() != b.size()) return -1;
  long n = 0;
  for (std::size_t i = 0; i < a.size(); ++i)
    for (int d = 0; d < Dim; ++d) n += !same_bits(a[i][d], b[i][d]);
  return n;
}

/// Two simulations of a built-in scene, restricted passes on and off: after every frame the
/// same statistics, particles, face velocities, pressures, liquid level set, W_F^u and bodies.
template <int Dim>
long check_scene(const std::string& name, const std::string& cells, int frames,
                 bool static_shapes = true) {
  INFO(name);
  const SceneFile scene =
      load_scene(name, {"domain.cells=" + cells, "render.enabled=false"});
  StageSwitches dense;
  dense.restricted_passes = false;
  Simulation<Dim> restricted(scene), reference(scene, dense);
  REQUIRE(restricted.static_shapes().empty() == !static_shapes);
  for (int f = 0; f < frames; ++f) {
    const FrameStats a = restricted.advance_frame();
    const FrameStats b = reference.advance_frame();
    CHECK(a.steps == b.steps);
    CHECK(a.solver.iterations == b.solver.iterations);
    CHECK(same_bits(a.liquid_volume, b.liquid_volume));
    CHECK(same_bits(a.kinetic_energy_liquid, b.kinetic_energy_liquid));
    CHECK(same_bits(a.kinetic_energy_bodies, b.kinetic_energy_bodies));
    const Particles<Dim>& pa = restricted.particles();
    const Particles<Dim>& pb = reference.particles();
    REQUIRE(pa.size() > 0);
    CHECK(differing<Dim>(pa.x, pb.x) == 0);
    CHECK(differing<Dim>(pa.v, pb.v) == 0);
    CHECK(differing(restricted.velocity(), reference.velocity()) == 0);
    CHECK(differing(restricted.pressure(), reference.pressure()) == 0);
    // (band23) a coupled run's pressure is +0 outside the cells its record lists (the solve
    // wrote only those); the dense run keeps no record
    if (restricted.rigid_world()) {
      const ZerosOutsideCells& record = restricted.pressure_cells();
      const VectorX& p = restricted.pressure();
      CHECK(record.holds(p));
      CHECK(!reference.pressure_cells().holds(reference.pressure()));
      std::vector<char> listed(static_cast<std::size_t>(p.size()), 0);
      for (int c : record.cells) listed[static_cast<std::size_t>(c)] = 1;
      long outside = 0;
      for (Eigen::Index c = 0; c < p.size(); ++c)
        outside += !listed[static_cast<std::size_t>(c)] && !same_bits(p[c], 0.0);
      CHECK(outside == 0);
    }
    CHECK(differing(restricted.liquid_phi(), reference.liquid_phi()) == 0);
    CHECK(differing(restricted.weights().fluid_face, reference.weights().fluid_face) == 0);
    CHECK(differing(restricted.weights().liquid_face, reference.weights().liquid_face) == 0);
    if (!restricted.rigid_world()) continue;
    const auto& ba = restricted.rigid_world()->bodies();
    const auto& bb = reference.rigid_world()->bodies();
    REQUIRE(ba.size() == bb.size());
    for (std::size_t i = 0; i < ba.size(); ++i) {
      const Vec<Dim> xa = ba[i].position, xb = bb[i].position;
      for (int d = 0; d < Dim; ++d) CHECK(same_bits(xa[d], xb[d]));
    }
  }
  CHECK(reference.constrained_faces_left_out() == 0);
  return restricted.constrained_faces_left_out();
}

/// After every frame of a built-in scene: every face off the walls with W_F^u = 0 lies in
/// Simulation::solid_face_box (the faces apply_wall_and_solid_velocities visits with the
/// restricted passes); returns the faces left outside the boxes in the last frame (the boxes'
/// saving: > 0 where a solid fills a part of the box only), and in `covered` the faces with
/// W_F^u = 0 off the walls summed over the frames (> 0: the check had faces to check).
template <int Dim>
long check_solid_face_box(const std::string& name, const std::string& cells, int frames,
                          long& covered, std::vector<std::string> overrides = {}) {
  INFO(name);
  covered = 0;
  overrides.push_back("domain.cells=" + cells);
  overrides.push_back("render.enabled=false");
  const SceneFile scene = load_scene(name, overrides);
  Simulation<Dim> sim(scene);
  const MacGrid<Dim>& grid = sim.grid();
  long left_out = 0;
  for (int f = 0; f <= frames; ++f) {
    if (f > 0) sim.advance_frame();
    const VectorX& fluid = sim.weights().fluid_face;
    REQUIRE(fluid.size() == grid.num_faces());
    long zero_outside = 0, zero_inside = 0;
    left_out = 0;
    for (int axis = 0; axis < Dim; ++axis) {
      const auto [lo, hi] = sim.solid_face_box(axis);
      const VecI<Dim> dims = grid.face_dims(axis);
      for (int k = 0; k < dims.prod(); ++k) {
        const VecI<Dim> c = lattice_coord<Dim>(k, dims);
        const int face = grid.face_index(axis, c);
        const bool inside = (c.array() >= lo.array()).all() && (c.array() <= hi.array()).all();
        left_out += !inside;
        const bool wall =
            grid.is_boundary_face(axis, c) &&
            sim.boundary()[2 * axis + (c[axis] == 0 ? 0 : 1)] == BoundaryType::wall;
        if (fluid[face] != 0.0 || wall) continue;
        zero_outside += !inside;
        zero_inside += inside;
      }
    }
    INFO("frame " << f);
    CHECK(zero_outside == 0);
    covered += zero_inside;
  }
  return left_out;
}

}  // namespace

TEST_CASE("W_F^u = 0 off the walls only in the solids' face box (band17)", "[unit]") {
  // static solids (the bowl of "default"), moving bodies on walled and open sides, a kinematic
  // board, shells in a basin (the union kept per body), a periodic axis, and Fig. 2's bowl
  long covered = 0;
  CHECK(check_solid_face_box<2>("default", "[48,32]", 3, covered) > 0);
  CHECK(covered > 0);
  CHECK(check_solid_face_box<2>("bunny-onto-floating-bowl-2d", "[40,40]", 4, covered) > 0);
  CHECK(covered > 0);
  check_solid_face_box<2>("boat-on-waves-2d", "[48,24]", 3, covered);
  CHECK(covered > 0);
  check_solid_face_box<2>("hollow-spheres-inviscid-2d", "[40,40]", 4, covered);
  CHECK(covered > 0);
  // periodic in x: every x coordinate (the control volumes' reads wrap), boxed in y
  CHECK(check_solid_face_box<2>("bunny-onto-floating-bowl-2d", "[40,40]", 3, covered,
                                {"domain.boundary.x-=periodic", "domain.boundary.x+=periodic"}) >
        0);
  CHECK(covered > 0);
  // (at 32^3 the bowl's wall covers whole faces; at 20^3 it covered none)
  CHECK(check_solid_face_box<3>("liquid-bunny-into-bowl-3d", "[32,32,32]", 1, covered) > 0);
  CHECK(covered > 0);
}

TEST_CASE("restricted passes with moving bodies only: the dense passes' bits (band17)",
          "[unit]") {
  // apply_wall_and_solid_velocities in the bodies' face box: the same bits as over every face
  check_scene<2>("bunny-onto-floating-bowl-2d", "[40,40]", 6, false);
  check_scene<3>("liquid-bunny-into-bowl-3d", "[20,20,20]", 2, false);
}

namespace {

/// Two simulations of a built-in scene, restricted passes on and off (with them off
/// apply_wall_and_solid_velocities asks every wall face without mass whether it is an air wall,
/// item 18; with them on only those within reach of the trusted boxes, setup19): after every
/// frame the same air walls of the last step and the same face velocities. Returns the air walls
/// summed over the frames (> 0: there were some to find) in `found` and the wall faces the
/// restricted run did not ask about (the reach's saving) summed over the frames.
template <int Dim>
long check_air_walls(const std::string& name, const std::string& cells, int frames, long& found) {
  INFO(name);
  const SceneFile scene = load_scene(name, {"domain.cells=" + cells, "render.enabled=false"});
  StageSwitches dense;
  dense.restricted_passes = false;
  Simulation<Dim> restricted(scene), reference(scene, dense);
  long saved = 0;
  found = 0;
  for (int f = 0; f < frames; ++f) {
    restricted.advance_frame();
    reference.advance_frame();
    INFO("frame " << f + 1);
    CHECK(restricted.air_walls() == reference.air_walls());
    CHECK(differing(restricted.velocity(), reference.velocity()) == 0);
    CHECK(restricted.wall_faces_asked() <= reference.wall_faces_asked());
    found += static_cast<long>(reference.air_walls().size());
    saved += reference.wall_faces_asked() - restricted.wall_faces_asked();
  }
  return saved;
}

}  // namespace

TEST_CASE("air walls asked about within reach of the trusted boxes: the dense rule's walls "
          "(setup19)",
          "[unit]") {
  // the dam breaks along the floor (wall faces beside air ahead of the front), the far walls
  // and the ceiling out of reach
  long found = 0;
  CHECK(check_air_walls<2>("dam-break-2d", "[64,32]", 6, found) > 0);
  CHECK(found > 0);
  CHECK(check_air_walls<3>("dam-break-3d", "[24,12,12]", 4, found) > 0);
  CHECK(found > 0);
  // a dynamic bowl on the floor (Fig. 2): the walls far from the liquid
  check_air_walls<3>("liquid-bunny-into-bowl-3d", "[20,20,20]", 3, found);
}

TEST_CASE("negative points searched in a box: the dense box and classes", "[unit]") {
  check_negative_point_search<2>(16);
  check_negative_point_search<3>(10);
}

TEST_CASE("liquid level set band: same values, background outside", "[unit]") {
  check_liquid_band<2>(32);
  check_liquid_band<3>(20);
}

TEST_CASE("liquid level set stored over its band: the dense bits through the view (band19)",
          "[unit]") {
  check_boxed_liquid_phi<2>(32);
  check_boxed_liquid_phi<3>(20);
}

TEST_CASE("the pressure kept over the coupled solves' cells: the dense passes' bits at 1 and 3 "
          "threads (band23)",
          "[unit]") {
  const int threads = omp_get_max_threads();
  for (int t : {1, 3}) {
    INFO(t << " threads");
    omp_set_num_threads(t);
    check_scene<2>("bunny-onto-floating-bowl-2d", "[40,40]", 4, false);
  }
  omp_set_num_threads(threads);
}

TEST_CASE("restricted passes give the dense passes' bits (Fig. 17)", "[unit]") {
  check_scene<2>("hollow-spheres-inviscid-2d", "[40,40]", 10);
  check_scene<3>("hollow-spheres-inviscid-3d", "[20,20,20]", 1);
  // a grid fine enough for faces deep in the basin's wall: constrain_velocity_in_solids leaves
  // them out while the shells are away (the shells pass near the wall in these frames)
  CHECK(check_scene<2>("hollow-spheres-inviscid-2d", "[96,96]", 12) > 0);
}

TEST_CASE("viscous scenes: the stress's clamped faces the dense passes' bits (surf24)", "[unit]") {
  // clamp_stressed_face_weights raises W_L^u on the dry faces the surface stress DOFs read and
  // grows the W_L^u boxes over them (restricted) or visits every stress DOF (dense): the same
  // weights, solves and particles. Liquid alone, coupled with bodies, Herschel-Bulkley, 3D
  check_scene<2>("liquid-drop-newtonian-2d", "[32,32]", 4, false);
  check_scene<2>("hollow-spheres-viscous-2d", "[40,40]", 3);
  check_scene<2>("liquid-drop-bingham-2d", "[32,32]", 3, false);
  check_scene<3>("liquid-drop-newtonian-3d", "[16,16,16]", 2, false);
}

TEST_CASE("viscous scenes with bodies: the cut faces' raised stress DOFs the dense passes' bits",
          "[unit]") {
  // raise_cut_face_stress (departures item 24) ties cut faces' liquid to the bodies in every
  // solve; its DOFs lie in the bodies, beside the liquid: the restricted and the dense passes
  // select and solve them alike. A body in a viscous block (Bingham: the model copies W_F^s after
  // the raise), a ball against a wall
  check_scene<2>("bunny-into-block-bingham-2d", "[32,32]", 3, false);
  check_scene<2>("viscous-sphere-bunny-wall-2d", "[32,32]", 3, false);
}

TEST_CASE("static solids keep their normals: the dense passes' bits", "[unit]") {
  // no body moves: every face in the bowl keeps its normal from the first step
  CHECK(check_scene<2>("default", "[48,32]", 8) > 0);
  CHECK(check_scene<2>("pour-into-bowl-2d", "[40,40]", 25) > 0);
}

namespace {

/// Runs a built-in scene with Simulation::check_speed_boxes on: every solve that gets the
/// liquid's band checks, over every face, that its starting velocity is +-0 outside the band's
/// speed boxes (the promise weighted_face_speed relies on, band18). Returns the check's sums.
template <int Dim>
typename Simulation<Dim>::SpeedBoxCheck check_speed_boxes(const std::string& name,
                                                          const std::string& cells, int frames,
                                                          std::vector<std::string> overrides = {}) {
  INFO(name);
  overrides.push_back("domain.cells=" + cells);
  overrides.push_back("render.enabled=false");
  const SceneFile scene = load_scene(name, overrides);
  Simulation<Dim> sim(scene);
  sim.check_speed_boxes(true);
  for (int f = 0; f < frames; ++f) sim.advance_frame();
  const auto check = sim.speed_box_check();
  CHECK(check.nonzero_outside == 0);
  CHECK(check.promised > 0);
  return check;
}

}  // namespace

TEST_CASE("u* = 0 outside the speed boxes at every banded solve (band18)", "[unit]") {
  // coupled (PC-unified) scenes, 2D and 3D, a periodic axis, liquid-only viscous and
  // non-Newtonian sequences (later solves start from an earlier one's velocity), the explicit
  // back end; the boxes leave faces out where the liquid fills a part of the box
  CHECK(check_speed_boxes<2>("bunny-onto-floating-bowl-2d", "[40,40]", 4).left_out > 0);
  CHECK(check_speed_boxes<2>("bunny-onto-floating-bowl-2d", "[40,40]", 3,
                             {"domain.boundary.x-=periodic", "domain.boundary.x+=periodic"})
            .left_out > 0);
  CHECK(check_speed_boxes<2>("liquid-bunny-into-bowl-2d", "[48,48]", 3, {"solver.backend=explicit"})
            .left_out > 0);
  CHECK(check_speed_boxes<2>("viscous-pour-2d", "[40,40]", 4).left_out > 0);
  CHECK(check_speed_boxes<2>("liquid-drop-shear-thinning-2d", "[32,32]", 3).left_out > 0);
  CHECK(check_speed_boxes<2>("hollow-spheres-viscous-2d", "[40,40]", 3).left_out > 0);
  CHECK(check_speed_boxes<3>("liquid-bunny-into-bowl-3d", "[24,24,24]", 2).left_out > 0);
}

namespace {

/// weighted_face_speed over a band's speed boxes against the pass over every face, for u zero
/// (+0 or -0) outside the boxes and random W_F^u (some 0) and u inside (with a NaN term).
template <int Dim>
void check_boxed_speed(int n, unsigned seed) {
  const MacGrid<Dim> grid = unit_grid<Dim>(n);
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> r(-3.0, 3.0);
  LiquidBand band;
  band.speed_valid = true;
  for (int a = 0; a < Dim; ++a)
    for (int d = 0; d < Dim; ++d) {
      band.speed_lo[a][d] = 2 + a + d;
      band.speed_hi[a][d] = n - 3 + (d == a ? 1 : 0);
    }
  VectorX fluid(grid.num_faces()), u(grid.num_faces());
  for (int a = 0; a < Dim; ++a) {
    const VecI<Dim> dims = grid.face_dims(a);
    for (int k = 0; k < dims.prod(); ++k) {
      const VecI<Dim> c = lattice_coord<Dim>(k, dims);
      bool inside = true;
      for (int d = 0; d < Dim; ++d)
        inside = inside && c[d] >= band.speed_lo[a][d] && c[d] <= band.speed_hi[a][d];
      const int f = grid.face_index(a, c);
      fluid[f] = k % 7 == 0 ? 0.0 : std::abs(r(rng)) / 3.0;
      u[f] = inside ? r(rng) : (k % 2 ? -0.0 : 0.0);
    }
  }
  const double full = weighted_face_speed(fluid, u);
  CHECK(full > 0.0);
  CHECK(same_bits(weighted_face_speed(grid, fluid, u, &band), full));
  // a NaN term inside: skipped by both
  u[grid.face_index(0, VecI<Dim>::Constant(4))] = std::numeric_limits<double>::quiet_NaN();
  CHECK(same_bits(weighted_face_speed(grid, fluid, u, &band), weighted_face_speed(fluid, u)));
  // empty boxes on every axis: U = +0 when u is zero everywhere
  band.speed_lo[0][0] = n + 5;
  for (int a = 1; a < Dim; ++a) band.speed_hi[a][Dim - 1] = -1;
  VectorX zero = VectorX::Zero(grid.num_faces());
  CHECK(same_bits(weighted_face_speed(grid, fluid, zero, &band), 0.0));
  CHECK(same_bits(weighted_face_speed(fluid, zero), 0.0));
  // without the promise: the pass over every face
  band.speed_valid = false;
  CHECK(same_bits(weighted_face_speed(grid, fluid, u, &band), weighted_face_speed(fluid, u)));
}

}  // namespace

TEST_CASE("weighted_face_speed over the speed boxes: the bits of every face (band18)", "[unit]") {
  check_boxed_speed<2>(24, 3u);
  check_boxed_speed<3>(12, 5u);
  check_boxed_speed<2>(300, 7u);  // above the serial threshold: several threads
}

namespace {

/// A built-in scene run with the energy ledger off (the guard's stream of the extrapolation
/// writes into the face masses' storage, and advect gives the copy's storage back: band20) and
/// on (the masses are read after the solve: every buffer its own): after every frame the same
/// face velocities and particles, and eta per cell (left pending for inviscid liquids) +0 on
/// every cell, as the splat of zeros writes it. Returns the frames compared.
template <int Dim>
int check_storage_handoffs(const std::string& name, const std::string& cells, int frames) {
  INFO(name);
  const SceneFile scene = load_scene(name, {"domain.cells=" + cells, "render.enabled=false"});
  StageSwitches ledger;
  ledger.energy_ledger = true;
  Simulation<Dim> lean(scene), kept(scene, ledger);
  int compared = 0;
  for (int f = 0; f < frames; ++f) {
    lean.advance_frame();
    kept.advance_frame();
    INFO("frame " << f + 1);
    CHECK(differing(lean.velocity(), kept.velocity()) == 0);
    REQUIRE(lean.particles().x.size() == kept.particles().x.size());
    long moved = 0;
    for (std::size_t p = 0; p < lean.particles().x.size(); ++p)
      moved += std::memcmp(lean.particles().x[p].data(), kept.particles().x[p].data(),
                           sizeof(double) * Dim) != 0;
    CHECK(moved == 0);
    const VectorX& eta = lean.cell_eta();
    REQUIRE(eta.size() == lean.grid().num_cells());
    long not_plus_zero = 0;
    for (Eigen::Index c = 0; c < eta.size(); ++c)
      not_plus_zero += !(eta[c] == 0.0 && !std::signbit(eta[c]));
    CHECK(not_plus_zero == 0);
    ++compared;
  }
  return compared;
}

}  // namespace

TEST_CASE("the guard's stream in the face masses' storage, eta per cell pending: the same "
          "bits (band20)",
          "[unit]") {
  // coupled (the masses hold u* after the solve) and liquid-only (they hold the masses) steps
  CHECK(check_storage_handoffs<3>("liquid-bunny-into-bowl-3d", "[20,20,20]", 2) == 2);
  CHECK(check_storage_handoffs<2>("dam-break-2d", "[64,32]", 3) == 3);
}

namespace {

/// (band24) A built-in scene with P's densities +0 beyond the faces their last diagonal filled
/// (the default) against rho_0 there (StageSwitches::densities_zero_outside off, the storage
/// written whole in frame 0): after every frame the same statistics, particles, velocities and
/// pressures; P the same bits on the kept faces, +0 (zero mode) and rho_0 (reference) on the
/// others; no solve found W_L^u beyond the kept faces (densities_before_solve's check: no
/// fallback). With `export_at` > 0 the oracle's export is requested for that step's frame: a reader
/// of every face, so the densities fall back to rho_0 outside the kept faces once and stay so.
/// Returns the faces outside the kept ones summed over the frames (> 0: pages never provided).
template <int Dim>
long check_density_zeros(const std::string& name, const std::string& cells, int frames,
                         int export_frame = 0) {
  INFO(name);
  const SceneFile scene = load_scene(name, {"domain.cells=" + cells, "render.enabled=false"});
  StageSwitches whole;
  whole.densities_zero_outside = false;
  Simulation<Dim> zeros(scene), reference(scene, whole);
  const double rho0 = scene.liquids.front().density;
  long outside_faces = 0;
  for (int f = 0; f < frames; ++f) {
    INFO("frame " << f + 1);
    bool exported = false;
    if (f + 1 == export_frame)
      zeros.request_system_export(1, [&](const SystemExport&) { exported = true; });
    const FrameStats a = zeros.advance_frame();
    const FrameStats b = reference.advance_frame();
    CHECK(a.steps == b.steps);
    CHECK(a.solver.iterations == b.solver.iterations);
    CHECK(same_bits(a.kinetic_energy_liquid, b.kinetic_energy_liquid));
    CHECK(same_bits(a.kinetic_energy_bodies, b.kinetic_energy_bodies));
    CHECK(differing<Dim>(zeros.particles().x, reference.particles().x) == 0);
    CHECK(differing<Dim>(zeros.particles().v, reference.particles().v) == 0);
    CHECK(differing(zeros.velocity(), reference.velocity()) == 0);
    CHECK(differing(zeros.pressure(), reference.pressure()) == 0);
    const auto record = zeros.density_zero_record();
    CHECK(!reference.density_zero_record().zero_outside);
    const bool dropped = export_frame > 0 && f + 1 >= export_frame;
    CHECK(record.zero_outside == !dropped);
    CHECK(record.fallbacks == (dropped ? 1 : 0));
    if (f + 1 == export_frame) CHECK(exported);
    // (P of the frame's last step, with that step's kept faces)
    const VectorX& pa = zeros.weights().face_density;
    const VectorX& pb = reference.weights().face_density;
    REQUIRE(pa.size() == pb.size());
    std::vector<char> kept(static_cast<std::size_t>(pa.size()), 0);
    for (const auto& [begin, end] : record.kept)
      for (long k = begin; k < end; ++k) kept[static_cast<std::size_t>(k)] = 1;
    long differ_kept = 0, not_zero = 0, not_rho0 = 0, outside = 0;
    for (Eigen::Index k = 0; k < pa.size(); ++k) {
      if (kept[static_cast<std::size_t>(k)] || dropped) {
        differ_kept += !same_bits(pa[k], pb[k]);
        continue;
      }
      ++outside;
      not_zero += !same_bits(pa[k], 0.0);
      not_rho0 += !same_bits(pb[k], rho0);
    }
    CHECK(differ_kept == 0);
    CHECK(not_zero == 0);
    CHECK(not_rho0 == 0);
    outside_faces += outside;
  }
  return outside_faces;
}

}  // namespace

TEST_CASE("the faces' densities +0 beyond their layers: the bits of rho_0 there at 1 and 3 "
          "threads (band24)",
          "[unit]") {
  const int threads = omp_get_max_threads();
  for (int t : {1, 3}) {
    INFO(t << " threads");
    omp_set_num_threads(t);
    // coupled 3D (a moving bowl), coupled 2D, liquid-only 2D: inviscid (a column falling into
    // a static bowl) and viscous (a drop thrown onto the ground: the Stokes solves)
    CHECK(check_density_zeros<3>("liquid-bunny-into-bowl-3d", "[20,20,20]", 2) > 0);
    CHECK(check_density_zeros<2>("bunny-onto-floating-bowl-2d", "[40,40]", 4) > 0);
    CHECK(check_density_zeros<2>("pour-into-bowl-2d", "[40,40]", 4) > 0);
    CHECK(check_density_zeros<2>("liquid-drop-newtonian-2d", "[40,40]", 3) > 0);
  }
  omp_set_num_threads(threads);
  // the oracle's export reads P on every face: rho_0 written beyond the layers once, then the
  // whole transfers of kern22 (the same bits before, at and after the fallback)
  check_density_zeros<2>("bunny-onto-floating-bowl-2d", "[40,40]", 3, 2);
}

TEST_CASE("the faces' densities +0 beyond their layers need W_L^u = +0 there: a face with "
          "liquid outside them gets other bits (band24, negative control)",
          "[unit]") {
  const SceneFile scene =
      load_scene("liquid-drop-newtonian-2d", {"domain.cells=[40,40]", "render.enabled=false"});
  StageSwitches whole;
  whole.densities_zero_outside = false;
  Simulation<2> zeros(scene), reference(scene, whole);
  zeros.advance_frame();
  reference.advance_frame();
  const MacGrid<2>& grid = zeros.grid();
  PressureWeights wa = zeros.weights(), wb = reference.weights();
  const auto record = zeros.density_zero_record();
  REQUIRE(record.zero_outside);
  // a face of axis 1 (its cells below and above it) outside the kept faces, open to fluid
  std::vector<char> kept(static_cast<std::size_t>(grid.num_faces()), 0);
  for (const auto& [begin, end] : record.kept)
    for (long k = begin; k < end; ++k) kept[static_cast<std::size_t>(k)] = 1;
  int face = -1;
  VecI<2> coord = VecI<2>::Zero();
  const VecI<2> dims = grid.face_dims(1);
  for (int k = 0; k < dims.prod() && face < 0; ++k) {
    const VecI<2> c = lattice_coord<2>(k, dims);
    const int f = grid.face_index(1, c);
    if (c[1] > 0 && c[1] < dims[1] - 1 && !kept[static_cast<std::size_t>(f)] &&
        wa.fluid_face[f] > 0.0) {
      face = f;
      coord = c;
    }
  }
  REQUIRE(face >= 0);
  VectorX pressure = VectorX::Zero(grid.num_cells());
  const int below = grid.face_cell_minus(1, coord), above = grid.face_cell_plus(1, coord);
  REQUIRE(below >= 0);
  REQUIRE(above >= 0);
  pressure[below] = 1.0;
  for (PressureWeights* w : {&wa, &wb}) {
    w->liquid_cell[below] = 1.0;
    w->liquid_cell[above] = 1.0;
  }
  const double dt = 1e-3;
  // W_L^u = +0 on the face (the premise): the same update
  wa.liquid_face[face] = wb.liquid_face[face] = 0.0;
  VectorX ua = VectorX::Zero(grid.num_faces()), ub = ua;
  apply_pressure_update<2>(grid, wa, dt, pressure, ua);
  apply_pressure_update<2>(grid, wb, dt, pressure, ub);
  CHECK(differing(ua, ub) == 0);
  // liquid on the face: rho_0 updates it, +0 leaves it
  wa.liquid_face[face] = wb.liquid_face[face] = 1.0;
  ua.setZero();
  ub.setZero();
  apply_pressure_update<2>(grid, wa, dt, pressure, ua);
  apply_pressure_update<2>(grid, wb, dt, pressure, ub);
  CHECK(differing(ua, ub) > 0);
}
