#pragma once
/// \file coupling.hpp
/// Consistent force exchange between the liquid and rigid bodies (section 4.4.1), the one-way /
/// two-way split of the body terms (section 4.4.4) and the solid weights of moving bodies with
/// the level-set shrinkage of section 4.4.6. docs/coupling.md explains the conventions.
///
/// Units. The paper's J_p, J_s are the ones of eq. (24), where the common factor dx^Dim of the
/// fluid control volumes is dropped and the body mass is scaled by alpha = 1/dx^Dim (section
/// 4.1). Here Q carries the control volume dx^Dim, so J_p p and J_s tau are forces in newtons
/// (2D: N per metre) and torques in N m (2D: N m per metre):
///     J_p(eq. 24) = alpha J_p(here),   J_s(eq. 24) = alpha J_s(here).
/// The right-hand-side functions below apply alpha themselves.
///
/// Body rows. Every group (two-way: dynamic bodies; one-way: fixed and kinematic bodies, section
/// 4.4.4) numbers its bodies in body order, kBodyDofs<Dim> rows each (linear, then angular: 2D
/// [fx, fy, torque_z], 3D [fx, fy, fz, tx, ty, tz]); the two-way numbering is the one of
/// contact_system.hpp (ContactSystem::body_dof).

#include <array>
#include <cmath>
#include <cstdint>
#include <vector>

#include "reference/core/common.hpp"
#include "reference/core/periodic_image.hpp"
#include "reference/geometry/shape.hpp"
#include "reference/grid/boundary.hpp"
#include "reference/grid/boxed_union_phi.hpp"
#include "reference/grid/mac_grid.hpp"
#include "reference/grid/stress_grid.hpp"
#include "reference/grid/volume_fractions.hpp"
#include "reference/rigid/mass_properties.hpp"
#include "reference/rigid/rigid_body.hpp"

namespace monolith {

/// A body as the coupling sees it: its posed signed distance, its centre of mass and whether it
/// is two-way coupled (dynamic) or one-way (fixed, kinematic).
template <int Dim>
struct CouplingBody {
  ShapePtr<Dim> shape;               ///< posed SDF, world frame, negative inside
  Vec<Dim> center = Vec<Dim>::Zero(); ///< centre of mass (torque reference point), world frame
  bool two_way = true;               ///< dynamic body
  /// Periodic domain axes: > 0 the period (RigidBody::set_periodic), 0 elsewhere.
  Vec<Dim> period = Vec<Dim>::Zero();
  /// x - center through the image of x nearest the centre on periodic axes (the lever arm of
  /// J_p, J_s for a face the body covers across a periodic face).
  Vec<Dim> arm(const Vec<Dim>& x) const {
    const Vec<Dim> r = x - center;
    return r - periodic_image_shift<Dim>(r, period);
  }
};

/// The coupling view of rigid bodies at their current pose (RigidBody::posed_shape()).
template <int Dim>
std::vector<CouplingBody<Dim>> coupling_bodies(const std::vector<RigidBody<Dim>>& bodies);

/// Which bodies a J block covers (section 4.4.4): two-way (J_{p,2}, J_{s,2}: dynamic bodies)
/// or one-way (J_{p,1}, J_{s,1}: fixed and kinematic bodies, right-hand side only).
enum class BodyGroup { two_way, one_way };

/// Solid weights with moving bodies (sections 3.1.2, 4.4.6), diagonal matrices stored as their
/// diagonals.
///
/// body_face[i] = W_{S,i}^u: the fraction of every face control volume inside body i's posed SDF
/// shrunk by zeta (phi_i + zeta < 0), computed on the half lattice like every other fraction
/// (volume_fractions.hpp). Overlap rule: W_S^u = min(1, sum_i W_{S,i}^u + W_static^u), W_static^u
/// the fraction of the union of the static (non-body) solids; where the sum exceeds 1 (bodies
/// interpenetrating by more than the shrinkage, or a body inside a static solid) every
/// contribution is scaled by the same factor 1/sum, so that the per-body weights stored here
/// always add up to W_S^u minus the static part. On `wall` boundary faces W_F^u = 0 and
/// W_S^u = 1 and the whole face belongs to the wall: body_face is 0 there (the pressure on a
/// wall face is not a force on any body; the wall pushes bodies through contact).
template <int Dim>
struct SolidWeights {
  std::vector<VectorX> body_face;  ///< W_{S,i}^u per body (after the overlap rule), num_faces
  /// static solids and walls' share of W_S^u, num_faces (empty from a call whose scratch has
  /// `parts` false and no static solid)
  VectorX static_face;
  /// W_S^u = static_face + sum_i body_face[i], num_faces (empty like static_face; the
  /// aggregation matrix reads it)
  VectorX solid_face;
  VectorX fluid_face;              ///< W_F^u = 1 - W_S^u (0 on wall faces), num_faces
  /// W_F^s per StressGrid DOF: stress_fluid_weights of the union of all solids (bodies and
  /// static), shrunk by zeta; equals 1 - (sum of the stress-control-volume fractions) wherever
  /// bodies do not overlap.
  VectorX fluid_stress;
  /// The signed distance of the union of all solids (bodies and static) on half_lattice(grid),
  /// shifted by zeta: solid_phi_on_lattice of them all, except that far (> 2 dx) from a body's
  /// bounds its distance is replaced by the distance to those bounds (same signs).
  VectorX lattice_phi;
};

/// Section 4.4.6 / 3.1.2: the weights above for bodies (shrunk by `shrink_in_metres` = zeta,
/// the paper uses 0.01 dx) and static solids (shrunk alike), with the wall rule of
/// fluid_face_weights and stress_fluid_weights.
template <int Dim>
SolidWeights<Dim> solid_weights(const MacGrid<Dim>& grid,
                                const std::vector<CouplingBody<Dim>>& bodies,
                                const std::vector<ShapePtr<Dim>>& static_solids,
                                const std::array<BoundaryType, 2 * Dim>& boundary,
                                double shrink_in_metres);

/// Working buffers of solid_weights kept by a caller that computes the weights every step.
template <int Dim>
struct SolidWeightsScratch {
  VectorX body_phi;         ///< one body's lattice phi (released at the end of each call)
  LatticeSigns<Dim> signs;  ///< lattice-cell classes of the static solids', then the union's phi
  /// Set by the caller, one entry per body (missing entries count as false): the body never
  /// moves (a fixed body in the body list), so its lattice phi and raw face fractions are
  /// computed once and kept below. Costs one lattice-sized vector per such body.
  std::vector<char> fixed;
  std::vector<VectorX> fixed_phi, fixed_face;  ///< the kept values, per body (empty: not yet)
  /// Set by the caller: false when it reads neither SolidWeights::static_face nor solid_face
  /// (the simulation: the coupled solve reads W_F^u, the bodies' W_{S,i}^u and W_F^s). Without
  /// static solids those two face-sized vectors are then left empty (at the paper's
  /// 256x128x256 grid 200 MB each).
  bool parts = true;
  /// Set by the caller: false when it reads no SolidWeights::fluid_stress (W_F^s), which is then
  /// left empty (the simulation's inviscid coupled steps: at the paper's 256x128x256 grid 400 MB
  /// made and dropped every step). The union's lattice-cell classes (signs) are made either way
  /// unless the union is kept per body.
  bool stress = true;
  /// Set by the caller: the union of the solids may be kept per body in `union_parts` (the
  /// kept phi of the bodies that never move, each moving body's values in its box: no
  /// lattice-sized pass per call) instead of written into SolidWeights::lattice_phi, which is
  /// then left as it was (but for the fallback of W_F^s below). Taken when there is no static
  /// solid, zeta >= 0, every moving body is bounded and, when W_F^s is made (`stress`), at most
  /// one body never moves; else the union is written as before and union_parts is not valid.
  /// The union's lattice-cell classes are then not made either: `signs` holds only the box of
  /// the lattice cells with a negative corner (signs.lo, hi).
  ///
  /// W_F^s with the union kept per body (issue 20, Fig. 18's viscous steps): the fixed body's
  /// W_F^s (its kept phi's stress fractions) everywhere but at the stress DOFs whose control
  /// volume reaches a moving body's box, which read the union there (the dense union's values,
  /// the same fractions). That holds when no moving body's far value (> far outside its box)
  /// can be the union's value at a corner of a lattice cell where the fixed body's phi changes
  /// sign: every such corner's value is at most far (tested once per kept phi,
  /// `fixed_stress_test`). Else the union is written into SolidWeights::lattice_phi from its
  /// parts (the same bits) and W_F^s made from it as without parts. Given the same W_F^s buffer
  /// back (same data pointer and size, boundary and fixed bodies) and nothing written into it,
  /// the next call makes again only the DOFs near a moving body in that call or this one.
  bool union_in_parts = false;
  PartsUnionPhi<Dim> union_parts;  ///< the union per part (valid() when taken)
  /// per body that never moves: the box of its kept phi's negative points (with fixed_phi)
  std::vector<VecI<Dim>> fixed_neg_lo, fixed_neg_hi;
  std::vector<char> fixed_neg_known;  ///< whether fixed_neg_lo, hi hold the kept phi's box
  /// With the union kept per body and `parts` false, the next call makes the face weights again
  /// only at the faces near a moving body (in this call or the next) when it is given the same
  /// output buffers (SolidWeights::body_face, fluid_face: same data pointers and sizes, the same
  /// bodies fixed) and nothing wrote into them in between; the state of that below.
  bool kept = false;
  const double* kept_fluid_face = nullptr;
  std::vector<const double*> kept_body_face;
  std::vector<char> kept_fixed;
  std::vector<std::vector<int>> near;  ///< per moving body: the faces of its fractions
  std::vector<std::uint8_t> face_mark;  ///< face-sized, 0 between calls
  std::vector<int> touched;
  /// W_F^s kept per body (see union_in_parts): the state of the last call's W_F^s
  bool kept_stress = false;
  const double* kept_fluid_stress = nullptr;
  std::array<BoundaryType, 2 * Dim> kept_boundary{};
  std::vector<char> kept_stress_fixed;
  std::vector<std::vector<int>> stress_near;  ///< per moving body: the stress DOFs it made
  /// per body that never moves: the test of its kept phi (0 not yet made, 1 passed, 2 failed)
  std::vector<char> fixed_stress_test;
  VectorX stress_union;  ///< the union's values in a moving body's box (per call)
};

/// The same into `w`, whose vectors (and the scratch buffers) are reused when they have the
/// right sizes: no grid-sized allocation from the second call on. Same values bit for bit.
template <int Dim>
void solid_weights(const MacGrid<Dim>& grid, const std::vector<CouplingBody<Dim>>& bodies,
                   const std::vector<ShapePtr<Dim>>& static_solids,
                   const std::array<BoundaryType, 2 * Dim>& boundary, double shrink_in_metres,
                   SolidWeights<Dim>& w, SolidWeightsScratch<Dim>& scratch);

/// Index of the first row of every body in its group's J blocks, -1 for bodies of the other
/// group; `count` receives the number of rows (kBodyDofs<Dim> x bodies of the group).
template <int Dim>
std::vector<int> body_rows(const std::vector<CouplingBody<Dim>>& bodies, BodyGroup group,
                           int* count);

/// Section 4.4.1: the aggregation matrix Q, num_group_rows x num_faces (explicit, for tests and
/// teaching). Column f (a face normal to axis a, centre x_f) holds, in the row block of body i,
///     dx^Dim s_i(f) [e_a ; (x_f - c_i) x e_a],   s_i(f) = W_{S,i}^u(f) / W_S^u(f)
/// (0 where W_S^u = 0): the force and torque about the centre of mass of a force density
/// (N/m^3) acting on the face control volume dx^Dim, shared among the bodies covering the face
/// in proportion to their volumes. With this share, Q W_S^u has the blocks
/// W_{S,i}^u(f) dx^Dim [e_a ; (x_f - c_i) x e_a], so J_p = -Q W_S^u G counts every solid volume
/// once, and sum_i (Q^T v)_f reproduces a common rigid velocity (Fig. 8). 2D torques are the
/// scalar r_x f_y - r_y f_x.
template <int Dim>
SparseMatrix aggregation_matrix(const MacGrid<Dim>& grid,
                                const std::vector<CouplingBody<Dim>>& bodies,
                                const SolidWeights<Dim>& weights, BodyGroup group);

/// The body-surface operators of section 4.4.1 for one group of bodies, assembled directly over
/// the body surfaces without forming Q:
///   J_p = -Q W_S^u G,        num_group_rows x num_cells,        (eq. (18)/(21)/(24))
///   J_s = -Q W_S^u D^T M,    num_group_rows x num_stress_dofs,  (eq. (19)/(21)/(24))
/// (units of this file: J_p p in N, see the file comment). Sign: the fluid's update is
/// -dt P^-1 (W_L^u)^-1 (G W_L^p p + D^T M W_L^s tau); J_p W_L^p p + J_s W_L^s tau is minus the
/// same face force density aggregated over the bodies' volume, i.e. the force the liquid exerts
/// on the bodies (Archimedes: J_p p_hydrostatic = +rho g V upward). M = diag(multiplicity) as in
/// stokes_system.hpp: the fluid feels D^T M W_L^s tau, so the body does too.
///
/// Column c of J_p involves only the faces of cell c, column k of J_s only the faces of the
/// stencil of D row k. Where those faces all exist and carry the same body weight (inside a body
/// or outside all bodies), the force terms cancel exactly, so only the surface cells and
/// surface stress DOFs are visited and stored. The matrix-free products evaluate the same
/// columns on the fly, so they equal the assembled matrices bit for bit.
///
/// The operator reads the per-body face weights of `weights` (weights.body_face) in place: they
/// must outlive it and not change while it is used (a grid-sized vector per body is not copied;
/// at the paper's 256x128x256 grid each is 200 MB).
template <int Dim>
class BodyCouplingOperator {
 public:
  /// The columns a caller reads (issue 20: the system's unknowns). By default every column:
  /// every cell of J_p and every StressGrid DOF of J_s.
  struct Columns {
    /// The cells whose J_p columns are wanted, increasing (the pressure unknowns' cells,
    /// PressureDofs::cell_of_dof); null: every cell. Cells not listed get no column (their
    /// surface entries are absent; every listed cell's column is the one of the full operator).
    const std::vector<int>* cells = nullptr;
    /// Whether J_s is wanted at all (false: a system without stress unknowns; no stress
    /// surface is searched and J_s has no column).
    bool stress = true;
    /// With `stress`: the StressGrid DOFs whose J_s columns are wanted, increasing (a viscous
    /// system's stress unknowns' DOFs and, in the reduced form, the eliminated component's DOF
    /// of every cell with a diagonal unknown: MonolithicSystem); null: every DOF. DOFs not
    /// listed get no column (every listed DOF's column is the one of the full operator).
    const std::vector<int>* stress_dofs = nullptr;
  };

  BodyCouplingOperator(const MacGrid<Dim>& grid, const std::vector<CouplingBody<Dim>>& bodies,
                       const SolidWeights<Dim>& weights, BodyGroup group);
  /// The same restricted to the columns of `columns`: the surface is searched only among the
  /// listed cells and stress DOFs (time in proportion to the unknowns, not to the bodies' boxes:
  /// Fig. 17's and Fig. 18's basin spans half the lattice) and, without stress, not among the
  /// stress DOFs. The columns kept are those of the full operator bit for bit.
  BodyCouplingOperator(const MacGrid<Dim>& grid, const std::vector<CouplingBody<Dim>>& bodies,
                       const SolidWeights<Dim>& weights, BodyGroup group, const Columns& columns);
  /// A temporary's weights would not outlive the operator.
  BodyCouplingOperator(const MacGrid<Dim>& grid, const std::vector<CouplingBody<Dim>>& bodies,
                       SolidWeights<Dim>&& weights, BodyGroup group) = delete;
  BodyCouplingOperator(const MacGrid<Dim>& grid, const std::vector<CouplingBody<Dim>>& bodies,
                       SolidWeights<Dim>&& weights, BodyGroup group, const Columns&) = delete;

  int num_rows() const { return num_rows_; }
  int num_cells() const { return grid_.num_cells(); }
  int num_stress_dofs() const { return stress_.num_dofs(); }
  /// First row of every body, -1 for bodies of the other group.
  const std::vector<int>& rows() const { return rows_; }
  /// Cells with a non-zero column of J_p (per body: the body's surface cells).
  const std::vector<std::vector<int>>& surface_cells() const { return surface_cells_; }
  /// Stress DOFs with a non-zero column of J_s (per body).
  const std::vector<std::vector<int>>& surface_stress() const { return surface_stress_; }

  /// One non-zero column block of J_p or J_s: the body (index in the body list), its first row,
  /// the cell (J_p) or StressGrid DOF (J_s), and the kBodyDofs entries of the column.
  struct SurfaceColumn {
    int body = 0;
    int row = 0;
    int index = 0;
    BodyVec<Dim> column;
  };
  /// The non-zero column blocks of J_p (eqs. (18)/(24)), per body in body order then by cell:
  /// the entries of pressure_jacobian() bit for bit (the same evaluation), without a num_rows x
  /// num_cells matrix. For the matrix-free back end of eq. (24), which keeps them per surface
  /// unknown.
  std::vector<SurfaceColumn> pressure_columns() const;
  /// The same for J_s (eqs. (19)/(24); stress_jacobian()), per body then by StressGrid DOF.
  std::vector<SurfaceColumn> stress_columns() const;

  /// J_p explicitly, num_rows x num_cells.
  SparseMatrix pressure_jacobian() const;
  /// J_s explicitly, num_rows x num_stress_dofs (all StressGrid components).
  SparseMatrix stress_jacobian() const;
  /// y = J_p p (force and torque on every body of the group from the cell pressures p).
  VectorX apply_pressure(const VectorX& p) const;
  /// y = J_p^T v, num_cells.
  VectorX apply_pressure_transpose(const VectorX& v) const;
  /// y = J_s tau (tau: all StressGrid components).
  VectorX apply_stress(const VectorX& tau) const;
  /// y = J_s^T v, num_stress_dofs.
  VectorX apply_stress_transpose(const VectorX& v) const;

 private:
  using Block = BodyVec<Dim>;
  /// Column of body b's block of J_p at cell c; false if it vanishes by the cancellation rule.
  bool pressure_column(int body, int cell, Block& column) const;
  /// Column of body b's block of J_s at stress DOF k; false if it vanishes.
  bool stress_column(int body, int dof, Block& column) const;
  /// dx^Dim w_i(f) [e_a; (x_f - c_i) x e_a] for face f.
  Block face_block(int body, int face) const;

  MacGrid<Dim> grid_;
  StressGrid<Dim> stress_;
  std::vector<CouplingBody<Dim>> bodies_;
  const std::vector<VectorX>& body_face_;  ///< SolidWeights::body_face of the constructor's weights
  std::vector<int> rows_;
  int num_rows_ = 0;
  std::vector<std::vector<int>> surface_cells_, surface_stress_;
};

/// The D row of stress DOF `dof` as (face, coefficient) pairs: the stencil of
/// deformation_rate_matrix (eq. (8)) without forming D. `complete` receives whether every face
/// of the interior stencil exists (false at a non-periodic boundary, where D omits faces).
template <int Dim>
std::vector<std::pair<int, double>> deformation_rate_row(const StressGrid<Dim>& stress, int dof,
                                                         bool* complete = nullptr);

/// eq. (24), the body part of b2: b2_cells -= alpha W_L^p J_p^T v* (alpha = 1/dx^Dim converts to
/// the paper's J_p, file comment), v* the group's body velocities (kBodyDofs per body, linear
/// then angular, world frame). Full cell vector; the Stokes assembly selects (S_p) afterwards.
template <int Dim>
void subtract_body_pressure_rhs(const BodyCouplingOperator<Dim>& op, const MacGrid<Dim>& grid,
                                const VectorX& liquid_cell, const VectorX& v_star,
                                VectorX& b2_cells);

/// eq. (24), the body part of b1: b1_full -= alpha W_L^s J_s^T v*, b1_full over all StressGrid
/// DOFs (the full form of stokes_system.hpp's b1 before E^T and S_tau: b1 = S_tau E^T b1_full).
template <int Dim>
void subtract_body_stress_rhs(const BodyCouplingOperator<Dim>& op, const MacGrid<Dim>& grid,
                              const VectorX& liquid_stress, const VectorX& v_star,
                              VectorX& b1_full);

/// The generalised velocities (v, omega) of the bodies of `group`, stacked in the group's row
/// order (kBodyDofs per body).
template <int Dim>
VectorX group_velocities(const std::vector<RigidBody<Dim>>& bodies, BodyGroup group);

}  // namespace monolith
