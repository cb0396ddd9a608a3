#pragma once
/// \file multigrid.hpp
/// Generic multigrid machinery for symmetric positive definite operators stored as sparse
/// matrices: a hierarchy of levels (operator, prolongation from the next coarser level), a
/// multiplicative patch (block Gauss-Seidel, "Vanka") smoother whose patches are grouped into
/// independent colours, and the symmetric V-cycle. Nothing here knows about grids: the levels,
/// prolongations and patches come from the caller (reference/fluid/mac_hierarchy.hpp builds them
/// for the MAC faces and cells).
///
/// The V-cycle used as a preconditioner is a fixed symmetric positive definite operator Q:
/// pre-smoothing sweeps the colours forward, post-smoothing backward (the adjoint), the coarse
/// operators are Galerkin products P^T A P, the coarsest level is solved exactly. Then the error
/// propagation E = I - Q A is self-adjoint and positive semi-definite in the A inner product, so
/// 0 < Q <= A^-1 (docs/preconditioners.md uses this). k cycles of the stationary iteration
/// x <- x + Q (b - A x) from zero give the operator (I - E^k) A^-1, also SPD and <= A^-1.
/// In single precision (the constructor's `single_precision`) A_l is replaced on every smoothed
/// level by its rounded Ã_l >= A_l ((P12)): Q stays SPD, Q <= A^-1 holds up to the rounding.
///
/// Parallel and deterministic: patches of one colour share no unknown and no matrix entry couples
/// an unknown of one to an unknown of another (checked by patches_independent), so each colour is
/// relaxed in parallel with the same result as serially; every matrix-vector product is row
/// parallel with one writer per entry. Scratch vectors are sized at construction: apply allocates
/// nothing, and one object must not run two applications at once from different threads.

#include <cstddef>
#include <memory>
#include <vector>

#include <Eigen/SparseCholesky>

#include "reference/core/common.hpp"
#include "reference/solvers/preconditioner.hpp"
#include "reference/solvers/sparse_ldlt.hpp"

namespace monolith {

/// An array whose elements are left uninitialised when it is allocated (default-initialised, so
/// no zero fill: fresh pages are first touched by the loop that writes every element, in parallel
/// where that loop is parallel). For buffers written in full right after allocation.
template <typename T>
class RawArray {
 public:
  void allocate(std::size_t n) {
    data_.reset(n ? new T[n] : nullptr);
    size_ = n;
  }
  T* data() { return data_.get(); }
  const T* data() const { return data_.get(); }
  std::size_t size() const { return size_; }
  bool empty() const { return size_ == 0; }
  T& operator[](std::size_t i) { return data_[i]; }
  const T& operator[](std::size_t i) const { return data_[i]; }

 private:
  std::unique_ptr<T[]> data_;
  std::size_t size_ = 0;
};

/// The patches of one level's smoother: patch k owns the unknowns
/// index[start[k]] .. index[start[k + 1] - 1] (each at most kMaxPatchSize, listed once). Patches
/// are relaxed in groups: group g is the patches group_start[g] .. group_start[g + 1] - 1, relaxed
/// one after the other in that order (a block of nearby patches, good for the caches); colours[c]
/// lists the groups of colour c. Groups of one colour must be independent (no shared unknown, no
/// matrix entry between their unknowns), so a colour is relaxed in parallel with the serial
/// result. Every unknown should be in some patch (an unknown in none is never smoothed).
struct PatchSet {
  static constexpr int kMaxPatchSize = 32;
  std::vector<int> start{0};
  std::vector<int> index;
  std::vector<int> group_start{0};
  std::vector<std::vector<int>> colours;
  int size() const { return static_cast<int>(start.size()) - 1; }
  int num_groups() const { return static_cast<int>(group_start.size()) - 1; }
  /// Appends a patch (its unknowns) to the current group and returns its number.
  int add(const std::vector<int>& unknowns);
  /// Closes the current group (the patches added since the last call) and puts it into colour
  /// `colour` (colours grows as needed); an empty group is dropped.
  void close_group(int colour);
};

/// One level of the hierarchy.
struct MultigridLevel {
  SparseMatrix a;             ///< the operator of this level (square, SPD)
  SparseMatrix prolongation;  ///< from the next coarser level: rows = a.rows(); empty on the coarsest
  /// optional: prolongation's transpose as Eigen forms it (galerkin_product hands out the one it
  /// formed), taken by Multigrid instead of forming it again; empty: formed there
  SparseMatrix restriction;
  PatchSet patches;           ///< the smoother's patches (ignored on the coarsest level)
};

/// A symmetric V-cycle over a hierarchy (levels[0] finest).
class Multigrid {
 public:
  Multigrid() = default;
  /// Takes the levels (each but the last with its prolongation and patches), computes the patch
  /// inverses and factors the coarsest operator (sparse LDL^T). `smoothing` is the number of
  /// sweeps before and after the coarse correction on every level. Throws std::invalid_argument
  /// on inconsistent sizes, a patch larger than kMaxPatchSize, or a singular patch block.
  /// `renumber` false keeps the caller's numbering on every level (the same results bit for bit,
  /// only slower on large levels; for the test that checks exactly that).
  ///
  /// `single_precision`: every smoothed level sweeps and forms residuals with its operator's
  /// values stored in single precision (rounded so that the rounded operator Ã_l >= A_l: SPD,
  /// (P12) of docs/derivations.md) and patch inverses of Ã_l's blocks; the transfers, the
  /// vectors and the coarsest factor stay in double. Q is then the V-cycle of the operators Ã_l:
  /// still symmetric positive definite (the file comment's argument with Ã_l in place of A_l), a
  /// different preconditioner by round-off (docs/preconditioners.md section 31).
  Multigrid(std::vector<MultigridLevel> levels, int smoothing, bool renumber = true, bool single_precision = false);
  bool single_precision() const { return single_precision_; }
  /// The operator level l's sweeps and residuals use, in its internal numbering: level(l).a, or
  /// in single precision its rounded values Ã_l as doubles (for tests and reports).
  SparseMatrix smoothed_operator(int l) const;

  int size() const { return levels_.empty() ? 0 : static_cast<int>(levels_[0].a.rows()); }
  int num_levels() const { return static_cast<int>(levels_.size()); }
  /// Level l in its internal numbering: every level but the coarsest is renumbered at
  /// construction in the order its forward sweep first touches the unknowns (order(l)), for
  /// locality; its operator, patches and transfers are the given ones in that numbering. The
  /// results of apply are unchanged by this, bit for bit (see renumber in multigrid.cpp).
  const MultigridLevel& level(int l) const { return levels_[l]; }
  /// The numbering of level l: internal unknown i is the caller's unknown order(l)[i] (empty on
  /// the coarsest level: unchanged).
  const std::vector<int>& order(int l) const { return order_[l]; }
  /// The finest operator in the caller's numbering (a copy; for tests and reports); `smoothed`:
  /// the one the finest level's sweeps and residuals use (rounded in single precision).
  SparseMatrix finest_operator(bool smoothed = false) const;
  int smoothing() const { return smoothing_; }

  /// x = Q_k b: `cycles` V-cycles of the stationary iteration from x = 0 (cycles >= 1), b and x
  /// in the caller's numbering of the finest level.
  void apply(const VectorX& b, VectorX& x, int cycles = 1) const;
  /// One V-cycle on level l from x = 0: x = Q_l b (b and x of that level's size, in its
  /// internal numbering).
  void cycle(int level, const VectorX& b, VectorX& x) const;
  /// One smoothing sweep on level l (internal numbering): all colours forward (backward =
  /// reverse colour order and reverse order within a colour), every patch relaxed exactly:
  /// x_P += A_PP^-1 (b - A x)_P.
  void sweep(int level, const VectorX& b, VectorX& x, bool backward) const;

  /// Bytes held (matrices, prolongations, patch inverses, coarse factor estimate, scratch).
  std::size_t memory_bytes() const;
  /// Sum over levels of the stored non-zeros divided by those of the finest operator.
  double operator_complexity() const;

 private:
  void renumber();
  void compute_patch_inverses(int level);
  template <typename V>
  void sweep_values(int level, const VectorX& b, VectorX& x, bool backward, const V* value) const;
  /// r = b - A_l x with the operator the level's sweeps use (rounded in single precision)
  void level_residual(int level, const VectorX& b, const VectorX& x, VectorX& r) const;

  void apply_internal(const VectorX& b, VectorX& x, int cycles) const;

  std::vector<MultigridLevel> levels_;
  std::vector<std::vector<int>> order_;  ///< per level: internal -> caller's numbering (empty: same)
  std::vector<SparseMatrix> restriction_;        ///< prolongation transposes, row-major
  std::vector<std::vector<int>> inverse_start_;  ///< per level, per patch: offset into inverse_
  /// per level: dense patch inverses, patch after patch: the packed upper triangle of patches of
  /// at most 6 unknowns, row-major m x m above (inverse_entries in multigrid.cpp)
  std::vector<RawArray<double>> inverse_;
  std::unique_ptr<SparseLdlt> coarse_;  ///< movable
  int smoothing_ = 1;
  bool single_precision_ = false;
  /// per smoothed level in single precision: the rounded operator's values (rounded_dominant in
  /// multigrid.cpp), in the stored order of levels_[l].a; empty otherwise
  std::vector<RawArray<float>> value_f_;
  // scratch per level
  mutable std::vector<VectorX> residual_, coarse_rhs_, coarse_x_, work_;
  mutable VectorX apply_residual_, apply_correction_;  ///< cycles >= 2 of apply (finest size)
  mutable VectorX apply_in_, apply_out_;  ///< apply's b and x in the internal numbering
};

/// A multigrid hierarchy used as a PCG preconditioner: z = Q_k r, `cycles` symmetric V-cycles
/// from zero (SPD, see the file comment). With a cell hierarchy of the pressure Poisson matrix
/// this is MGPCG (McAdams, Sifakis and Teran 2010) for the pressure-only solves.
class MultigridPreconditioner : public Preconditioner {
 public:
  MultigridPreconditioner(Multigrid mg, int cycles = 1) : mg_(std::move(mg)), cycles_(cycles) {}
  int size() const override { return mg_.size(); }
  void apply(const VectorX& r, VectorX& z) const override { mg_.apply(r, z, cycles_); }
  std::string name() const override { return "multigrid"; }
  const Multigrid& multigrid() const { return mg_; }

 private:
  Multigrid mg_;
  int cycles_;
};

/// a b for compressed row-major a, b, row by row (Gustavson; rows sorted; one thread per row,
/// so the result does not depend on the thread count): the same additions in the same order as
/// Eigen's conservative sparse product, hence the same bits; with `drop_zeros` the entries that
/// are exactly zero are left out (Eigen's prune(0, 0)), else kept as Eigen keeps them.
/// `sort_columns` false leaves each row's columns in the order of their first term (the values
/// are the same; a product only read by another product's rows, galerkin_product's A P).
SparseMatrix sparse_row_product(const SparseMatrix& a, const SparseMatrix& b, bool drop_zeros, bool sort_columns = true);

/// The Galerkin coarse operator P^T A P (row-major, explicit zeros dropped). `transpose` (optional)
/// receives the P^T it formed (compressed, row-major; MultigridLevel::restriction).
SparseMatrix galerkin_product(const SparseMatrix& a, const SparseMatrix& p, SparseMatrix* transpose = nullptr);

/// True when no two groups of one colour share an unknown or are coupled by an entry of `a`
/// (so relaxing a colour in parallel gives the serial result) and every group is in exactly one
/// colour.
bool patches_independent(const SparseMatrix& a, const PatchSet& patches);

}  // namespace monolith
