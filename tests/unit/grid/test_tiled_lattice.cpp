// TiledLattice (reference/grid/tiled_lattice.hpp): values in tiles made on demand agree with a
// dense lattice written the same way, and nothing outside the touched tiles is stored.
#include <catch2/catch.hpp>
#include <algorithm>
#include <map>
#include <random>

#include "reference/grid/tiled_lattice.hpp"

using namespace monolith;

namespace {

template <int Dim>
VecI<Dim> random_coord(std::mt19937& rng, const VecI<Dim>& dims) {
  VecI<Dim> c;
  for (int a = 0; a < Dim; ++a) c[a] = std::uniform_int_distribution<int>(0, dims[a] - 1)(rng);
  return c;
}

template <int Dim>
void check_against_dense(const VecI<Dim>& dims) {
  std::mt19937 rng(7);
  const double background = 3.5;
  TiledLattice<Dim, double, 2> tiled(dims, background);
  std::vector<double> dense(2 * static_cast<std::size_t>(dims.prod()), background);
  // sums at random points (with repeats), the way a splat accumulates
  for (int n = 0; n < 400; ++n) {
    const VecI<Dim> c = random_coord<Dim>(rng, dims);
    const double w = std::uniform_real_distribution<double>(-1.0, 1.0)(rng);
    double* v = tiled.at(c);
    v[0] += w;
    v[1] += 2.0 * w;
    const std::size_t k = 2 * static_cast<std::size_t>(lattice_index<Dim>(c, dims));
    dense[k] += w;
    dense[k + 1] += 2.0 * w;
  }
  // every point reads the dense value (the background where no tile was made)
  for (int k = 0; k < dims.prod(); ++k) {
    const VecI<Dim> c = lattice_coord<Dim>(k, dims);
    REQUIRE(tiled.value(c, 0) == dense[2 * k]);
    REQUIRE(tiled.value(c, 1) == dense[2 * k + 1]);
  }
  VectorX out;
  tiled.to_dense(out, 1);
  REQUIRE(out.size() == dims.prod());
  for (int k = 0; k < dims.prod(); ++k) REQUIRE(out[k] == dense[2 * k + 1]);
  // for_each_point visits each point of the made tiles once, inside the lattice
  std::map<int, int> seen;
  int points = 0;
  tiled.for_each_point([&](const VecI<Dim>& c, const double* v) {
    REQUIRE(((c.array() >= 0).all() && (c.array() < dims.array()).all()));
    const int k = lattice_index<Dim>(c, dims);
    REQUIRE(v[0] == dense[2 * k]);
    ++seen[k];
    ++points;
  });
  for (const auto& [k, count] : seen) REQUIRE(count == 1);
  REQUIRE(points <= tiled.num_tiles() * TiledLattice<Dim, double, 2>::kTilePoints);
  // tile by tile (how a parallel loop over the slots reads them; for_each_point above is made
  // of these calls): points only from made slots, and the made slots are num_tiles()
  int made = 0;
  for (int tile = 0; tile < tiled.num_tile_slots(); ++tile) {
    made += tiled.has_tile(tile) ? 1 : 0;
    tiled.for_each_point_in_tile(tile, [&](const VecI<Dim>&, const double*) { REQUIRE(tiled.has_tile(tile)); });
  }
  REQUIRE(made == tiled.num_tiles());
}

}  // namespace

TEST_CASE("tiled lattice agrees with a dense lattice written the same way", "[grid][tiled]") {
  check_against_dense<2>(VecI<2>(37, 20));    // partial tiles on both axes
  check_against_dense<3>(VecI<3>(17, 9, 24));
  check_against_dense<3>(VecI<3>(1, 1, 1));
}

TEST_CASE("tiled lattice stores only the tiles a band touches", "[grid][tiled]") {
  // a 129^3 half lattice (64^3 cells) with a box of 10 points per axis around its middle
  const VecI<3> dims = VecI<3>::Constant(129);
  TiledLattice<3, double> t(dims, 1.0);
  REQUIRE(t.num_tiles() == 0);
  REQUIRE(t.find(VecI<3>(60, 60, 60)) == nullptr);
  REQUIRE(t.value(VecI<3>(60, 60, 60)) == 1.0);
  t.touch_box(VecI<3>::Constant(60), VecI<3>::Constant(69));
  // points 60..69 lie in tiles 7 (56..63) and 8 (64..71) on each axis
  REQUIRE(t.num_tiles() == 8);
  REQUIRE(t.find(VecI<3>(60, 69, 64)) != nullptr);
  REQUIRE(t.find(VecI<3>(55, 60, 60)) == nullptr);
  REQUIRE(t.value_bytes() == 8u * 512u * sizeof(double));
  // a box partly outside the lattice is clamped; an empty one makes nothing
  t.touch_box(VecI<3>(125, 125, 125), VecI<3>(140, 140, 140));
  // (points 125..128: tiles 15 (120..127) and 16 (128, the last point) on each axis)
  REQUIRE(t.num_tiles() == 16);
  t.touch_box(VecI<3>(5, 5, 5), VecI<3>(4, 50, 50));
  REQUIRE(t.num_tiles() == 16);
  // reset forgets every tile and takes the new background
  t.reset(dims, -2.0);
  REQUIRE(t.num_tiles() == 0);
  REQUIRE(t.value(VecI<3>(60, 60, 60)) == -2.0);
  REQUIRE_THROWS_AS(t.reset(VecI<3>(0, 4, 4), 0.0), std::invalid_argument);
}

TEST_CASE("TiledLattice: tiles flagged on several threads (mark_box, make_tiles) are those of "
          "touch_box",
          "[unit]") {
  std::mt19937 rng(5);
  const VecI<3> dims(37, 20, 29);
  TiledLattice<3, double, 2> serial(dims, -1.0), flagged(dims, -1.0);
  std::vector<std::pair<VecI<3>, VecI<3>>> boxes;
  for (int n = 0; n < 60; ++n) {
    const VecI<3> lo = random_coord<3>(rng, dims) - VecI<3>::Constant(3);
    boxes.push_back({lo, lo + VecI<3>(2, 5, 1)});  // some stick out of the lattice (clamped)
  }
  for (const auto& [lo, hi] : boxes) serial.touch_box(lo, hi);
  std::vector<unsigned char> flags = flagged.tile_flags();
#pragma omp parallel for num_threads(2)
  for (int n = 0; n < static_cast<int>(boxes.size()); ++n)
    flagged.mark_box(boxes[n].first, boxes[n].second, flags);
  flagged.make_tiles(flags, 2);
  CHECK(flagged.num_tiles() == serial.num_tiles());
  CHECK(flagged.num_tiles() > 0);
  int differ = 0;
  for (int t = 0; t < serial.num_tile_slots(); ++t) differ += serial.has_tile(t) != flagged.has_tile(t);
  CHECK(differ == 0);
  // made tiles hold the background
  flagged.for_each_point([&](const VecI<3>&, const double* v) { differ += v[0] != -1.0 || v[1] != -1.0; });
  CHECK(differ == 0);
  // flags already made are left alone: a second make_tiles makes nothing
  flagged.make_tiles(flags, 2);
  CHECK(flagged.num_tiles() == serial.num_tiles());
}

TEST_CASE("TiledLattice: tiles made after a lattice is reset or destroyed take the released "
          "memory and hold the new background",
          "[unit]") {
  const VecI<3> dims(24, 16, 16);
  std::vector<const double*> released;
  {
    TiledLattice<3, double, 3> first(dims, -1.0);
    first.touch_box(VecI<3>::Zero(), dims - VecI<3>::Ones());  // every tile
    first.for_each_point([&](const VecI<3>&, const double* v) {
      const_cast<double*>(v)[0] = 7.0;  // values the next lattice must not see
    });
    for (int t = 0; t < first.num_tile_slots(); ++t) released.push_back(first.find(first.tile_origin(t)));
    first.reset(dims, -1.0);
    CHECK(first.num_tiles() == 0);
  }
  // (the pool holds them now; another lattice's tiles, made serially and in parallel, reuse them)
  TiledLattice<3, double, 3> serial(dims, 2.5), flagged(dims, 4.0);
  serial.touch_box(VecI<3>::Zero(), VecI<3>(7, 7, 7));
  std::vector<unsigned char> flags = flagged.tile_flags();
  flagged.mark_box(VecI<3>(8, 0, 0), dims - VecI<3>::Ones(), flags);
  flagged.make_tiles(flags, 2);
  int reused = 0, differ = 0;
  for (const TiledLattice<3, double, 3>* t : {&serial, &flagged})
    for (int tile = 0; tile < t->num_tile_slots(); ++tile)
      if (t->has_tile(tile))
        reused += std::count(released.begin(), released.end(), t->find(t->tile_origin(tile))) > 0;
  CHECK(reused == serial.num_tiles() + flagged.num_tiles());
  serial.for_each_point([&](const VecI<3>&, const double* v) { differ += v[0] != 2.5 || v[2] != 2.5; });
  flagged.for_each_point([&](const VecI<3>&, const double* v) { differ += v[0] != 4.0 || v[2] != 4.0; });
  CHECK(differ == 0);
  CHECK(serial.num_tiles() == 1);
  CHECK(flagged.num_tiles() == 8);  // tiles 1..2 along x of 3 x 2 x 2
}
