// Tests of the APIC transfers on the MAC grid (Jiang et al. 2015): affine exactness, momentum
// conservation, angular momentum of a rigid rotation, face density, determinism, and the
// breadth-first velocity extrapolation.
#include <omp.h>

#include <algorithm>
#include <catch2/catch.hpp>
#include <cmath>
#include <cstring>
#include <limits>
#include <deque>
#include <random>
#include <type_traits>

#include "reference/core/parallel.hpp"
#include "reference/fluid/pressure_projection.hpp"
#include "reference/particles/particles.hpp"

using namespace monolith;

namespace {

template <int Dim>
MacGrid<Dim> make_grid(int n, bool periodic_all = false) {
  std::array<bool, Dim> periodic{};
  periodic.fill(periodic_all);
  return MacGrid<Dim>(Vec<Dim>::Constant(-0.5), 1.0 / n, VecI<Dim>::Constant(n), periodic);
}

/// Random particles uniformly in [lo, hi]^Dim with mass and density.
template <int Dim>
Particles<Dim> random_cloud(int count, double lo, double hi, unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> u(lo, hi), m(0.5, 2.0);
  Particles<Dim> p;
  for (int i = 0; i < count; ++i) {
    Vec<Dim> x;
    for (int a = 0; a < Dim; ++a) x[a] = u(rng);
    p.x.push_back(x);
    p.v.push_back(Vec<Dim>::Zero());
    p.c.push_back(Mat<Dim>::Zero());
    p.mass.push_back(m(rng));
    p.density.push_back(1000.0);
    p.liquid.push_back(0);
  }
  return p;
}

/// 2D angular momentum is the scalar x v_y - y v_x; 3D the vector x cross v.
double angular(const Vec<2>& x, const Vec<2>& v) {
  return x[0] * v[1] - x[1] * v[0];
}
Vec<3> angular(const Vec<3>& x, const Vec<3>& v) {
  return x.cross(v);
}
/// |L| of either kind (a size-1 dynamic vector for the 2D scalar made g++ 12 warn of a
/// vectorised load it could not prove in bounds: -Wmaybe-uninitialized)
double magnitude(double L) {
  return std::abs(L);
}
double magnitude(const Vec<3>& L) {
  return L.norm();
}

template <int Dim>
void check_affine_exactness() {
  const MacGrid<Dim> grid = make_grid<Dim>(16);
  // particles at least 1.5 dx inside the walls, so no stencil reaches the clamped boundary
  Particles<Dim> particles = random_cloud<Dim>(Dim == 2 ? 2000 : 8000, -0.4, 0.4, 5u);
  std::mt19937 rng(9);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  Mat<Dim> A;
  Vec<Dim> b;
  for (int i = 0; i < Dim; ++i) {
    b[i] = u(rng);
    for (int j = 0; j < Dim; ++j) A(i, j) = u(rng);
  }
  for (std::size_t p = 0; p < particles.size(); ++p) {
    particles.v[p] = A * particles.x[p] + b;
    particles.c[p] = A;
  }
  VectorX ug, mass, density;
  particles_to_grid(particles, grid, ug, mass, density);
  Particles<Dim> back = particles;
  for (std::size_t p = 0; p < back.size(); ++p) {
    back.v[p].setZero();
    back.c[p].setZero();
  }
  grid_to_particles(back, grid, ug);
  double ev = 0.0, ec = 0.0;
  for (std::size_t p = 0; p < back.size(); ++p) {
    ev = std::max(ev, (back.v[p] - particles.v[p]).cwiseAbs().maxCoeff());
    ec = std::max(ec, (back.c[p] - A).cwiseAbs().maxCoeff());
  }
  INFO("dim " << Dim << ": max |v error| " << ev << ", max |c error| " << ec);
  CHECK(ev < 1e-12);
  CHECK(ec < 1e-12);
}

template <int Dim>
void check_linear_momentum(bool periodic) {
  const MacGrid<Dim> grid = make_grid<Dim>(12, periodic);
  // walls: keep away from them; periodic: particles everywhere, across the wrap too
  const double lo = periodic ? -0.5 : -0.35, hi = periodic ? 0.5 : 0.35;
  Particles<Dim> particles = random_cloud<Dim>(Dim == 2 ? 3000 : 6000, lo, hi, 17u);
  std::mt19937 rng(21);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  Vec<Dim> total = Vec<Dim>::Zero();
  for (std::size_t p = 0; p < particles.size(); ++p) {
    for (int a = 0; a < Dim; ++a) {
      particles.v[p][a] = u(rng);
      for (int b = 0; b < Dim; ++b) particles.c[p](a, b) = 5.0 * u(rng);
    }
    total += particles.mass[p] * particles.v[p];
  }
  VectorX ug, mass, density;
  particles_to_grid(particles, grid, ug, mass, density);
  for (int a = 0; a < Dim; ++a) {
    const int off = grid.face_offset(a), nf = grid.num_faces(a);
    const double grid_momentum =
        (mass.segment(off, nf).array() * ug.segment(off, nf).array()).sum();
    INFO("dim " << Dim << " periodic " << periodic << " axis " << a << ": particle " << total[a]
                << ", grid " << grid_momentum);
    CHECK(std::abs(grid_momentum - total[a]) <
          1e-12 * std::max(1.0, std::abs(total[a])) + 1e-12 * particles.size());
  }
  // total mass is conserved too
  double pm = 0.0;
  for (double m : particles.mass) pm += m;
  for (int a = 0; a < Dim; ++a)
    CHECK(std::abs(mass.segment(grid.face_offset(a), grid.num_faces(a)).sum() - pm) < 1e-10 * pm);
}

template <int Dim>
void check_rigid_rotation_angular_momentum() {
  const MacGrid<Dim> grid = make_grid<Dim>(16);
  Particles<Dim> particles = random_cloud<Dim>(Dim == 2 ? 2000 : 6000, -0.35, 0.35, 33u);
  // rigid motion about x0: v = v0 + omega x (x - x0), c = [omega]_x
  std::vector<double> omega =
      Dim == 2 ? std::vector<double>{2.5} : std::vector<double>{0.7, -1.3, 2.1};
  Vec<Dim> x0 = Vec<Dim>::Constant(0.05), v0 = Vec<Dim>::Constant(0.3);
  Mat<Dim> c = Mat<Dim>::Zero();
  if constexpr (Dim == 2) {
    c << 0.0, -omega[0], omega[0], 0.0;
  } else {
    c << 0.0, -omega[2], omega[1], omega[2], 0.0, -omega[0], -omega[1], omega[0], 0.0;
  }
  for (std::size_t p = 0; p < particles.size(); ++p) {
    particles.v[p] = v0 + c * (particles.x[p] - x0);
    particles.c[p] = c;
  }
  auto momentum = [](const Particles<Dim>& q) {
    auto L = angular(q.x[0], q.v[0]);
    L *= 0.0;
    for (std::size_t p = 0; p < q.size(); ++p) L += q.mass[p] * angular(q.x[p], q.v[p]);
    return L;
  };
  const auto before = momentum(particles);
  VectorX ug, mass, density;
  particles_to_grid(particles, grid, ug, mass, density);
  grid_to_particles(particles, grid, ug);
  const auto after = momentum(particles);
  const std::decay_t<decltype(before)> change = after - before;
  const double scale = magnitude(before);
  const double diff = magnitude(change);
  INFO("dim " << Dim << ": |L| " << scale << ", |L_after - L_before| " << diff);
  CHECK(scale > 0.0);
  CHECK(diff < 1e-10 * scale);
}

}  // namespace

TEST_CASE("apic round trip reproduces an affine velocity field exactly", "[unit][property]") {
  check_affine_exactness<2>();
  check_affine_exactness<3>();
}

TEST_CASE("apic particles-to-grid conserves linear momentum and mass", "[unit][property]") {
  for (bool periodic : {false, true}) {
    check_linear_momentum<2>(periodic);
    check_linear_momentum<3>(periodic);
  }
}

TEST_CASE("apic round trip preserves the angular momentum of a rigid rotation",
          "[unit][property]") {
  check_rigid_rotation_angular_momentum<2>();
  check_rigid_rotation_angular_momentum<3>();
}

TEST_CASE("apic face density is the mass-weighted particle density", "[unit]") {
  // two liquids: density 1000 left of x = 0, 800 right of it
  const MacGrid<2> grid = make_grid<2>(10);
  Particles<2> particles = random_cloud<2>(4000, -0.45, 0.45, 2u);
  for (std::size_t p = 0; p < particles.size(); ++p)
    particles.density[p] = particles.x[p][0] < 0.0 ? 1000.0 : 800.0;
  VectorX ug, mass, density;
  particles_to_grid(particles, grid, ug, mass, density);
  int faces_with_mass = 0;
  for (int f = 0; f < grid.num_faces(); ++f) {
    if (mass[f] == 0.0) {
      CHECK(density[f] == 0.0);
      CHECK(ug[f] == 0.0);
      continue;
    }
    ++faces_with_mass;
    REQUIRE(density[f] >= 800.0 - 1e-9);
    REQUIRE(density[f] <= 1000.0 + 1e-9);
    const Vec<2> xf = grid.face_center(grid.face_coord(f).first, grid.face_coord(f).second);
    if (xf[0] < -0.15) REQUIRE(density[f] == Approx(1000.0).epsilon(1e-12));
    if (xf[0] > 0.15) REQUIRE(density[f] == Approx(800.0).epsilon(1e-12));
  }
  CHECK(faces_with_mass > grid.num_faces() / 2);
}

TEST_CASE("apic particles-to-grid gives the same bits for any thread count", "[unit]") {
  // the slab-partitioned scatter sums every face in particle order, whatever the partition:
  // 1, 2, 3 and 5 threads, walled and periodic, must agree to the last bit. On 28^3 cells
  // (68k faces) the zero and division passes and the layer count leave their serial
  // fall-backs (kParallelMinWork) too; the team is exactly the requested size (the core monitor
  // off: on a busy machine it would hand the test one thread)
  const bool monitor = core_monitor();
  set_core_monitor(false);
  for (const auto& [n, periodic] : {std::pair{12, false}, std::pair{12, true}, std::pair{28, false},
                                    std::pair{28, true}}) {
    CAPTURE(n, periodic);
    const MacGrid<3> grid = make_grid<3>(n, periodic);
    REQUIRE((n < 28 || grid.num_faces() > kParallelMinWork));
    // a cloud beyond the domain on one side too (clamped stencils at the walls); on 28^3 in the
    // lower 60% of the box, so the walled grid has face layers no particle reaches (zeroed
    // after the sums, beside the division)
    Particles<3> particles = random_cloud<3>(20000, -0.55, n < 28 ? 0.5 : 0.1, 8u);
    std::mt19937 rng(4);
    std::uniform_real_distribution<double> u(-1.0, 1.0);
    for (std::size_t p = 0; p < particles.size(); ++p) {
      for (int a = 0; a < 3; ++a) particles.v[p][a] = u(rng);
      for (int a = 0; a < 3; ++a)
        for (int b = 0; b < 3; ++b) particles.c[p](a, b) = u(rng);
      particles.density[p] = 900.0 + 200.0 * (u(rng) + 1.0);
    }
    const int saved = omp_get_max_threads();
    omp_set_num_threads(1);
    VectorX u1, m1, d1;
    particles_to_grid(particles, grid, u1, m1, d1);
    CHECK(m1.sum() > 0.0);
    for (int threads : {2, 3, 5}) {
      CAPTURE(threads);
      omp_set_num_threads(threads);
      VectorX ut, mt, dt;
      particles_to_grid(particles, grid, ut, mt, dt);
      REQUIRE((u1.array() == ut.array()).all());
      REQUIRE((m1.array() == mt.array()).all());
      REQUIRE((d1.array() == dt.array()).all());
    }
    omp_set_num_threads(saved);
  }
  set_core_monitor(monitor);
}

namespace {

/// pic_velocity_on_faces (read on the ballistic faces beside a support, issue 16/20) on a list of
/// faces gives, on each listed face, particles_to_grid's u of the same particles with c = 0 bit
/// for bit, for any thread count and any list: every face, the faces with mass, a sparse random
/// subset, and faces no particle reaches (zero there). The cloud reaches past the lower walls
/// (the clamped stencils), and on the periodic grid across the wrap.
template <int Dim>
void check_pic_on_faces(bool periodic) {
  const MacGrid<Dim> grid = make_grid<Dim>(Dim == 2 ? 24 : 10, periodic);
  const int nf = grid.num_faces();
  Particles<Dim> particles = random_cloud<Dim>(Dim == 2 ? 3000 : 8000, -0.55, 0.3, 11u);
  std::mt19937 rng(5);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  for (std::size_t p = 0; p < particles.size(); ++p) {
    for (int a = 0; a < Dim; ++a) particles.v[p][a] = u(rng);
    for (int a = 0; a < Dim; ++a)
      for (int b = 0; b < Dim; ++b) particles.c[p](a, b) = 20.0 * u(rng);
  }
  Particles<Dim> no_affine = particles;
  for (auto& c : no_affine.c) c.setZero();
  const int saved = omp_get_max_threads();
  omp_set_num_threads(1);
  VectorX u_apic, m_apic, d_apic, u_pic, m_pic, d_pic;
  particles_to_grid(particles, grid, u_apic, m_apic, d_apic);
  particles_to_grid(no_affine, grid, u_pic, m_pic, d_pic);
  std::vector<int> every(nf), with_mass, sparse, empty;
  for (int f = 0; f < nf; ++f) {
    every[f] = f;
    if (m_apic[f] > 0.0) with_mass.push_back(f);
    if (m_apic[f] == 0.0) empty.push_back(f);
    if (rng() % 7 == 0) sparse.push_back(f);
  }
  REQUIRE(!empty.empty());
  REQUIRE(sparse.size() > 10);
  for (int threads : {1, 2, 3}) {
    CAPTURE(threads);
    omp_set_num_threads(threads);
    for (const std::vector<int>* list : {&every, &with_mass, &sparse, &empty}) {
      std::vector<double> pic;
      pic_velocity_on_faces(particles, grid, *list, pic);
      REQUIRE(pic.size() == list->size());
      for (std::size_t i = 0; i < list->size(); ++i) {
        const int f = (*list)[i];
        CAPTURE(f);
        REQUIRE(std::memcmp(&pic[i], &u_pic[f], sizeof(double)) == 0);
      }
    }
  }
  omp_set_num_threads(saved);
  // the affine part is not small here: the two velocities differ on most faces with mass
  long differing = 0;
  for (const int f : with_mass) differing += std::abs(u_pic[f] - u_apic[f]) > 1e-3;
  CHECK(differing > static_cast<long>(with_mass.size()) / 2);
}

}  // namespace

TEST_CASE("apic PIC velocity on listed faces equals P2G with c = 0 bit for bit", "[unit]") {
  check_pic_on_faces<2>(false);
  check_pic_on_faces<2>(true);
  check_pic_on_faces<3>(false);
  check_pic_on_faces<3>(true);
}

namespace {

template <int Dim>
void check_extrapolation(bool periodic) {
  const MacGrid<Dim> grid = make_grid<Dim>(Dim == 2 ? 16 : 8, periodic);
  const int nf = grid.num_faces();
  // valid: faces whose centre lies in a ball of radius 0.2; value a constant per axis
  VectorX u = VectorX::Constant(nf, -99.0);
  std::vector<char> valid(nf, 0);
  for (int f = 0; f < nf; ++f) {
    const auto [axis, coord] = grid.face_coord(f);
    if (grid.face_center(axis, coord).norm() < 0.2) {
      valid[f] = 1;
      u[f] = 1.0 + axis;
    }
  }
  // reference breadth-first distance over same-axis neighbours
  std::vector<int> dist(nf, -1);
  std::deque<int> queue;
  for (int f = 0; f < nf; ++f)
    if (valid[f]) {
      dist[f] = 0;
      queue.push_back(f);
    }
  while (!queue.empty()) {
    const int f = queue.front();
    queue.pop_front();
    const auto [axis, coord] = grid.face_coord(f);
    const VecI<Dim> dims = grid.face_dims(axis);
    for (int b = 0; b < Dim; ++b)
      for (int s = -1; s <= 1; s += 2) {
        VecI<Dim> nb = coord;
        nb[b] += s;
        if (periodic) nb[b] = (nb[b] + dims[b]) % dims[b];
        if (nb[b] < 0 || nb[b] >= dims[b]) continue;
        const int g = grid.face_index(axis, nb);
        if (dist[g] < 0) {
          dist[g] = dist[f] + 1;
          queue.push_back(g);
        }
      }
  }
  const int layers = 3;
  extrapolate_velocity(grid, u, valid, layers);
  int newly = 0;
  for (int f = 0; f < nf; ++f) {
    const int axis = grid.face_coord(f).first;
    const bool expect = dist[f] >= 0 && dist[f] <= layers;
    REQUIRE(static_cast<bool>(valid[f]) == expect);
    // a per-axis constant extends as that constant; untouched faces keep their value
    REQUIRE(u[f] == (expect ? 1.0 + axis : -99.0));
    if (dist[f] > 0 && expect) ++newly;
  }
  CHECK(newly > 0);
}

}  // namespace

namespace {

/// The extrapolation as a sweep over every face per layer (the form before the band version):
/// the band version must give the same bits.
template <int Dim>
void extrapolate_by_full_sweeps(const MacGrid<Dim>& grid, VectorX& u, std::vector<char>& valid,
                                int layers) {
  const int nf = grid.num_faces();
  for (int layer = 0; layer < layers; ++layer) {
    const std::vector<char> old = valid;
    int filled = 0;
    for (int f = 0; f < nf; ++f) {
      if (old[f]) continue;
      const auto [axis, coord] = grid.face_coord(f);
      const VecI<Dim> dims = grid.face_dims(axis);
      double sum = 0.0;
      int count = 0;
      for (int b = 0; b < Dim; ++b)
        for (int s = -1; s <= 1; s += 2) {
          VecI<Dim> nb = coord;
          nb[b] += s;
          if (grid.periodic(b))
            nb[b] = (nb[b] + dims[b]) % dims[b];
          else if (nb[b] < 0 || nb[b] >= dims[b])
            continue;
          const int g = grid.face_index(axis, nb);
          if (g == f || !old[g]) continue;
          sum += u[g];
          ++count;
        }
      if (count > 0) {
        u[f] = sum / count;
        valid[f] = 1;
        ++filled;
      }
    }
    if (filled == 0) break;
  }
}

template <int Dim>
void check_band_extrapolation(bool periodic) {
  const MacGrid<Dim> grid = make_grid<Dim>(Dim == 2 ? 20 : 10, periodic);
  const int nf = grid.num_faces();
  std::mt19937 rng(11);
  std::uniform_real_distribution<double> r(-1.0, 1.0);
  VectorX u(nf);
  std::vector<char> valid(nf, 0);
  // two blobs of valid faces with random values, one touching the boundary
  for (int f = 0; f < nf; ++f) {
    const auto [axis, coord] = grid.face_coord(f);
    const Vec<Dim> x = grid.face_center(axis, coord);
    u[f] = r(rng);
    const bool blob = x.norm() < 0.15 || (x - Vec<Dim>::Constant(0.4)).norm() < 0.2;
    valid[f] = blob && r(rng) > -0.6;  // with holes inside
  }
  for (int layers : {1, 2, 5, 40}) {
    CAPTURE(layers);
    VectorX ua = u, ub = u;
    std::vector<char> va = valid, vb = valid;
    extrapolate_velocity(grid, ua, va, layers);
    extrapolate_by_full_sweeps(grid, ub, vb, layers);
    REQUIRE(va == vb);
    REQUIRE((ua.array() == ub.array()).all());
    // given boxes holding every valid face (their bounding boxes per axis, grown by 0 or 2, an
    // empty box on an axis without valid faces): the same bits (band17)
    for (int grow : {0, 2}) {
      CAPTURE(grow);
      std::array<VecI<Dim>, Dim> lo, hi;
      for (int a = 0; a < Dim; ++a) {
        lo[a] = grid.face_dims(a);
        hi[a] = -VecI<Dim>::Ones();
      }
      for (int f = 0; f < nf; ++f) {
        if (!valid[f]) continue;
        const auto [axis, coord] = grid.face_coord(f);
        lo[axis] = lo[axis].cwiseMin(coord);
        hi[axis] = hi[axis].cwiseMax(coord);
      }
      for (int a = 0; a < Dim; ++a)
        if ((lo[a].array() <= hi[a].array()).all()) {
          lo[a] = (lo[a] - VecI<Dim>::Constant(grow)).cwiseMax(VecI<Dim>::Zero());
          hi[a] = (hi[a] + VecI<Dim>::Constant(grow)).cwiseMin(grid.face_dims(a) - VecI<Dim>::Ones());
        }
      VectorX uc = u;
      std::vector<char> vc = valid;
      extrapolate_velocity<Dim>(grid, uc, vc, layers, lo, hi);
      REQUIRE(vc == vb);
      REQUIRE((uc.array() == ub.array()).all());
    }
  }
  // valid faces of one axis only: the other axes' boxes empty
  std::vector<char> one(nf, 0);
  std::array<VecI<Dim>, Dim> lo, hi;
  for (int a = 0; a < Dim; ++a) {
    lo[a] = VecI<Dim>::Ones();
    hi[a] = VecI<Dim>::Zero();
  }
  lo[1] = VecI<Dim>::Zero();
  hi[1] = grid.face_dims(1) - VecI<Dim>::Ones();
  for (int f = grid.face_offset(1); f < grid.face_offset(1) + grid.face_dims(1).prod(); ++f)
    one[f] = valid[f];
  VectorX ua = u, ub = u;
  std::vector<char> va = one, vb = one;
  extrapolate_velocity(grid, ua, va, 3);
  extrapolate_velocity<Dim>(grid, ub, vb, 3, lo, hi);
  REQUIRE(va == vb);
  REQUIRE((ua.array() == ub.array()).all());
}

}  // namespace

TEST_CASE("velocity extrapolation in the band equals full sweeps bit for bit", "[unit]") {
  for (bool periodic : {false, true}) {
    CAPTURE(periodic);
    check_band_extrapolation<2>(periodic);
    check_band_extrapolation<3>(periodic);
  }
}

TEST_CASE("velocity extrapolation fills breadth-first layers with neighbour averages", "[unit]") {
  for (bool periodic : {false, true}) {
    check_extrapolation<2>(periodic);
    check_extrapolation<3>(periodic);
  }
  // a linear field along x extends by averages: one layer beyond a valid half plane
  const MacGrid<2> grid = make_grid<2>(8);
  VectorX u = VectorX::Zero(grid.num_faces());
  std::vector<char> valid(grid.num_faces(), 0);
  for (int f = 0; f < grid.num_faces(); ++f) {
    const auto [axis, coord] = grid.face_coord(f);
    if (axis == 1 && coord[0] < 4) {
      valid[f] = 1;
      u[f] = coord[1];
    }
  }
  extrapolate_velocity(grid, u, valid, 1);
  for (int j = 0; j < grid.face_dims(1)[1]; ++j) {
    const int f = grid.face_index(1, VecI<2>(4, j));
    REQUIRE(valid[f]);
    CHECK(u[f] == Approx(j).margin(1e-14));
  }
}

template <int Dim>
void check_unread_flags() {
  // A smooth velocity with a NaN block (faces a caller marks unreadable) on one side of the box:
  // the particles whose stencil or path touches the block are flagged and left where they are,
  // every other particle gets the bits of a transfer and advection without flags; a second pass
  // over the flagged ones after the block got values equals one pass over all of them.
  const MacGrid<Dim> grid = make_grid<Dim>(12);
  const int nf = grid.num_faces();
  VectorX u(nf), filled(nf);
  for (int f = 0; f < nf; ++f) {
    const auto [axis, coord] = grid.face_coord(f);
    const Vec<Dim> x = grid.face_center(axis, coord);
    u[f] = 0.8 + 0.3 * std::sin(3.0 * x[0] + axis) - 0.2 * x[1];
  }
  filled = u;
  for (int f = 0; f < nf; ++f) {
    const auto [axis, coord] = grid.face_coord(f);
    if (grid.face_center(axis, coord)[0] > 0.25) u[f] = std::numeric_limits<double>::quiet_NaN();
  }
  std::array<BoundaryType, 2 * Dim> walls;
  walls.fill(BoundaryType::wall);
  const SolidField<Dim> no_solids;
  const double dt = 0.05;  // 0.04 s at 0.8-1.3 m/s: up to about 0.8 dx
  Particles<Dim> plain = random_cloud<Dim>(400, -0.45, 0.45, 3);
  Particles<Dim> guarded = plain;
  grid_to_particles(plain, grid, filled);
  advect_particles(plain, grid, filled, dt, no_solids, walls);
  std::vector<char> unread;
  const long g2p_flags = grid_to_particles(guarded, grid, u, &unread);
  const Particles<Dim> start = guarded;
  unread.clear();  // a first pass over every particle
  advect_particles(guarded, grid, u, dt, no_solids, walls, &unread);
  REQUIRE(unread.size() == guarded.size());
  long flagged = 0, moved = 0;
  for (std::size_t p = 0; p < guarded.size(); ++p) {
    if (unread[p]) {
      ++flagged;
      CHECK(guarded.x[p] == start.x[p]);
      continue;
    }
    ++moved;
    CHECK(guarded.x[p] == plain.x[p]);
    CHECK(guarded.v[p] == plain.v[p]);
    CHECK(guarded.c[p] == plain.c[p]);
  }
  CHECK(g2p_flags > 0);
  CHECK(flagged > g2p_flags);  // the block also stops particles whose path reaches it
  CHECK(moved > 100);
  // the flagged ones again, through the filled velocity: now as the plain pass
  const std::vector<char> both = unread;
  CHECK(grid_to_particles(guarded, grid, filled, &unread) == 0);
  unread = both;
  advect_particles(guarded, grid, filled, dt, no_solids, walls, &unread);
  CHECK(std::count(unread.begin(), unread.end(), 1) == 0);
  for (std::size_t p = 0; p < guarded.size(); ++p) {
    CHECK(guarded.x[p] == plain.x[p]);
    CHECK(guarded.v[p] == plain.v[p]);
    CHECK(guarded.c[p] == plain.c[p]);
  }
}

TEST_CASE("velocity extrapolation gives the same bits for any thread count above its layers' "
          "serial fall-back", "[unit]") {
  // Every layer runs in one parallel region with one barrier per layer (two22): each thread
  // averages and writes its own candidates, and the next layer's candidates are listed from an
  // even share of all the faces just filled, while faster threads already average the next layer
  // (flags stamped per layer, three stamps in turn). A ball of valid faces on 40^3 cells lists
  // ~10k candidates in its first layer; 1, 2, 3 and 5 threads (the team exactly that: the core
  // monitor off) give the same velocities and flags over 1, 2, 3, 7 and 12 layers (the stamps
  // cycle up to four times), walled and periodic, for the pass over every face and the boxed
  // pass, each team run three times (a race would show as a run that differs).
  const bool monitor = core_monitor();
  set_core_monitor(false);
  const int saved = omp_get_max_threads();
  for (bool periodic : {false, true}) {
    CAPTURE(periodic);
    const MacGrid<3> grid = make_grid<3>(40, periodic);
    const int nf = grid.num_faces();
    VectorX u0 = VectorX::Zero(nf);
    std::vector<char> valid0(nf, 0);
    for (int f = 0; f < nf; ++f) {
      const auto [axis, coord] = grid.face_coord(f);
      if (grid.face_center(axis, coord).norm() > 0.3) continue;
      valid0[f] = 1;
      u0[f] = std::sin(0.37 * f) + 0.1 * (f % 7);
    }
    // the first layer alone: enough candidates for the team (the faces it fills are some of them)
    {
      omp_set_num_threads(1);
      VectorX u = u0;
      std::vector<char> valid = valid0;
      extrapolate_velocity(grid, u, valid, 1);
      long filled = 0;
      for (int f = 0; f < nf; ++f) filled += valid[f] && !valid0[f];
      REQUIRE(filled * 2 * 3 >= kParallelMinWork);
    }
    // boxes holding every valid face, grown by 1 (the boxed pass)
    std::array<VecI<3>, 3> lo, hi;
    for (int a = 0; a < 3; ++a) {
      lo[a] = grid.face_dims(a);
      hi[a] = -VecI<3>::Ones();
    }
    for (int f = 0; f < nf; ++f) {
      if (!valid0[f]) continue;
      const auto [axis, coord] = grid.face_coord(f);
      lo[axis] = lo[axis].cwiseMin(coord);
      hi[axis] = hi[axis].cwiseMax(coord);
    }
    for (int a = 0; a < 3; ++a) {
      lo[a] = (lo[a] - VecI<3>::Ones()).cwiseMax(VecI<3>::Zero());
      hi[a] = (hi[a] + VecI<3>::Ones()).cwiseMin(grid.face_dims(a) - VecI<3>::Ones());
    }
    for (int layers : {1, 2, 3, 7, 12}) {
      CAPTURE(layers);
      omp_set_num_threads(1);
      VectorX u1 = u0;
      std::vector<char> valid1 = valid0;
      extrapolate_velocity(grid, u1, valid1, layers);
      long reached = 0;
      for (int f = 0; f < nf; ++f) {
        reached += valid1[f] && !valid0[f];
        REQUIRE((valid1[f] == 0 || valid1[f] == 1));  // no stamp left
      }
      CHECK(reached > 0);
      for (int threads : {2, 3, 5})
        for (bool boxed : {false, true})
          for (int run = 0; run < 3; ++run) {
            CAPTURE(threads, boxed, run);
            omp_set_num_threads(threads);
            VectorX u = u0;
            std::vector<char> valid = valid0;
            if (boxed)
              extrapolate_velocity<3>(grid, u, valid, layers, lo, hi);
            else
              extrapolate_velocity(grid, u, valid, layers);
            REQUIRE(valid == valid1);
            REQUIRE(std::memcmp(u.data(), u1.data(), sizeof(double) * nf) == 0);
          }
    }
  }
  omp_set_num_threads(saved);
  set_core_monitor(monitor);
}

TEST_CASE("transfers and advection flag the particles that read NaN faces and leave them be",
          "[unit]") {
  check_unread_flags<2>();
  check_unread_flags<3>();
}

namespace {

/// particles_to_grid zeroes only the face layers (along the last axis) its particles reach
/// (issue 20) and writes zeros on the others after the sums: into outputs holding stale values
/// it gives, bit for bit, the outputs of the whole-grid fill (the margin set beyond every
/// layer), on 1 and 2 threads, for a cloud in a slab, clouds past the lower and upper walls
/// (clamped layers), a non-finite position, no particles, and on the periodic grid.
template <int Dim>
void check_zeroed_layers(bool periodic) {
  const MacGrid<Dim> grid = make_grid<Dim>(Dim == 2 ? 24 : 12, periodic);
  const int nf = grid.num_faces();
  std::vector<std::pair<double, double>> slabs = {{-0.12, 0.04}, {-0.62, -0.35}, {0.33, 0.61}};
  int case_index = 0;
  for (int kind = 0; kind < 5; ++kind, ++case_index) {
    CAPTURE(periodic, kind);
    Particles<Dim> particles = random_cloud<Dim>(kind == 4 ? 0 : (Dim == 2 ? 800 : 3000), -0.45, 0.45, 31u + kind);
    std::mt19937 rng(9 + kind);
    std::uniform_real_distribution<double> u(-1.0, 1.0);
    const auto [lo, hi] = slabs[kind < 3 ? kind : 0];
    for (std::size_t p = 0; p < particles.size(); ++p) {
      particles.x[p][Dim - 1] = lo + (hi - lo) * 0.5 * (u(rng) + 1.0);
      for (int a = 0; a < Dim; ++a) particles.v[p][a] = u(rng);
      for (int a = 0; a < Dim; ++a)
        for (int b = 0; b < Dim; ++b) particles.c[p](a, b) = u(rng);
      particles.density[p] = 900.0 + 100.0 * (u(rng) + 1.0);
    }
    if (kind == 3) particles.x[7][Dim - 1] = std::numeric_limits<double>::quiet_NaN();
    const int saved = omp_get_max_threads();
    const int margin = particles_to_grid_zero_margin();
    REQUIRE(margin == 1);
    // the whole-grid fill: every layer zeroed before the sums
    omp_set_num_threads(1);
    particles_to_grid_zero_margin() = 1 << 20;
    VectorX u_ref, m_ref, d_ref;
    particles_to_grid(particles, grid, u_ref, m_ref, d_ref);
    particles_to_grid_zero_margin() = margin;
    auto same = [](const VectorX& a, const VectorX& b) {
      return a.size() == b.size() &&
             std::memcmp(a.data(), b.data(), sizeof(double) * static_cast<std::size_t>(a.size())) == 0;
    };
    for (int threads : {1, 2}) {
      CAPTURE(threads);
      omp_set_num_threads(threads);
      VectorX us = VectorX::Constant(nf, 7.0), ms = VectorX::Constant(nf, -3.0),
              ds = VectorX::Constant(nf, std::numeric_limits<double>::quiet_NaN());
      particles_to_grid(particles, grid, us, ms, ds);
      CHECK(same(us, u_ref));
      CHECK(same(ms, m_ref));
      CHECK(same(ds, d_ref));
    }
    omp_set_num_threads(saved);
    if (kind < 3) {
      // the cloud reaches a part of the layers only
      long with_mass = 0;
      for (int f = 0; f < nf; ++f) with_mass += m_ref[f] > 0.0;
      CHECK(with_mass > 0);
      CHECK(with_mass < nf / 2);
    }
    if (kind == 0 && !periodic) {
      // one layer short of the stencils' reach: the faces of the first layer below the
      // particles lose their sums
      particles_to_grid_zero_margin() = 0;
      VectorX uc, mc, dc;
      particles_to_grid(particles, grid, uc, mc, dc);
      particles_to_grid_zero_margin() = margin;
      CHECK(!same(mc, m_ref));
    }
  }
}

}  // namespace

TEST_CASE("apic particles-to-grid zeroes the layers its particles reach: stale outputs, fresh bits",
          "[unit]") {
  for (bool periodic : {false, true}) {
    check_zeroed_layers<2>(periodic);
    check_zeroed_layers<3>(periodic);
  }
}

namespace {

/// The boxes of Simulation::particle_face_boxes: per component lattice c, the particles' cells
/// grown by 3 along every axis (every sample of a periodic axis or one whose bounds are not
/// finite; empty without particles); the boxes the diagonal of P is searched in after the
/// transfer.
template <int Dim>
void particle_boxes(const Particles<Dim>& particles, const MacGrid<Dim>& grid,
                    std::array<VecI<Dim>, Dim>& lo, std::array<VecI<Dim>, Dim>& hi) {
  Vec<Dim> mn = Vec<Dim>::Constant(std::numeric_limits<double>::infinity()), mx = -mn;
  std::array<bool, Dim> finite;
  finite.fill(true);
  for (const Vec<Dim>& x0 : particles.x) {
    const Vec<Dim> x = grid.wrap_position(x0);
    for (int a = 0; a < Dim; ++a) {
      finite[a] = finite[a] && std::isfinite(x[a]);
      mn[a] = std::min(mn[a], x[a]);
      mx[a] = std::max(mx[a], x[a]);
    }
  }
  const bool none = particles.x.empty();
  for (int c = 0; c < Dim; ++c) {
    const VecI<Dim> fdims = grid.face_dims(c);
    for (int a = 0; a < Dim; ++a) {
      const int cells = grid.cells()[a];
      int clo = 0, chi = fdims[a] - 1;
      if (!none && !grid.periodic(a) && finite[a]) {
        const double slo = std::floor((mn[a] - grid.origin()[a]) / grid.dx());
        const double shi = std::floor((mx[a] - grid.origin()[a]) / grid.dx());
        clo = std::max(static_cast<int>(std::clamp(slo, 0.0, cells - 1.0)) - 3, 0);
        chi = std::min(static_cast<int>(std::clamp(shi, 0.0, cells - 1.0)) + 3, fdims[a] - 1);
      } else if (none) {
        chi = -1;
      }
      lo[c][a] = clo;
      hi[c][a] = chi;
    }
  }
}

/// (kern22) The faces' densities kept across transfers with DensitySpans, each transfer
/// followed by the boxed diagonal of P on the faces it wrote, equal bit for bit the transfer
/// into fresh zeros followed by the diagonal over every face, after every call: a slab of
/// particles moving up the last axis, shrinking, past the upper wall, a non-finite position,
/// no particles, and storage swapped for another vector (spans not known); kept storage on 1
/// and 3 threads against fresh storage on 1. Two negative controls: spans that say nothing was
/// written while the storage holds the last diagonal, and spans taken as known for a storage
/// holding other values, both leave wrong values.
template <int Dim>
void check_kept_density_spans(bool periodic) {
  const MacGrid<Dim> grid = make_grid<Dim>(Dim == 2 ? 48 : 16, periodic);
  const int nf = grid.num_faces();
  const double fallback = 1000.0;
  // (slab along the last axis, particles, a NaN position)
  struct Call {
    double lo, hi;
    int count;
    bool nan, swap;
  };
  const std::vector<Call> calls = {
      {-0.45, -0.2, 600, false, false}, {-0.3, -0.05, 600, false, false},
      {-0.1, 0.2, 600, false, false},   {0.0, 0.1, 300, false, false},
      {0.05, 0.08, 100, false, false},  {0.3, 0.6, 400, false, false},
      {-0.2, 0.0, 500, true, false},    {-0.2, 0.0, 0, false, false},
      {-0.4, -0.3, 300, false, false},  {0.1, 0.3, 400, false, true},
      {0.2, 0.25, 200, false, false}};
  const auto same = [](const VectorX& a, const VectorX& b) {
    const auto bytes = sizeof(double) * static_cast<std::size_t>(a.size());
    return a.size() == b.size() && std::memcmp(a.data(), b.data(), bytes) == 0;
  };
  const int saved = omp_get_max_threads();
  for (int threads : {1, 3}) {
    CAPTURE(periodic, threads);
    VectorX uk, mk, dk;
    DensitySpans spans;
    bool known = false;
    long skipped = 0;  // faces some kept call left unwritten in the densities
    for (std::size_t k = 0; k < calls.size(); ++k) {
      CAPTURE(k);
      const Call& call = calls[k];
      Particles<Dim> particles = random_cloud<Dim>(call.count * (Dim == 2 ? 1 : 4), -0.45, 0.45,
                                                   77u + static_cast<unsigned>(k));
      std::mt19937 rng(5 + k);
      std::uniform_real_distribution<double> r(0.0, 1.0);
      for (std::size_t p = 0; p < particles.size(); ++p) {
        particles.x[p][Dim - 1] = call.lo + (call.hi - call.lo) * r(rng);
        for (int a = 0; a < Dim; ++a) particles.v[p][a] = r(rng) - 0.5;
        particles.density[p] = 900.0 + 200.0 * r(rng);
      }
      if (call.nan) particles.x[3][Dim - 1] = std::numeric_limits<double>::quiet_NaN();
      std::array<VecI<Dim>, Dim> lo, hi;
      particle_boxes<Dim>(particles, grid, lo, hi);
      // the reference: fresh zeros, the diagonal over every face, one thread
      omp_set_num_threads(1);
      VectorX ur, mr, dr;
      particles_to_grid(particles, grid, ur, mr, dr);
      density_diagonal_in_place(grid, dr, fallback);
      // the kept storage
      omp_set_num_threads(threads);
      if (call.swap) {
        VectorX other = VectorX::Constant(nf, -5.0);
        dk.swap(other);
        known = false;  // (another storage: its spans are not known)
      }
      spans.known = known;
      particles_to_grid(particles, grid, uk, mk, dk, &spans);
      density_diagonal_in_place<Dim>(grid, dk, fallback, lo, hi, &spans.written);
      spans.kept = spans.layers;
      known = true;
      long written = 0;
      for (const auto& [b, e] : spans.written) written += e - b;
      skipped += nf - written;
      CHECK(same(uk, ur));
      CHECK(same(mk, mr));
      CHECK(same(dk, dr));
      // outside the layers: the fallback
      std::vector<char> inside(nf, 0);
      for (const auto& [b, e] : spans.layers)
        for (long f = b; f < e; ++f) inside[f] = 1;
      long outside_other = 0;
      for (int f = 0; f < nf; ++f) outside_other += !inside[f] && dk[f] != fallback;
      CHECK(outside_other == 0);
    }
    omp_set_num_threads(saved);
    if (!periodic) CHECK(skipped > 0);  // (the spans left faces unwritten)
    // negative controls, from the last call's state (the diagonal of a slab in dk)
    Particles<Dim> moved = random_cloud<Dim>(Dim == 2 ? 400 : 1600, -0.45, 0.45, 901u);
    for (auto& x : moved.x) x[Dim - 1] = -0.4 + 0.1 * (x[Dim - 1] + 0.45);
    std::array<VecI<Dim>, Dim> lo, hi;
    particle_boxes<Dim>(moved, grid, lo, hi);
    VectorX ur, mr, dr;
    particles_to_grid(moved, grid, ur, mr, dr);
    density_diagonal_in_place(grid, dr, fallback);
    if (!periodic) {
      // kept spans forgotten: the last slab's densities stay
      VectorX uc = uk, mc = mk, dc = dk;
      DensitySpans forgot;
      forgot.known = true;
      particles_to_grid(moved, grid, uc, mc, dc, &forgot);
      density_diagonal_in_place<Dim>(grid, dc, fallback, lo, hi, &forgot.written);
      CHECK(same(mc, mr));
      CHECK(!same(dc, dr));
    }
    {
      // spans known for a storage of other values
      VectorX uc, mc, dc = VectorX::Constant(nf, -5.0);
      DensitySpans wrong = spans;
      wrong.known = true;
      particles_to_grid(moved, grid, uc, mc, dc, &wrong);
      density_diagonal_in_place<Dim>(grid, dc, fallback, lo, hi, &wrong.written);
      CHECK(same(mc, mr));
      CHECK(same(dc, dr) == periodic);  // (a periodic last axis writes every layer)
    }
  }
}

}  // namespace

TEST_CASE("apic particles-to-grid: kept densities over moving, shrinking slabs and a swapped "
          "storage equal fresh ones after the diagonal (kern22)",
          "[unit]") {
  for (bool periodic : {false, true}) {
    check_kept_density_spans<2>(periodic);
    check_kept_density_spans<3>(periodic);
  }
}
