#pragma once
/// \file stokes_workspace.hpp
/// Storage of the liquid solve's set-up kept across steps by its owner (issue 20, branch
/// solve17; docs/preconditioners.md section 39), and the liquid's band that the owner states
/// for the step.
///
/// MatrixFreeStokesOperator needs per step a face-sized vector of C_f and a face-sized scratch,
/// a cell-sized scratch and grid -> unknown maps (202 + 202 + 67 + 33.6 MB at Fig. 2's
/// 256x128x256 grid); all but the face scratch are kept (band18: see face_coefficient below).
/// Made fresh per step they are a whole-grid allocation, a zero (or -1) fill
/// and the first touch of their pages in every step. A StokesWorkspace owned by the caller (the
/// simulation) keeps them: an operator built with one borrows its vectors (moved, not copied)
/// and gives them back when it is destroyed, with the list of the entries it left non-zero (the
/// rows it wrote); the next operator resets only those. Sized on first use, grown (made anew)
/// only when the grid's size changes. An explicit object, not a static: a later back end (a
/// distributed one) keeps a workspace of its own, and two solves may run side by side with
/// two workspaces. One operator borrows a workspace at a time: an operator built while another
/// holds it makes its own vectors, as without a workspace (the same values).
///
/// The band (LiquidBand): boxes of cells and of the faces of each axis outside which W_L^p and
/// W_L^u are 0, which the owner knows from where it wrote them (the simulation's WrittenBox of
/// update_liquid_weights). The set-up then visits those boxes instead of the grid:
/// select_pressure_dofs' cells (a DOF needs W_L^p > 0) and the operator's C_f (C_f = 0 where
/// W_L^u = 0). The same DOFs, coefficients and bits as a pass over the grid, provided the
/// promise holds; without a band (valid = false) every pass covers the grid as before.

#include <array>
#include <utility>
#include <vector>

#include "reference/core/common.hpp"
#include "reference/core/huge_pages.hpp"

namespace monolith {

/// Inclusive boxes (lattice coordinates; the first Dim entries are used) outside which the
/// liquid weights W_L^p (cells) and W_L^u (the faces of axis a, coordinates on that axis's face
/// lattice) are 0. An empty box (some lo > hi): no liquid there. valid = false: no promise.
struct LiquidBand {
  bool valid = false;
  std::array<int, 3> cell_lo{}, cell_hi{};
  std::array<std::array<int, 3>, 3> face_lo{}, face_hi{};
  /// (band18) Boxes of the faces of each axis outside which the solve's u* is +0 or -0, and
  /// with it every velocity a solve of the step's sequence starts from (an update changes only
  /// faces with W_L^u > 0, inside face_lo / face_hi, which these boxes contain): the round-off
  /// bound's U = max_f |W_F^u u_f| (weighted_face_speed) is the maximum over these boxes.
  /// speed_valid = false: no promise (the maximum over every face).
  bool speed_valid = false;
  std::array<std::array<int, 3>, 3> speed_lo{}, speed_hi{};
};

/// A double vector kept across steps that is 0 outside the spans [first, second) listed in
/// `dirty` (or anywhere, when the vector is empty).
struct KeptZeros {
  VectorX values;
  std::vector<std::pair<long, long>> dirty;
  /// `out` becomes a vector of n zeros: the kept storage with its dirty spans zeroed when it
  /// has n entries (the spans then forgotten), else a fresh zero vector (the storage dropped).
  /// (huge21) The fresh vector's zeros are given by the kernel (zero_by_release): its pages are
  /// provided only where the borrower writes (the band's rows), not all at the first lend.
  void lend(long n, VectorX& out) {
    if (values.size() == n) {
      for (const auto& [b, e] : dirty) values.segment(b, e - b).setZero();
      out.swap(values);
    } else {
      resize_to_released_zeros(out, n);
    }
    values = VectorX();
    dirty.clear();
  }
};

/// An int vector kept across steps that is -1 except at the entries listed in `dirty`.
struct KeptMinusOnes {
  std::vector<int> values;
  std::vector<int> dirty;
  /// `out` becomes n entries of -1 (as KeptZeros::lend).
  void lend(long n, std::vector<int>& out) {
    if (static_cast<long>(values.size()) == n) {
      for (int e : dirty) values[e] = -1;
      out.swap(values);
    } else {
      out.assign(n, -1);
    }
    std::vector<int>().swap(values);
    dirty.clear();
  }
};

/// (band23) What a cell-sized double vector kept across steps holds outside a list of cells:
/// while `data` and `size` name its storage, it is +0 at every cell not in `cells` (the coupled
/// solve's pressure, MonolithicSystem::pressure_cells_into: the cells of the last solve's
/// pressure DOFs). A writer that honours it zeroes only the listed cells before writing its own
/// instead of the whole vector, so the pages beyond the liquid are never written (Fig. 2's paper
/// grid: 67 MB of pressure, 16k first touches). Every other writer of the storage calls forget().
struct ZerosOutsideCells {
  const double* data = nullptr;
  long size = -1;
  std::vector<int> cells;
  /// `v` is the storage this record describes.
  bool holds(const VectorX& v) const {
    return data != nullptr && v.data() == data && static_cast<long>(v.size()) == size;
  }
  /// `v` is +0 everywhere (nothing written in it yet).
  void nothing_written(const VectorX& v) {
    data = v.data();
    size = static_cast<long>(v.size());
    cells.clear();
  }
  /// No promise about any storage.
  void forget() {
    data = nullptr;
    size = -1;
    cells.clear();
  }
};

/// (band23) An int vector kept across steps that holds index + 1 (0: no index) and is 0 except
/// at the entries listed in `dirty`: a map whose "none" is the kernel's zero, so a fresh
/// storage's pages are provided only where an index is written (MatrixFreeStokesOperator's
/// unknown of each cell: 34 MB at Fig. 2's paper grid, of which the liquid's rows are written).
struct KeptIndexPlusOne {
  Eigen::VectorXi values;
  std::vector<int> dirty;
  /// `out` becomes n zeros: the kept storage with its dirty entries zeroed when it has n
  /// entries, else fresh storage whose zeros come from the kernel (zero_by_release).
  void lend(long n, Eigen::VectorXi& out) {
    if (static_cast<long>(values.size()) == n) {
      for (int e : dirty) values[e] = 0;
      out.swap(values);
    } else {
      resize_to_released_zeros(out, n);
    }
    values = Eigen::VectorXi();
    dirty.clear();
  }
};

/// The kept storage of the liquid solve's set-up (see the file comment), owned by the caller and
/// passed to the solve (solve_stokes' StokesSolveOptions::workspace, CoupledStepInput::workspace,
/// MonolithicSystem). Holds no reference to any grid or operator.
struct StokesWorkspace {
  /// The liquid's band of this step (the owner sets it before each solve; see LiquidBand).
  LiquidBand band;
  /// MatrixFreeStokesOperator's storage while no operator holds it: C_f per face, the
  /// per-DOF and per-cell unknown maps, the stress and cell scratch (0 outside `dirty`). Not the
  /// face scratch (band18): its values are never reused (the operator zeroes the rows it uses),
  /// so kept it saved no pass, and it lay beside the block the liquid level set frees before the
  /// solve (202 MB of the step's peak at Fig. 2's paper grid) instead of reusing it.
  KeptZeros face_coefficient, stress_scratch, cell_scratch;
  KeptMinusOnes unknown_of_dof;
  KeptIndexPlusOne unknown_of_cell;  ///< (band23) unknown + 1 per cell, 0: none
  /// An operator holds the storage above (it gives it back when destroyed).
  bool lent = false;
  /// false: the band only; operators make their own vectors (a measurement switch: the kept
  /// vectors raise the peak, section 39 of docs/preconditioners.md).
  bool keep = true;
  /// Operators built with the kept storage and with storage of their own (a workspace already
  /// lent), for tests and the benchmark notes.
  long reused = 0, refused = 0;
};

}  // namespace monolith
