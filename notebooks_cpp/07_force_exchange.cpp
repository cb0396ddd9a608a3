// Notebook 07: consistent force exchange (section 4.4.1): the aggregation matrix Q, the body
// Jacobians J_p = -Q W_S^u G and J_s = -Q W_S^u D^T M assembled over the body surface, and the
// Fig. 8 identity b1 = b2 = 0 for liquid and body in one uniform motion.
//
// Run: build/notebooks/notebook_07_force_exchange --out DIR
#include <Eigen/Dense>
#include <cmath>

#include "notebooks_cpp/notebook.hpp"
#include "reference/coupling/coupling.hpp"
#include "reference/fluid/deformation_rate.hpp"
#include "reference/fluid/gradient.hpp"
#include "reference/fluid/viscosity.hpp"
#include "reference/grid/volume_fractions.hpp"
#include "reference/viz/image.hpp"

using namespace monolith;

namespace {

ShapePtr<2> box_shape(const Vec<2>& c, const Vec<2>& half) {
  ShapeSpec spec;
  spec.type = ShapeType::box;
  spec.center = {c[0], c[1]};
  spec.half_size = {half[0], half[1]};
  return make_shape<2>(spec, "notebook.box");
}

ShapePtr<2> disk_shape(const Vec<2>& c, double r) {
  ShapeSpec spec;
  spec.type = ShapeType::sphere;
  spec.center = {c[0], c[1]};
  spec.radius = r;
  return make_shape<2>(spec, "notebook.disk");
}

}  // namespace

int main(int argc, char** argv) {
  notebook::Notebook nb(argc, argv, "07 Consistent force exchange: Q, J_p, J_s");

  nb.md("## One box on a 5 x 4 grid (dx = 1)\n"
        "The box [1.4, 3.4] x [1.2, 2.6] (centre of mass at its centre) partly covers cells. "
        "W_{S,i}^u is the fraction of each face control volume (the dx-cube centred on the face) "
        "inside the box's SDF shrunk by zeta = 0.01 dx (section 4.4.6). Faces are numbered x-faces "
        "first (6 x 4), then y-faces (5 x 5).");
  const MacGrid<2> grid(Vec<2>::Zero(), 1.0, VecI<2>(5, 4), {false, false});
  const StressGrid<2> stress(grid);
  std::array<BoundaryType, 4> open;
  open.fill(BoundaryType::open);
  const std::vector<CouplingBody<2>> bodies = {
      CouplingBody<2>{box_shape(Vec<2>(2.4, 1.9), Vec<2>(1.0, 0.7)), Vec<2>(2.4, 1.9), true}};
  const SolidWeights<2> w = solid_weights<2>(grid, bodies, {}, open, 0.01 * grid.dx());
  nb.matrix("W_S^u per face (one row)", Eigen::MatrixXd(w.solid_face.transpose()), 3);
  nb.check("W_F^u + W_S^u = 1 on every face (open boundary), max deviation",
           (w.fluid_face + w.solid_face - VectorX::Ones(grid.num_faces())).cwiseAbs().maxCoeff(), 1e-15);

  nb.md("## Q: face force densities to body force and torque\n"
        "Column f (normal to axis a, centre x_f) is dx^2 s(f) [e_a ; (x_f - c) x e_a] with the "
        "body's share s = W_{S,i}^u / W_S^u (1 here: one body). Rows: f_x, f_y, torque.");
  const SparseMatrix Q = aggregation_matrix<2>(grid, bodies, w, BodyGroup::two_way);
  nb.matrix("Q (3 x 49)", Eigen::MatrixXd(Q), 2);
  {
    // every column by the formula: s = 1 wherever the box covers part of the face control volume
    const Eigen::MatrixXd Qd(Q);
    const Vec<2> c(2.4, 1.9);
    double worst = 0.0;
    for (int f = 0; f < grid.num_faces(); ++f) {
      const auto [axis, coord] = grid.face_coord(f);
      Eigen::Vector3d expected = Eigen::Vector3d::Zero();
      if (w.body_face[0][f] > 0.0) {
        const Vec<2> r = grid.face_center(axis, coord) - c;
        expected[axis] = 1.0;                                // e_a, times dx^2 = 1
        expected[2] = axis == 0 ? -r[1] : r[0];              // (x_f - c) x e_a in 2D
      }
      worst = std::max(worst, (Qd.col(f) - expected).cwiseAbs().maxCoeff());
    }
    nb.check("every column of Q is dx^2 [e_a ; (x_f - c) x e_a] on the body's faces, 0 elsewhere: max deviation", worst, 1e-15);
  }

  nb.md("## J_p and J_s assembled over the surface\n"
        "BodyCouplingOperator visits only cells (stress DOFs) whose faces carry different body "
        "weights; inside the body the contributions of opposite faces cancel exactly.");
  const BodyCouplingOperator<2> op(grid, bodies, w, BodyGroup::two_way);
  const Eigen::MatrixXd Jp(op.pressure_jacobian()), Js(op.stress_jacobian());
  nb.matrix("J_p (3 x 20 cells)", Jp, 3);
  nb.matrix("J_s (3 x 70 stress DOFs: xx, yy at cells, xy at nodes)", Js, 3);

  const Eigen::MatrixXd G(gradient_matrix<2>(grid));
  const Eigen::MatrixXd D(deformation_rate_matrix<2>(stress));
  const VectorX M = stress_multiplicity<2>(stress);
  const Eigen::MatrixXd QW = Eigen::MatrixXd(Q) * w.solid_face.asDiagonal();
  nb.check("max |J_p + Q W_S^u G|", (Jp + QW * G).cwiseAbs().maxCoeff(), 1e-12);
  nb.check("max |J_s + Q W_S^u D^T M|", (Js + QW * D.transpose() * M.asDiagonal()).cwiseAbs().maxCoeff(), 1e-12);
  nb.check("matrix-free J_p^T v equals the matrix",
           (op.apply_pressure_transpose(VectorX::Ones(3)) - Jp.transpose() * VectorX::Ones(3)).cwiseAbs().maxCoeff(), 1e-13);
  {
    std::srand(11);
    const VectorX p = VectorX::Random(grid.num_cells()), tau = VectorX::Random(stress.num_dofs());
    const VectorX v = VectorX::Random(3);
    nb.check("matrix-free J_p p equals the matrix", (op.apply_pressure(p) - Jp * p).cwiseAbs().maxCoeff(), 1e-13);
    nb.check("matrix-free J_s tau equals the matrix", (op.apply_stress(tau) - Js * tau).cwiseAbs().maxCoeff(), 1e-13);
    nb.check("matrix-free J_s^T v equals the matrix",
             (op.apply_stress_transpose(v) - Js.transpose() * v).cwiseAbs().maxCoeff(), 1e-13);
    // J_p has non-zero columns on the body's surface cells only
    std::vector<char> surface(grid.num_cells(), 0);
    for (int cell : op.surface_cells()[0]) surface[cell] = 1;
    double off_surface = 0.0;
    for (int cell = 0; cell < grid.num_cells(); ++cell)
      if (!surface[cell]) off_surface = std::max(off_surface, Jp.col(cell).cwiseAbs().maxCoeff());
    nb.md("J_p has " + std::to_string(op.surface_cells()[0].size()) + " non-zero columns (the surface cells) of " +
          std::to_string(grid.num_cells()) + ".");
    nb.check("columns of J_p off the surface cells, max |entry|", off_surface, 0.0);
  }

  nb.md("## Fig. 8: uniform motion feels no force\n"
        "Liquid fills the grid (W_L^p = 1; W_L^s = 1 on the interior stress DOFs, 0 on the "
        "boundary nodes where D is one-sided), u* = (0.8, -1.5) on every face and the body moves "
        "with v* = (0.8, -1.5), omega = 0. Then b2 = W_L^p G^T W_F^u u* - W_L^p alpha J_p^T v* and "
        "b1 = W_L^s M D W_F^u u* - W_L^s alpha J_s^T v* vanish: W_F^u + W_S^u = 1 and G^T, D "
        "annihilate a constant field.");
  const Vec<2> v0(0.8, -1.5);
  VectorX u_star(grid.num_faces());
  for (int f = 0; f < grid.num_faces(); ++f) u_star[f] = v0[grid.face_coord(f).first];
  const VectorX liquid_cell = VectorX::Ones(grid.num_cells());
  VectorX liquid_stress(stress.num_dofs());
  for (int k = 0; k < stress.num_dofs(); ++k) {
    const auto [comp, c] = stress.coord(k);
    liquid_stress[k] = stress.is_boundary(comp, c) ? 0.0 : 1.0;
  }
  VectorX b2 = liquid_cell.cwiseProduct(G.transpose() * w.fluid_face.cwiseProduct(u_star));
  VectorX b1 = liquid_stress.cwiseProduct(M.cwiseProduct(D * w.fluid_face.cwiseProduct(u_star)));
  const double b2_liquid_only = b2.cwiseAbs().maxCoeff();
  VectorX v_star(3);
  v_star << v0[0], v0[1], 0.0;
  subtract_body_pressure_rhs<2>(op, grid, liquid_cell, v_star, b2);
  subtract_body_stress_rhs<2>(op, grid, liquid_stress, v_star, b1);
  nb.md("Without the body term, max |b2| = " + std::to_string(b2_liquid_only) +
        " (the liquid alone sees the body as a wall).");
  nb.check("max |b2| with the body moving along", b2.cwiseAbs().maxCoeff(), 1e-13);
  nb.check("max |b1| with the body moving along", b1.cwiseAbs().maxCoeff(), 1e-13);

  nb.md("## Figure: the surface faces\n"
        "A disk and a box on a 24 x 16 grid. Grey: inside a body. Each face is a dot: dark blue "
        "W_{S,i}^u = 1 (interior), red 0 < W_{S,i}^u < 1 (the surface faces), none outside. "
        "Yellow cells: the surface cells, the only columns of J_p.");
  const int px = 24;
  const MacGrid<2> big(Vec<2>::Zero(), 1.0 / 16, VecI<2>(24, 16), {false, false});
  const std::vector<CouplingBody<2>> two = {
      CouplingBody<2>{disk_shape(Vec<2>(0.45, 0.5), 0.27), Vec<2>(0.45, 0.5), true},
      CouplingBody<2>{box_shape(Vec<2>(1.1, 0.43), Vec<2>(0.23, 0.17)), Vec<2>(1.1, 0.43), true}};
  const SolidWeights<2> wb = solid_weights<2>(big, two, {}, open, 0.01 * big.dx());
  const BodyCouplingOperator<2> op_big(big, two, wb, BodyGroup::two_way);
  Image image(24 * px, 16 * px, {255, 255, 255});
  auto to_world = [&](int x, int y) {
    return Vec<2>((x + 0.5) / px * big.dx(), (16 * px - 1 - y + 0.5) / px * big.dx());
  };
  std::vector<char> surface(big.num_cells(), 0);
  for (const auto& cells : op_big.surface_cells())
    for (int c : cells) surface[c] = 1;
  for (int y = 0; y < image.height; ++y)
    for (int x = 0; x < image.width; ++x) {
      const Vec<2> p = to_world(x, y);
      const int cell = big.cell_index(big.cell_containing(p));
      Rgb colour = surface[cell] ? Rgb{255, 240, 170} : Rgb{255, 255, 255};
      for (const auto& b : two)
        if (b.shape->distance(p) < 0) colour = {static_cast<std::uint8_t>(colour[0] * 0.75),
                                                static_cast<std::uint8_t>(colour[1] * 0.75),
                                                static_cast<std::uint8_t>(colour[2] * 0.75)};
      if (x % px == 0 || y % px == 0) colour = {200, 200, 200};
      image.set(x, y, colour);
    }
  int surface_faces = 0;
  for (int f = 0; f < big.num_faces(); ++f) {
    double wf = 0.0;
    for (const VectorX& body : wb.body_face) wf = std::max(wf, body[f]);
    if (wf <= 0.0) continue;
    const auto [axis, coord] = big.face_coord(f);
    const Vec<2> x = big.face_center(axis, coord);
    const int cx = static_cast<int>(x[0] / big.dx() * px), cy = 16 * px - 1 - static_cast<int>(x[1] / big.dx() * px);
    const Rgb colour = wf < 1.0 ? Rgb{220, 30, 30} : Rgb{30, 40, 150};
    surface_faces += wf < 1.0;
    for (int dy = -2; dy <= 2; ++dy)
      for (int dx = -2; dx <= 2; ++dx) {
        const int ix = cx + dx, iy = cy + dy;
        if (ix >= 0 && iy >= 0 && ix < image.width && iy < image.height) image.set(ix, iy, colour);
      }
  }
  nb.figure("07_surface_faces.ppm", image, "surface faces (red), interior faces (blue), surface cells (yellow)");
  nb.check_true("the surface has faces with 0 < W_S,i^u < 1", surface_faces > 0);
  return nb.finish();
}
