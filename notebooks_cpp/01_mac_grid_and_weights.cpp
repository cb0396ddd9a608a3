// Notebook 01: the MAC grid, level sets and the volume-fraction weights (section 3.1.2, 4.4.6).
//
// Run: build/notebooks/notebook_01_mac_grid_and_weights --out DIR   (writes DIR/transcript.md)
#include <cmath>
#include <memory>

#include "notebooks_cpp/notebook.hpp"
#include "reference/grid/mac_grid.hpp"
#include "reference/grid/volume_fractions.hpp"

using namespace monolith;

namespace {

/// Signed distance of a disk/ball of radius r about c, sampled on a lattice.
template <int Dim>
VectorX ball_phi(const SampleLattice<Dim>& lattice, const Vec<Dim>& c, double r) {
  VectorX phi(lattice.size());
  for (int k = 0; k < lattice.size(); ++k) phi[k] = (lattice.position(lattice.coord(k)) - c).norm() - r;
  return phi;
}

/// Relative error of sum(W_L^p) dx^Dim against the exact ball volume on an n^Dim unit grid.
template <int Dim>
double ball_volume_error(int n) {
  const MacGrid<Dim> grid(Vec<Dim>::Zero(), 1.0 / n, VecI<Dim>::Constant(n), {});
  const SampleLattice<Dim> lattice = half_lattice(grid);
  const double r = 0.31;
  const VectorX phi = ball_phi<Dim>(lattice, Vec<Dim>::Constant(0.5), r);
  const double measured = liquid_cell_weights<Dim>(grid, lattice, phi).sum() * grid.cell_volume();
  const double exact = Dim == 2 ? M_PI * r * r : 4.0 / 3.0 * M_PI * r * r * r;
  return std::abs(measured - exact) / exact;
}

}  // namespace

int main(int argc, char** argv) {
  notebook::Notebook nb(argc, argv, "01 The MAC grid, level sets and volume fractions");

  nb.md("## The staggered grid\n"
        "Pressure lives at cell centres, velocity component a on the faces normal to axis a "
        "(`reference/grid/mac_grid.hpp`). Cells are numbered x fastest; the faces of all axes form one "
        "vector, axis 0 first, which is the velocity vector u of the paper, so G is "
        "num_faces x num_cells.");
  const int nx = 6, ny = 4;
  const MacGrid<2> grid(Vec<2>::Zero(), 1.0 / nx, VecI<2>(nx, ny), {false, false});
  {
    std::ostringstream s;
    s << "A " << nx << " x " << ny << " grid with dx = " << grid.dx() << ": " << grid.num_cells()
      << " cells, " << grid.num_faces(0) << " x-faces (" << nx + 1 << " x " << ny << "), "
      << grid.num_faces(1) << " y-faces (" << nx << " x " << ny + 1 << "), " << grid.num_faces()
      << " faces in all; the y-faces start at index " << grid.face_offset(1) << ".";
    nb.md(s.str());
  }
  nb.check_true("cell (2, 3) has index 2 + 6 * 3 = 20", grid.cell_index(VecI<2>(2, 3)) == 20);
  nb.check_true("x-face (6, 0) lies on the x+ wall", grid.is_boundary_face(0, VecI<2>(6, 0)));
  nb.check_true("the x-face (3, 1) separates cells 8 and 9",
                grid.face_cell_minus(0, VecI<2>(3, 1)) == 8 && grid.face_cell_plus(0, VecI<2>(3, 1)) == 9);

  nb.md("## Level sets on the half lattice\n"
        "Every level set is sampled once on the lattice of spacing dx/2. Each control volume "
        "(a cell, or the cube of side dx centred on a face) is the union of 2^Dim lattice cells, and "
        "the fraction of a lattice cell where phi < 0 is exact for the linear interpolant on its "
        "simplices. So one sampling gives W_L^p (cells), W_L^u and W_F^u (faces), and later the "
        "stress weights.");
  const SampleLattice<2> lattice = half_lattice(grid);
  const VectorX liquid = ball_phi<2>(lattice, Vec<2>(0.45, 0.30), 0.22);
  const VectorX W_L_p = liquid_cell_weights<2>(grid, lattice, liquid);
  Eigen::MatrixXd table(ny, nx);
  for (int j = 0; j < ny; ++j)
    for (int i = 0; i < nx; ++i) table(ny - 1 - j, i) = W_L_p[grid.cell_index(VecI<2>(i, j))];
  nb.matrix("W_L^p of a disk of radius 0.22 at (0.45, 0.30), top row = highest y", table, 3);
  nb.check("min W_L^p (fractions are never negative), negated", -W_L_p.minCoeff(), 0.0);
  nb.check("max W_L^p - 1 (fractions never exceed one)", W_L_p.maxCoeff() - 1.0, 0.0);

  nb.md("## W_L^u: the liquid fraction of the face control volumes\n"
        "The same level set gives W_L^u on the faces (the cube of side dx centred on each face). A "
        "face control volume covers only the near halves of its two cells, so a face can hold no "
        "liquid while a neighbouring cell does; eq. (8) needs (W_L^u)^-1 there, and W_L^u is clamped "
        "from below to kMinLiquidFaceFraction = 1e-4 on every face beside a cell with W_L^p > 0 "
        "(a departure, docs/derivations.md). Faces far from the liquid keep W_L^u = 0.");
  const VectorX W_L_u = liquid_face_weights<2>(grid, lattice, liquid, W_L_p);
  {
    Eigen::MatrixXd xf(ny, nx + 1);
    for (int j = 0; j < ny; ++j)
      for (int i = 0; i <= nx; ++i) xf(ny - 1 - j, i) = W_L_u[grid.face_index(0, VecI<2>(i, j))];
    nb.matrix("W_L^u on the x-faces, top row = highest y", xf, 4);
  }
  const VectorX raw_face = face_negative_fractions<2>(grid, lattice, liquid);
  double clamp_violation = 0.0, far_from_liquid = 0.0, unclamped_change = 0.0;
  int clamped = 0;
  for (int f = 0; f < grid.num_faces(); ++f) {
    const auto [axis, coord] = grid.face_coord(f);
    // the cells beside the face (outside the domain: none)
    double beside = 0.0;
    if (coord[axis] > 0) beside = std::max(beside, W_L_p[grid.face_cell_minus(axis, coord)]);
    if (coord[axis] < grid.cells()[axis]) beside = std::max(beside, W_L_p[grid.face_cell_plus(axis, coord)]);
    if (beside > 0.0) {
      clamp_violation = std::max(clamp_violation, kMinLiquidFaceFraction - W_L_u[f]);
      clamped += raw_face[f] < kMinLiquidFaceFraction;
    } else {
      far_from_liquid = std::max(far_from_liquid, std::abs(W_L_u[f]));
    }
    if (raw_face[f] >= kMinLiquidFaceFraction) unclamped_change = std::max(unclamped_change, std::abs(W_L_u[f] - raw_face[f]));
  }
  nb.md("Faces beside a wet cell whose own control volume holds less than the clamp: " + std::to_string(clamped) + ".");
  nb.check("W_L^u >= 1e-4 on every face beside a cell with W_L^p > 0 (worst shortfall)", clamp_violation, 0.0);
  nb.check("W_L^u = 0 on faces with no wet cell beside them, max |W_L^u|", far_from_liquid, 0.0);
  nb.check("elsewhere W_L^u is the face's own liquid fraction, max difference", unclamped_change, 0.0);

  nb.md("## Solids, walls and the shrinkage zeta (section 4.4.6)\n"
        "W_F^u is the non-solid fraction of each face control volume; wall faces get 0. For "
        "volume fractions the solid's signed distance is shifted inward by zeta = 0.01 dx, so that "
        "two touching solids never claim the same sliver of a control volume.");
  VectorX solid(lattice.size());
  // a floor below y = 0.12: the solid's signed distance is positive above it
  for (int k = 0; k < lattice.size(); ++k) solid[k] = lattice.position(lattice.coord(k))[1] - 0.12;
  const std::array<BoundaryType, 4> walls{BoundaryType::wall, BoundaryType::wall, BoundaryType::wall,
                                          BoundaryType::open};
  const VectorX W_F_u = fluid_face_weights<2>(grid, lattice, solid, walls);
  VectorX shrunk = solid;
  shrunk.array() += 0.01 * grid.dx();
  const VectorX W_F_u_shrunk = fluid_face_weights<2>(grid, lattice, shrunk, walls);
  nb.check_true("wall faces have W_F^u = 0", W_F_u[grid.face_index(0, VecI<2>(0, 2))] == 0.0 &&
                                                W_F_u[grid.face_index(1, VecI<2>(2, 0))] == 0.0);
  nb.check_true("the open top faces have W_F^u = 1", W_F_u[grid.face_index(1, VecI<2>(2, ny))] == 1.0);
  nb.check("shrinking the solid by zeta never lowers a fluid fraction", (W_F_u - W_F_u_shrunk).maxCoeff(), 0.0);
  nb.check_true("and raises the fraction of the faces the floor cuts",
                W_F_u_shrunk[grid.face_index(0, VecI<2>(3, 0))] > W_F_u[grid.face_index(0, VecI<2>(3, 0))]);
  const VectorX W_S_u = solid_face_weights(W_F_u);
  {
    Eigen::MatrixXd yf(ny + 1, nx);
    for (int j = 0; j <= ny; ++j)
      for (int i = 0; i < nx; ++i) yf(ny - j, i) = W_S_u[grid.face_index(1, VecI<2>(i, j))];
    nb.matrix("W_S^u = 1 - W_F^u on the y-faces (floor below y = 0.12), top row = highest y", yf, 3);
  }
  nb.check("W_F^u + W_S^u = 1 on every face, max deviation", (W_F_u + W_S_u - VectorX::Ones(grid.num_faces())).cwiseAbs().maxCoeff(), 0.0);
  // dx = 1/6: the x-face (3, 0) (centre y = dx/2) has the control volume y in [0, dx], the y-face
  // (2, 1) (y = dx) the control volume [dx/2, 3dx/2]; the floor below y = 0.12 fills
  // 0.12 / dx = 0.72 and (0.12 - dx/2) / dx = 0.22 of them (exact: the level set is linear)
  nb.check("x-face (3, 0): W_S^u = 0.12 / dx = 0.72", std::abs(W_S_u[grid.face_index(0, VecI<2>(3, 0))] - 0.72), 1e-12);
  nb.check("y-face (2, 1): W_S^u = (0.12 - dx/2) / dx = 0.22", std::abs(W_S_u[grid.face_index(1, VecI<2>(2, 1))] - 0.22), 1e-12);

  nb.md("## Second-order convergence of the fractions\n"
        "The liquid volume sum(W_L^p) dx^Dim of a disk (2D) or ball (3D) against the exact one.");
  for (int dim : {2, 3}) {
    const double e1 = dim == 2 ? ball_volume_error<2>(16) : ball_volume_error<3>(8);
    const double e2 = dim == 2 ? ball_volume_error<2>(32) : ball_volume_error<3>(16);
    const double e3 = dim == 2 ? ball_volume_error<2>(64) : ball_volume_error<3>(32);
    std::ostringstream s;
    s << dim << "D relative volume errors: " << e1 << ", " << e2 << ", " << e3
      << "; observed orders " << std::log2(e1 / e2) << ", " << std::log2(e2 / e3);
    nb.md(s.str());
    nb.check(std::to_string(dim) + "D error at the finest grid", e3, 2e-3);
    nb.check(std::to_string(dim) + "D observed order is at least 1.7 (2 - order)", 2.0 - std::log2(e2 / e3), 0.3);
  }

  // figure: W_L^p of a finer disk with W_F^u of the floor
  const int n = 48;
  const MacGrid<2> fine(Vec<2>::Zero(), 1.0 / n, VecI<2>(n, n), {false, false});
  const SampleLattice<2> fl = half_lattice(fine);
  const VectorX fw = liquid_cell_weights<2>(fine, fl, ball_phi<2>(fl, Vec<2>(0.5, 0.5), 0.3));
  const int scale = 8;
  Image img(n * scale, n * scale, {255, 255, 255});
  for (int y = 0; y < n * scale; ++y)
    for (int x = 0; x < n * scale; ++x)
      img.set(x, n * scale - 1 - y, colormap_viridis(fw[fine.cell_index(VecI<2>(x / scale, y / scale))]));
  nb.figure("weights_disk.ppm", img, "W_L^p of a disk on a 48 x 48 grid (viridis, 0 to 1)");
  return nb.finish();
}
