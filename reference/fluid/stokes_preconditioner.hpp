#pragma once
/// \file stokes_preconditioner.hpp
/// The block preconditioner of the unified pressure-viscosity system of eq. (8) (the (tau, p)
/// blocks of eq. (24)); the derivation and the measured comparison with the alternatives are in
/// docs/preconditioners.md. In short, with the factors of reference/fluid/velocity_operator.hpp
/// (A = B^T C B + blkdiag(K, 0)) and a positive diagonal Pi on the pressure block:
///
///   A' = A + blkdiag(0, Pi),   A'^-1 = D^-1 - D^-1 B^T V^-1 B D^-1   (Woodbury, D = blkdiag(K, Pi))   [(P2)]
///   A^-1 = A'^-1 + A'^-1 E Pi S Pi E^T A'^-1,   S = (Pi - Pi E^T A'^-1 E Pi)^-1 = Sigma_pi^-1
///
/// (E the pressure rows, Sigma_pi = B_p^T V^-1 B_p the pressure Schur complement of the velocity
/// form, Sigma_pi^-1 = Sigma^-1 + Pi^-1, Sigma = B_p^T V0^-1 B_p with V0 = C^-1 + B_tau K^-1
/// B_tau^T the unpenalised velocity operator). The preconditioner applies the right-hand sides
/// with V^-1 replaced by multigrid V-cycles (more of them the stiffer the system: their error
/// reaches the result amplified by about the viscous-to-mass ratio of V, section 19) and Sigma^-1
/// by a scaled least-squares commutator (BFBt; Sigma^-1 ~ L^-1 B_p^T W V0 W B_p L^-1 with
/// W = diag(V0)^-1, L = B_p^T W B_p by cell multigrid; docs/preconditioners.md section 19), or
/// by the older Cahouet-Chabard-type sum, and wraps the result in SOR sweeps of
/// A itself (a symmetric two-level composition): SPD for any choice of its parts. Between the
/// sweeps and that inverse, on each side, an exact solve with A's principal block A_CC on the
/// unknowns next to a curved solid (the cut block, StokesPreconditionerOptions::cut_threshold;
/// docs/preconditioners.md, section 12); between the outer sweeps and the cut solves, on each
/// side, point Gauss-Seidel sweeps of A on the free surface's rows (StokesPreconditionerOptions::
/// surface_sweeps, (P17), section 38).

#include <memory>
#include <string>
#include <vector>

#include "reference/core/common.hpp"
#include "reference/fluid/mac_hierarchy.hpp"
#include "reference/fluid/velocity_operator.hpp"
#include "reference/solvers/linear_operator.hpp"
#include "reference/grid/mac_grid.hpp"
#include "reference/solvers/multigrid.hpp"
#include "reference/solvers/preconditioner.hpp"
#include "reference/solvers/sparse_ldlt.hpp"

namespace monolith {

/// The approximation of Sigma^-1 = (B_p^T V0^-1 B_p)^-1 in the two-term form (S = Sigma^-1 + Pi^-1).
enum class SchurApproximation {
  /// A22^-1 + schur_viscous_factor eta / W_L^p (Poisson multigrid plus a diagonal): the form of
  /// sections 5-18; loses quality near free surfaces (section 17).
  cahouet_chabard,
  /// L^-1 B_p^T C V0 C B_p L^-1 with L = A22 = B_p^T C B_p (the commutator weighted by the face
  /// mobility C; measured 4-8x worse than scaled on Fig. 5, section 19).
  commutator_mobility,
  /// L^-1 B_p^T W V0 W B_p L^-1, W = diag(V0)^-1, L = B_p^T W B_p (the scaled BFBt of
  /// Elman et al. 2006 / May and Moresi 2008) [(P7)].
  commutator_scaled,
};

struct StokesPreconditionerOptions {
  double penalty_factor = 3.0;       ///< gamma: Pi^-1 = gamma (eta / W_L^p + 1 / A22_ii)
  /// Near-empty pressure cells: a pressure unknown whose Poisson diagonal A22_kk is below this
  /// fraction of the median A22 diagonal (a liquid cell almost closed by solid faces) is left out
  /// of the penalised inverse and of the Schur term (Pi_k^-1 = 0 in (P2): the limit Pi_k -> inf,
  /// A'^-1 restricted to the other unknowns) and gets the Jacobi term r_k / A22_kk instead. With
  /// its Pi_k^-1 = gamma (eta / W_L^p + 1 / A22_kk) up to 1e13 times the median, the penalised
  /// inverse's difference of two terms amplified the V-cycle error and the round-off until P was
  /// non-symmetric and indefinite (docs/preconditioners.md sections 20-21) [(P8)]. 0: none left out
  /// (the default here: on the liquid-only solves the snapshot measured more iterations with it;
  /// CoupledPreconditionerOptions::empty_cell_ratio turns it on where a body term meets the liquid).
  double empty_cell_ratio = 0.0;
  /// The diagonal d_k of a term added to the system's pressure rows that P does not see (the
  /// coupled preconditioner passes the body term's, (B_f^T W B_f)_kk; one entry per pressure
  /// unknown, non-negative; empty: d = 0). The Jacobi term of a near-empty cell is
  /// r_k / (A22_kk + d_k).
  VectorX empty_cell_extra;
  /// > 0: a cell below empty_cell_ratio is near-empty only if also d_k >= this x A22_kk (the
  /// added term dwarfs or matches its Poisson row: where the Woodbury correction (P4) would have
  /// to cancel P's 1 / A22_kk). The cells of the 3D viscous scenes below 1e-4 of the median have
  /// d_k / A22_kk below 2e-5 and P is better with them kept; those of the 2D stalls 0.07..1e13
  /// (docs/preconditioners.md section 23). 0: no such condition.
  double empty_cell_extra_ratio = 0.0;
  /// false: no Jacobi term, P is zero on the near-empty cells' rows and columns (P = blkdiag(P_r, 0);
  /// the coupled preconditioner solves those cells itself, exactly with the body term).
  bool empty_cell_jacobi = true;
  double min_fluid_fraction = 0.01;  ///< W_F^s floor in the preconditioner's K
  /// V-cycles per solve with V. 2: on `viscous-bunny-into-sphere-3d` (stiffness 205) one cycle
  /// needed 118-171 PCG iterations in the air and 313 on the curved wall, two 38-55 and 118, at
  /// 1.3-1.5x less solve time; smoothing 2 or 3 cycles cost about the same, transverse-constant
  /// transfers or sparsified coarse levels doubled the iterations (docs/preconditioners.md,
  /// section 10).
  /// (With cycle_ratio > 0: the count at or below that ratio; section 19.) Section 24 measured
  /// velocity_cycles 1 with cycle_ratio 67.5 (the same counts as 2 with 270 wherever the median
  /// ratio is at least 270, since 1 + floor(log4(r / 67.5)) = 2 + floor(log4(r / 270)); one cycle
  /// below): half the solve time on the 64^3 tank at eta 100 (6 iterations either way), but about
  /// twice the iterations on the 3D built-in scenes below that ratio (viscous-coiling-3d,
  /// liquid-drop-bingham-3d, viscous-sphere-wall-3d, ...): not the default.
  int velocity_cycles = 2;
  /// > 0: one V-cycle more per factor 4 of the median viscous-to-mass ratio r_f = C_f (V0)_ff - 1
  /// of V's rows above this value [(P6): I - M'A' = D^-1 B^T (I - QV) C B amplifies the V-cycle
  /// error by r] (a fixed count per system: P stays a fixed SPD map).
  /// velocity_cycles() of the preconditioner is velocity_cycles + max(0, floor(log4(median r /
  /// cycle_ratio))), at most max_velocity_cycles. In 3D the median r is 6.7 eta dt / (rho dx^2)
  /// (Fig. 5 at 32^3 and 64^3), so 270 is a stiffness of 40: 2 cycles at 32^3, 3 at 64^3, 4 at
  /// 128^3 (section 19). 0: velocity_cycles always.
  double cycle_ratio = 270.0;
  int max_velocity_cycles = 6;
  /// 3D: one V-cycle fewer (at least one) than the rule above gives when the free-surface share
  /// (the pressure unknowns with W_L^p < 1 over all pressure unknowns) is below this [(P9)]. A
  /// liquid that fills its box (the 64^3 tank of the benchmark: share 0.035) gets the same PCG
  /// iterations from one cycle as from two at eta 100 and 2 more at eta 1000, at about 0.55x the
  /// cost per iteration; the small built-in 3D scenes with a free surface all round (shares
  /// 0.37-0.76) need up to twice the iterations with one cycle, so they keep the rule above;
  /// blocks of liquid filling the bottom of their box (bunny-into-block-bingham-3d,
  /// -shear-thickening-3d) fall below it (docs/preconditioners.md sections 24-25). 0: off. Not
  /// applied in 2D (not measured there).
  double lean_share = 0.15;
  int smoothing = 1;                 ///< patch sweeps before and after each coarse correction
  int outer_sweeps = 2;              ///< SOR sweeps of A before and after (0: none)
  double omega = 1.0;                ///< their relaxation
  /// The second term (the two-term form; default since section 19: with the scaled commutator
  /// 4.7x fewer iterations than the additive form on Fig. 5 at 64^3, 1.8x less solve time).
  bool schur_correction = true;
  bool additive_pressure = false;    ///< instead of the second term: + E A22^-1 E^T (one V solve less)
  int inner_cg = 0;                  ///< > 0: V^-1 by this many multigrid-preconditioned CG steps (nonlinear: flexible outer CG)
  SchurApproximation schur = SchurApproximation::commutator_scaled;  ///< Sigma^-1 in the two-term form
  double schur_viscous_factor = 0.5; ///< cahouet_chabard: S ~ A22^-1 + Pi^-1 + factor eta / W_L^p
  bool element_patches = true;       ///< stress-element patches on the finest velocity level
  int max_coarse = 1500;             ///< multigrid coarsest-level size
  bool transverse_linear = true;     ///< MacMultigridOptions::transverse_linear of the velocity levels
  bool fine_cell_patches = true;     ///< MacMultigridOptions::fine_cell_patches
  bool renumber = true;              ///< MacMultigridOptions::renumber (locality; same bits)
  /// The velocity hierarchy's smoothed levels in single precision (MacMultigridOptions::
  /// single_precision: V-cycles of rounded operators Ã_l >= A_l, SPD by (P12); about 15 % less
  /// time per V-cycle on the 64^3 tank, docs/preconditioners.md section 31).
  bool single_precision_velocity = true;
  /// The cut block C, solved exactly (sparse LDL^T of A_CC with the system's own K, no floor)
  /// after the forward outer sweeps and before the backward ones, around the two-term inverse
  /// (a symmetric multiplicative composition: SPD as before). C = the stress unknowns with
  /// 0 < W_F^s < cut_threshold (cut by a solid; 1/2, strictly below, leaves out those on a
  /// grid-aligned wall, which have exactly 1/2 and which the hierarchy handles), then
  /// (cut_pressure) the pressure unknowns their rows of A reach, then cut_layers layers of all
  /// unknowns the rows of the set reach. cut_threshold 0: no block. On
  /// `viscous-bunny-on-sphere-wall-3d` (the bunny on the curved container wall): 240 -> 38 PCG
  /// iterations (docs/preconditioners.md, section 12). No block is built when its factor would
  /// hold more than cut_factor_cap times the entries of the finest velocity operator.
  double cut_threshold = 0.5;
  bool cut_pressure = true;
  int cut_layers = 2;
  /// Layers after the first are added only while the block holds at most this many unknowns
  /// (0: no limit). The factor's cost grows much faster than the block: on the 64^3 tank (a cut
  /// ball) two layers gave 28070 unknowns and 8.5M factor entries, half the set-up, one layer
  /// 19307 and 3.9M at the same 6 PCG iterations; the wall bunny's block (about 2.8k unknowns)
  /// keeps its two layers (docs/preconditioners.md, section 22).
  int cut_layer_limit = 10000;
  /// The largest cut-block factor built, in entries of L per entry of the finest velocity
  /// operator (the two cut solves of an application then cost about 4 cut_factor_cap such
  /// entries' products, against some 50-80 for the rest of an application). 8 until the
  /// twenty-fifth session; the cut faces' raised stress DOFs (departures item 24, W_F^s = 0.01 <
  /// cut_threshold) joined the seed and took hollow-spheres-viscous-3d's factor to 9-10.3x, where
  /// no block meant 63-80 iterations per frame instead of 14-17 and 1.4-2x the solve time
  /// (docs/preconditioners.md section 47).
  double cut_factor_cap = 16.0;
  /// The cut block's numeric factorisation by supernodes (SparseLdlt::factorize_supernodal:
  /// dense panels and dense updates) instead of Eigen's simplicial one: the same factor up to
  /// round-off at a fraction of the time on large blocks (docs/preconditioners.md section 27).
  bool cut_supernodal = true;
  /// Point Gauss-Seidel sweeps of A on the free surface's unknowns S (the pressure unknowns of
  /// partly filled cells, W_L^p < 1, and the stress unknowns on their faces), after the forward
  /// outer sweeps and, mirrored, before the backward ones: a symmetric multiplicative composition
  /// as for the cut block, SPD as before [(P17)]. The residual of the settling liquid sits on
  /// these rows (the off-diagonal stress unknowns with W_L^s < 1 and the partly filled cells:
  /// 35-65 % of ||r||^2 and the maximum in most iterations of viscous-bunny-into-sphere-3d's
  /// settling frames); 4 sweeps: 65 -> 55 PCG iterations on its frames 31-34 and 77 -> 65 on
  /// 35-38 at about 7 % of an application (docs/preconditioners.md section 38). Only with
  /// outer_sweeps > 0. 0: none.
  int surface_sweeps = 4;
};

/// The preconditioner over the unknowns (tau, p) of StokesDofs. Holds a reference to `a` (the
/// system operator, whose SOR sweeps it uses; explicit or matrix-free); everything else it owns.
/// apply allocates nothing; one object must not run two applications at once.
template <int Dim>
class StokesPreconditioner : public Preconditioner {
 public:
  StokesPreconditioner(const MacGrid<Dim>& grid, const LinearOperator& a, StokesFactors factors,
                       const StokesPreconditionerOptions& options = {});
  int size() const override { return n_; }
  void apply(const VectorX& r, VectorX& z) const override;
  std::string name() const override { return "block"; }

  const StokesFactors& factors() const { return f_; }
  const StokesPreconditionerOptions& options() const { return options_; }
  const Multigrid& velocity_multigrid() const { return velocity_; }
  const Multigrid& pressure_multigrid() const { return pressure_; }
  /// The unknowns of the cut block C (increasing; empty when off or when there is none).
  const std::vector<int>& cut_unknowns() const { return cut_; }
  /// The unknowns of the free-surface sweeps (increasing; empty when off or without W_L^p < 1).
  const std::vector<int>& surface_unknowns() const { return surface_; }
  /// Entries of the cut block's LDL^T factor (0 without a block).
  long cut_factor_entries() const { return cut_factor_ ? static_cast<long>(cut_factor_->analysed_entries()) : 0; }
  /// Pi per pressure unknown (as the formula gives it, also on the near-empty cells).
  const VectorX& penalty() const { return penalty_; }
  /// The near-empty pressure unknowns (0..n_p-1, increasing; options().empty_cell_ratio).
  const std::vector<int>& empty_cells() const { return empty_; }
  /// The Jacobi term of the near-empty cells becomes r_k / (A22_kk + extra_k) (extra: one
  /// non-negative entry per pressure unknown; only those of the near-empty cells are used). The
  /// coupled preconditioner passes the diagonal of the body term B_f^T W B_f, so that P is not
  /// 1 / A22_kk (up to 1e16 times A_ff's scale) on a cell that a light body's term dominates:
  /// the Woodbury correction (P4) would cancel it in round-off. Before the first apply.
  void set_empty_cell_diagonal(const VectorX& extra);
  /// The V-cycles per velocity solve (options' velocity_cycles, raised by the rule of (P6)).
  int velocity_cycles() const { return cycles_; }
  /// The median over V's rows of the viscous-to-mass ratio C_f (V0)_ff - 1 (0 without stress).
  double viscous_ratio() const { return viscous_ratio_; }
  /// The pressure unknowns with W_L^p < 1 over all pressure unknowns (0 without pressure).
  double free_surface_share() const { return free_surface_share_; }
  /// s ~ Sigma^-1 e + Pi^-1 e (S of the second term; Sigma^-1 by options().schur: with the
  /// commutators, (P7)).
  void apply_schur(const VectorX& e, VectorX& s) const;
  /// y = V0 x = x / C + B_tau K^-1 B_tau^T x over the faces (the preconditioner's K).
  void apply_unpenalised_velocity(const VectorX& x, VectorX& y) const;
  /// y = A'^-1 g with the V-cycles in place of V^-1 (the first term above).
  void apply_penalised_inverse(const VectorX& g, VectorX& y) const;
  /// Bytes held (factors, hierarchies, scratch).
  std::size_t memory_bytes() const;

 private:
  void apply_two_term(const VectorX& r, VectorX& z) const;
  /// apply_penalised_inverse for a g whose stress part is +0, with B_p in place of B (the same
  /// bits; docs/preconditioners.md section 41).
  void apply_penalised_inverse_pressure(const VectorX& g, VectorX& y) const;
  /// z_k = r_k / A22_kk on the near-empty cells.
  void add_empty_cells(const VectorX& r, VectorX& z) const;
  void build_cut_block();
  /// Rows `list` of A = B^T C B + blkdiag(K, 0) (the system's own K), row-major |list| x n.
  SparseMatrix rows_of_a(const std::vector<int>& list) const;
  void build_surface_block();
  /// options().surface_sweeps point Gauss-Seidel sweeps of A on the surface set (backward when
  /// `reverse`).
  void surface_sweeps(bool reverse, const VectorX& r, VectorX& z) const;
  /// z_C += A_CC^-1 (r - A z)_C.
  void correct_cut(const VectorX& r, VectorX& z) const;
  /// `count` outer SOR sweeps of A (backward when `reverse`) on the rows swept_ allows: on an
  /// explicit A in the order factors().sweep_order (the matrix-free operator's), else by a_.
  void outer_sweeps(bool reverse, const VectorX& r, VectorX& z, int count) const;

  const LinearOperator& a_;
  /// a_ as an explicit matrix whose sweeps run in f_.sweep_order (nullptr: a_ sweeps itself)
  const SparseMatrix* ordered_matrix_ = nullptr;
  VectorX ordered_diagonal_;
  StokesFactors f_;
  StokesPreconditionerOptions options_;
  int n_ = 0, ns_ = 0, np_ = 0, nf_ = 0;
  SparseMatrix kinv_;       ///< K^-1 (stress unknowns)
  int cycles_ = 0;          ///< V-cycles per velocity solve
  double viscous_ratio_ = 0.0;
  double free_surface_share_ = 0.0;
  bool commutator_ = false;  ///< the two-term form with a commutator S
  SparseMatrix bp_, bpt_;   ///< B_p (faces x n_p) and B_p^T (commutator only)
  SparseMatrix bp_second_;  ///< B_p for the second term without a commutator (else empty)
  VectorX commutator_weight_;  ///< W (C or diag(V0)^-1) per face
  VectorX penalty_;         ///< Pi
  VectorX penalty_divisor_; ///< Pi in (P2) and S, divided by: +inf on the near-empty cells (Pi^-1 = 0)
  VectorX penalty_used_;    ///< Pi in the second term: 0 on the near-empty cells
  std::vector<int> empty_;  ///< the near-empty pressure unknowns
  VectorX empty_diagonal_;  ///< A22_kk on them
  VectorX empty_inverse_;   ///< 1 / (A22_kk + extra_k) on them
  std::vector<char> swept_; ///< rows the outer sweeps relax (empty: all)
  VectorX schur_diagonal_;  ///< Pi^-1 + factor eta / W_L^p
  Multigrid velocity_, pressure_;
  SparseMatrix velocity_finest_;  ///< V in the faces' numbering (inner_cg > 0 only)
  bool pressure_only_ = false;
  std::vector<int> surface_;       ///< the unknowns of the surface set (increasing)
  SparseMatrix surface_rows_;      ///< A_{S,:} (row-major, |S| x n)
  VectorX surface_diagonal_;       ///< A_ii on them
  std::vector<int> cut_;    ///< the unknowns of C
  SparseMatrix cut_rows_;   ///< A_{C,:} (row-major, |C| x n)
  std::unique_ptr<SparseLdlt> cut_factor_;  ///< of A_CC
  mutable VectorX cut_r_, cut_d_;
  mutable VectorX lq_, lh_, lf_, lg_, lt_, lu_;  ///< apply_schur scratch
  // scratch
  mutable VectorX ir_, iz_, ip_, iap_;
  mutable VectorX h_, face_, v_, back_, y1_, y2_, e_, s_, w_, res_, d_, az_;
};

}  // namespace monolith
