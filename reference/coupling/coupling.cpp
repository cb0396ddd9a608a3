#include "reference/coupling/coupling.hpp"
#include "reference/core/parallel.hpp"
#include "reference/core/first_touch.hpp"
#include "reference/core/huge_pages.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <tuple>

#include "reference/grid/stress_weights.hpp"
#include "reference/grid/volume_fractions.hpp"

namespace monolith {

namespace {

template <int Dim>
bool in_group(const CouplingBody<Dim>& body, BodyGroup group) {
  return body.two_way == (group == BodyGroup::two_way);
}

/// Lattice coordinates [lo, hi] (inclusive) of the points origin + (c + shift) dx, c in
/// [0, dims), that lie within `margin` of the box; the whole range on periodic axes (the box may
/// wrap) and for unbounded or empty boxes.
template <int Dim>
std::pair<VecI<Dim>, VecI<Dim>> lattice_range(const MacGrid<Dim>& grid, const Box<Dim>& box,
                                              const Vec<Dim>& shift, const VecI<Dim>& dims,
                                              double margin) {
  VecI<Dim> lo = VecI<Dim>::Zero(), hi = dims - VecI<Dim>::Ones();
  if (box.isEmpty()) return {lo, hi};
  for (int a = 0; a < Dim; ++a) {
    if (grid.periodic(a) || !std::isfinite(box.min()[a]) || !std::isfinite(box.max()[a])) continue;
    const double from = (box.min()[a] - margin - grid.origin()[a]) / grid.dx() - shift[a];
    const double to = (box.max()[a] + margin - grid.origin()[a]) / grid.dx() - shift[a];
    lo[a] = std::max(lo[a], static_cast<int>(std::floor(std::max(from, -1.0))));
    hi[a] = std::min(hi[a], static_cast<int>(std::ceil(std::min(to, static_cast<double>(dims[a])))));
  }
  return {lo, hi};
}

/// Calls fn(c) for every c in [lo, hi] (inclusive), x fastest.
template <int Dim, class Fn>
void for_range(const VecI<Dim>& lo, const VecI<Dim>& hi, Fn&& fn) {
  for (int a = 0; a < Dim; ++a)
    if (hi[a] < lo[a]) return;
  VecI<Dim> c = lo;
  while (true) {
    fn(c);
    int a = 0;
    while (a < Dim && c[a] == hi[a]) c[a] = lo[a], ++a;
    if (a == Dim) return;
    ++c[a];
  }
}

/// body_phi_on_lattice's values of a bounded shape at the lattice points of the inclusive box
/// [lo, hi] only, into `out` (the box's points, x fastest; sized by the caller): the closed form
/// (box_offset_table, summed as box_offset_distance does) everywhere, the shape's distance where
/// that is at most `far`. body_phi_on_lattice of a bounded shape is this over the whole lattice.
template <int Dim>
void body_phi_in_box(const SampleLattice<Dim>& lattice, const Shape<Dim>& shape,
                     double shrink_in_metres, double far, const VecI<Dim>& lo,
                     const VecI<Dim>& hi, VectorX& out) {
  if ((lo.array() > hi.array()).any()) return;
  const Box<Dim> box = shape.bounds();
  const VecI<Dim> box_dims = hi - lo + VecI<Dim>::Ones();
  const int nx = box_dims[0];
  VecI<Dim> row_dims = box_dims;
  row_dims[0] = 1;
  const int rows = row_dims.prod();
  std::array<std::vector<double>, Dim> offset;
  box_offset_table<Dim>(lattice, box, offset);
#pragma omp parallel for schedule(static) num_threads(team_threads(box_dims.prod()))
  for (int q = 0; q < rows; ++q) {
    VecI<Dim> c = lo + lattice_coord<Dim>(q, row_dims);
    double* o = out.data() + static_cast<std::size_t>(q) * nx;
    // the squares of the row's other offsets
    std::array<double, Dim> square;
    for (int a = 1; a < Dim; ++a) square[a] = offset[a][c[a]] * offset[a][c[a]];
    const auto outside = [&](int x) {
      double sum = offset[0][x] * offset[0][x];
      for (int a = 1; a < Dim; ++a) sum += square[a];
      return std::sqrt(sum);
    };
    for (int i = 0; i < nx; ++i) o[i] = outside(lo[0] + i) + shrink_in_metres;
    // a point within `far` has |t_a| <= far on every axis (the rounded sums only grow)
    double rest = 0.0;
    for (int a = 1; a < Dim; ++a) rest += square[a];
    if (std::sqrt(rest) > far) continue;
    for (int i = 0; i < nx; ++i) {
      const int x = lo[0] + i;
      if (std::abs(offset[0][x]) > far || outside(x) > far) continue;
      c[0] = x;
      o[i] = shape.distance(lattice.position(c)) + shrink_in_metres;
    }
  }
}

/// A body's SDF on the lattice shifted by zeta (solid_phi_on_lattice of one shape), evaluated
/// only within 2 dx of its bounds: farther out the distance to the bounds box (plus zeta), a
/// positive lower bound of the true distance, stands in. The fractions, which read only signs
/// and the values next to sign changes, are the same; a 3D mesh body costs its own box of
/// samples instead of the whole lattice in every step.
///
/// By rows along x: the distance to the box is sqrt((t_0^2 + t_1^2) + t_2^2), t_a the point's
/// offset from the box along axis a (one table per axis), summed in the order of Eigen's norm()
/// of the offset vector (the same bits as that expression); the shape is evaluated only at the
/// points of a row where that distance is at most `far`.
template <int Dim>
void body_phi_on_lattice(const SampleLattice<Dim>& lattice, const Shape<Dim>& shape,
                         double shrink_in_metres, double far, VectorX& phi) {
  const Box<Dim> box = shape.bounds();
  const bool bounded = !box.isEmpty() && box.min().allFinite() && box.max().allFinite();
  if (phi.size() != lattice.size()) phi.resize(lattice.size());
  if (bounded) {
    body_phi_in_box<Dim>(lattice, shape, shrink_in_metres, far, VecI<Dim>::Zero(),
                         lattice.dims - VecI<Dim>::Ones(), phi);
    return;
  }
  const int nx = lattice.dims[0];
  VecI<Dim> row_dims = lattice.dims;
  row_dims[0] = 1;
  const int rows = row_dims.prod();
#pragma omp parallel for schedule(static) num_threads(process_threads())
  for (int q = 0; q < rows; ++q) {
    VecI<Dim> c = lattice_coord<Dim>(q, row_dims);
    double* out = phi.data() + static_cast<std::size_t>(q) * nx;
    for (int x = 0; x < nx; ++x) {
      c[0] = x;
      out[x] = shape.distance(lattice.position(c)) + shrink_in_metres;
    }
  }
}

/// The lattice points where body_phi_on_lattice may be negative: those within `far` of the
/// bounds (every other point reads the distance to the bounds plus zeta >= 0), one point of
/// margin for rounding. False for an unbounded shape (no such box).
template <int Dim>
bool body_phi_negative_box(const SampleLattice<Dim>& lattice, const Shape<Dim>& shape,
                           double far, VecI<Dim>& lo, VecI<Dim>& hi) {
  const Box<Dim> box = shape.bounds();
  if (box.isEmpty()) {
    // no point is within the bounds: every value is the positive far value
    lo = lattice.dims;
    hi = -VecI<Dim>::Ones();
    return true;
  }
  if (!box.min().allFinite() || !box.max().allFinite()) return false;
  far_point_box<Dim>(lattice, box, far, 1, lo, hi);  // (an empty result is a valid answer)
  return true;
}

/// The faces whose control volume (the face centre +- dx along every axis) can reach `box`
/// (a bounded body's bounds): every face whose centre lies within 1.5 dx of the box, axis by
/// axis in index order, into `near` (cleared first). The faces body_face_fractions and
/// body_face_fractions_at evaluate; every other face's fraction is 0.
template <int Dim>
void faces_near_box(const MacGrid<Dim>& grid, const Box<Dim>& box, std::vector<int>& near) {
  const double reach = 1.5 * grid.dx();
  near.clear();
  for (int axis = 0; axis < Dim; ++axis) {
    const auto [lo, hi] = lattice_range<Dim>(grid, box, MacGrid<Dim>::face_shift(axis),
                                             grid.face_dims(axis), reach + grid.dx());
    for_range<Dim>(lo, hi, [&](const VecI<Dim>& coord) {
      const Vec<Dim> x = grid.face_center(axis, coord);
      if ((x.array() < box.min().array() - reach).any() ||
          (x.array() > box.max().array() + reach).any())
        return;
      near.push_back(grid.face_index(axis, coord));
    });
  }
}

/// w[f] = fraction(lower) for every face f in `near`, lower the half-lattice corner of f's
/// control volume (which starts half a cell before the face along its normal): the one loop of
/// body_face_fractions and body_face_fractions_at, which read the cube's fraction differently.
/// One face per iteration, so any thread count gives the same values.
template <int Dim, class CubeFraction>
void face_fractions_of_cubes(const MacGrid<Dim>& grid, const std::vector<int>& near, VectorX& w,
                             const CubeFraction& fraction) {
#pragma omp parallel for schedule(static) num_threads(process_threads())
  for (int n = 0; n < static_cast<int>(near.size()); ++n) {
    const int f = near[n];
    const auto [axis, coord] = grid.face_coord(f);
    VecI<Dim> lower = 2 * coord;
    lower[axis] -= 1;
    w[f] = fraction(lower);
  }
}

/// face_negative_fractions of a body's lattice phi, evaluated only on faces whose control
/// volume (the face centre +- dx along every axis) can reach the body's bounds; the others are
/// zero (their whole control volume lies where phi > 0). Same values, O(faces near the body):
/// only the faces in the index range of the bounds (plus a margin) are visited.
template <int Dim>
void body_face_fractions(const MacGrid<Dim>& grid, const SampleLattice<Dim>& lattice,
                         const VectorX& phi, const Box<Dim>& box, VectorX& w) {
  const bool bounded = !box.isEmpty() && box.min().allFinite() && box.max().allFinite();
  if (!bounded) {
    w = face_negative_fractions(grid, lattice, phi);
    return;
  }
  // (huge21) fresh storage takes its zeros from the kernel (core/huge_pages.hpp): the pages
  // outside the body's faces are not written
  if (w.size() != grid.num_faces()) {
    resize_to_released_zeros(w, grid.num_faces());
  } else {
    w.setZero();
  }
  std::vector<int> near;
  faces_near_box<Dim>(grid, box, near);
  face_fractions_of_cubes<Dim>(grid, near, w, [&](const VecI<Dim>& lower) {
    return lattice_cube_negative_fraction<Dim>(grid, lattice, lower, phi);
  });
}

/// The inclusive box of the points c in [lo, hi] where value(c) < 0 (lo > hi: none); any
/// thread count gives the same box.
template <int Dim, class Fn>
void negative_points(const VecI<Dim>& lo, const VecI<Dim>& hi, const Fn& value,
                     VecI<Dim>& neg_lo, VecI<Dim>& neg_hi) {
  VecI<Dim> nlo = VecI<Dim>::Constant(std::numeric_limits<int>::max()), nhi = -VecI<Dim>::Ones();
  if ((lo.array() <= hi.array()).all()) {
    const VecI<Dim> box_dims = hi - lo + VecI<Dim>::Ones();
    VecI<Dim> row_dims = box_dims;
    row_dims[0] = 1;
    const int rows = row_dims.prod();
#pragma omp parallel num_threads(team_threads(box_dims.prod()))
    {
      VecI<Dim> tlo = nlo, thi = nhi;
#pragma omp for schedule(static)
      for (int q = 0; q < rows; ++q) {
        VecI<Dim> c = lo + lattice_coord<Dim>(q, row_dims);
        for (int x = lo[0]; x <= hi[0]; ++x) {
          c[0] = x;
          if (value(c) < 0.0) {
            tlo = tlo.cwiseMin(c);
            thi = thi.cwiseMax(c);
          }
        }
      }
#pragma omp critical(monolith_negative_points)
      {
        nlo = nlo.cwiseMin(tlo);
        nhi = nhi.cwiseMax(thi);
      }
    }
  }
  if ((nlo.array() > nhi.array()).any()) {
    nlo = VecI<Dim>::Zero();
    nhi = -VecI<Dim>::Ones();
  }
  neg_lo = nlo;
  neg_hi = nhi;
}

/// lattice_cube_negative_fraction with the level set read through phi: directly from
/// phi.values when every corner lies in the box [phi.lo, phi.hi] (its points, x fastest), else
/// through phi(lattice coordinate); the same corners in the same order, so the same value.
template <int Dim, class Phi>
double cube_negative_fraction_at(const MacGrid<Dim>& grid, const VecI<Dim>& lower,
                                 const Phi& phi) {
  constexpr int kCorners = 1 << Dim;
  std::array<std::array<std::array<int, 2>, 2>, Dim> coord;
  for (int a = 0; a < Dim; ++a)
    for (int s = 0; s < 2; ++s) {
      const int l = map_lattice_cell(lower[a] + s, 2 * grid.cells()[a], grid.periodic(a));
      coord[a][s] = {l, l + 1};
    }
  std::array<std::array<double, kCorners>, kCorners> corners;
  int negatives = 0;
  // every corner inside the box of directly indexed values (phi.values, phi.lo, phi.hi): their
  // indices as sums of per-axis offsets, as lattice_cube_negative_fraction forms them
  bool inside = true;
  for (int a = 0; a < Dim; ++a)
    for (int s = 0; s < 2; ++s)
      inside = inside && coord[a][s][0] >= phi.lo[a] && coord[a][s][1] <= phi.hi[a];
  if (inside) {
    std::array<std::array<std::array<int, 2>, 2>, Dim> offset;
    int stride = 1;
    for (int a = 0; a < Dim; ++a) {
      for (int s = 0; s < 2; ++s)
        offset[a][s] = {(coord[a][s][0] - phi.lo[a]) * stride,
                        (coord[a][s][1] - phi.lo[a]) * stride};
      stride *= phi.hi[a] - phi.lo[a] + 1;
    }
    for (int sub = 0; sub < kCorners; ++sub)
      for (int k = 0; k < kCorners; ++k) {
        int index = 0;
        for (int a = 0; a < Dim; ++a) index += offset[a][(sub >> a) & 1][(k >> a) & 1];
        const double v = (*phi.values)[index];
        corners[sub][k] = v;
        negatives += v < 0.0;
      }
  } else {
    for (int sub = 0; sub < kCorners; ++sub)
      for (int k = 0; k < kCorners; ++k) {
        VecI<Dim> p;
        for (int a = 0; a < Dim; ++a) p[a] = coord[a][(sub >> a) & 1][(k >> a) & 1];
        const double v = phi(p);
        corners[sub][k] = v;
        negatives += v < 0.0;
      }
  }
  return sub_cubes_negative_fraction<Dim>(corners, negatives);
}

/// body_face_fractions of a bounded body whose lattice phi is read through phi(coordinate)
/// (a part of PartsUnionPhi): the same faces, the same values.
///
/// `near` receives the faces visited (every other face is 0). With `zero_all` false, w must
/// already be 0 on every face but those (the caller zeroed its previous list).
template <int Dim, class Phi>
void body_face_fractions_at(const MacGrid<Dim>& grid, const Phi& phi, const Box<Dim>& box,
                            VectorX& w, bool zero_all, std::vector<int>& near) {
  if (w.size() != grid.num_faces()) {
    // (huge21) fresh storage: its zeros from the kernel, the pages outside the body's faces
    // never written (core/huge_pages.hpp)
    resize_to_released_zeros(w, grid.num_faces());
    zero_all = false;
  }
  if (zero_all) w.setZero();
  faces_near_box<Dim>(grid, box, near);
  face_fractions_of_cubes<Dim>(grid, near, w, [&](const VecI<Dim>& lower) {
    return cube_negative_fraction_at<Dim>(grid, lower, phi);
  });
}


/// Whether every lattice point next to a negative point of `phi` (the 3^Dim points around it,
/// clamped to the lattice: every corner of a lattice cell with a negative corner) holds a value
/// of at most `far` (NaN fails), the negative points lying in the inclusive box [neg_lo,
/// neg_hi]. Then at every corner of a lattice cell where phi changes sign, phi is below a moving
/// body's far value (> far outside its box), so the union's value there is phi's. The same
/// answer for any thread count.
template <int Dim>
bool corners_of_negative_cells_within(const SampleLattice<Dim>& lattice, const VectorX& phi,
                                      const VecI<Dim>& neg_lo, const VecI<Dim>& neg_hi,
                                      double far) {
  if ((neg_lo.array() > neg_hi.array()).any()) return true;
  const VecI<Dim> box_dims = neg_hi - neg_lo + VecI<Dim>::Ones();
  VecI<Dim> row_dims = box_dims;
  row_dims[0] = 1;
  const int rows = row_dims.prod();
  int failed = 0;
#pragma omp parallel for schedule(static) num_threads(team_threads(box_dims.prod())) reduction(|| : failed)
  for (int q = 0; q < rows; ++q) {
    if (failed) continue;
    VecI<Dim> c = neg_lo + lattice_coord<Dim>(q, row_dims);
    for (int x = neg_lo[0]; x <= neg_hi[0] && !failed; ++x) {
      c[0] = x;
      if (!(phi[lattice.index(c)] < 0.0)) continue;
      VecI<Dim> lo, hi;
      for (int a = 0; a < Dim; ++a) {
        lo[a] = std::max(c[a] - 1, 0);
        hi[a] = std::min(c[a] + 1, lattice.dims[a] - 1);
      }
      for_range<Dim>(lo, hi, [&](const VecI<Dim>& n) {
        if (!(phi[lattice.index(n)] <= far)) failed = 1;
      });
    }
  }
  return !failed;
}

/// W_F^s with the union of the solids kept per body (SolidWeightsScratch::union_in_parts, the
/// W_F^s paragraph): at most one body never moves (`fixed_body`, -1 none), `part_of` gives each
/// moving body's part of scratch.union_parts. Writes w.fluid_stress with the values of
/// stress_fluid_weights of the dense union.
template <int Dim>
void stress_weights_in_parts(const MacGrid<Dim>& grid, const SampleLattice<Dim>& lattice,
                             const std::vector<CouplingBody<Dim>>& bodies, int fixed_body,
                             const std::vector<int>& part_of,
                             const std::array<BoundaryType, 2 * Dim>& boundary, double far,
                             SolidWeights<Dim>& w, SolidWeightsScratch<Dim>& scratch) {
  const StressGrid<Dim> stress(grid);
  const int ns = stress.num_dofs();
  const PartsUnionPhi<Dim>& parts = scratch.union_parts;
  std::vector<char> fixed_flags(bodies.size(), 0);
  for (std::size_t i = 0; i < bodies.size(); ++i)
    fixed_flags[i] = i < scratch.fixed.size() && scratch.fixed[i];
  const bool was_kept = scratch.kept_stress;
  scratch.kept_stress = false;
  bool within = true;
  if (fixed_body >= 0) {
    char& test = scratch.fixed_stress_test[fixed_body];
    if (test == 0)
      test = corners_of_negative_cells_within<Dim>(lattice, scratch.fixed_phi[fixed_body],
                                                   scratch.fixed_neg_lo[fixed_body],
                                                   scratch.fixed_neg_hi[fixed_body], far)
                 ? 1
                 : 2;
    within = test == 1;
  }
  if (!within) {
    // the dense union from its parts (the same bits), then W_F^s from it as without parts
    VectorX& union_phi = w.lattice_phi;
    if (union_phi.size() != lattice.size()) union_phi.resize(lattice.size());
    VecI<Dim> lo, hi;
    parts.negative_box(lo, hi);
    for_each_lattice_point_in_box<Dim>(lattice, VecI<Dim>::Zero(),
                                       lattice.dims - VecI<Dim>::Ones(),
                                       [&](int k) { union_phi[k] = parts(k); });
    classify_lattice_cells_in_box(grid, lattice, union_phi, lo, hi, scratch.signs);
    stress_fluid_weights(stress, lattice, union_phi, scratch.signs, boundary, w.fluid_stress);
    return;
  }
  const bool incremental = was_kept && w.fluid_stress.size() == ns &&
                           w.fluid_stress.data() == scratch.kept_fluid_stress &&
                           scratch.kept_boundary == boundary &&
                           scratch.kept_stress_fixed == fixed_flags &&
                           scratch.stress_near.size() == bodies.size();
  scratch.stress_near.resize(bodies.size());
  // the fixed body's fraction of the control volume with lower lattice corner `lower` (0 without
  // a fixed body): lattice_cube_negative_fraction, the value stress_fluid_weights' classified
  // pass gives
  const VectorX* fixed_phi = fixed_body >= 0 ? &scratch.fixed_phi[fixed_body] : nullptr;
  if (incremental) {
    // the last call's DOFs near a moving body get the fixed body's value again (those near a
    // moving body in this call are made below)
    for (std::size_t i = 0; i < bodies.size(); ++i) {
      const std::vector<int>& list = scratch.stress_near[i];
#pragma omp parallel for schedule(static) num_threads(team_threads(static_cast<int>(list.size())))
      for (int n = 0; n < static_cast<int>(list.size()); ++n) {
        const int d = list[n];
        const auto [k, c] = stress.coord(d);
        const double fraction =
            fixed_phi ? lattice_cube_negative_fraction<Dim>(
                            grid, lattice, stress_control_volume_lower<Dim>(stress, d), *fixed_phi)
                      : 0.0;
        w.fluid_stress[d] = stress_fluid_weight<Dim>(stress, boundary, k, c, fraction);
      }
    }
  } else if (fixed_phi) {
    // the fixed body's W_F^s everywhere (its classes in the box of its negative points)
    classify_lattice_cells_in_box(grid, lattice, *fixed_phi, scratch.fixed_neg_lo[fixed_body],
                                  scratch.fixed_neg_hi[fixed_body], scratch.signs);
    stress_fluid_weights(stress, lattice, *fixed_phi, scratch.signs, boundary, w.fluid_stress);
  } else {
    // no fixed body: no solid outside the moving bodies' boxes (fraction 0)
    LatticeSigns<Dim> none;
    none.cells = 2 * grid.cells();
    stress_fluid_weights(stress, lattice, VectorX(), none, boundary, w.fluid_stress);
  }
  // the DOFs whose control volume (lattice points 2 c + o .. 2 c + o + 2, o = 2 shift - 1;
  // mirrored at walls into the same range) reaches a moving body's box: the union read there
  for (std::size_t i = 0; i < bodies.size(); ++i) {
    std::vector<int>& list = scratch.stress_near[i];
    list.clear();
    if (part_of[i] < 0) continue;
    VecI<Dim> lo, hi;
    parts.boxed_values(part_of[i], lo, hi);
    if ((lo.array() > hi.array()).any()) continue;
    // the union's values in the box grown by two points (every corner such a control volume
    // reads, off periodic axes), read directly by the fractions
    VecI<Dim> ulo, uhi;
    for (int a = 0; a < Dim; ++a) {
      ulo[a] = std::max(lo[a] - 2, 0);
      uhi[a] = std::min(hi[a] + 2, lattice.dims[a] - 1);
    }
    const VecI<Dim> udims = uhi - ulo + VecI<Dim>::Ones();
    VectorX& values = scratch.stress_union;
    values.resize(udims.prod());
    {
      VecI<Dim> row_dims = udims;
      row_dims[0] = 1;
      const int rows = row_dims.prod();
#pragma omp parallel for schedule(static) num_threads(team_threads(udims.prod()))
      for (int q = 0; q < rows; ++q) {
        VecI<Dim> c = ulo + lattice_coord<Dim>(q, row_dims);
        double* o = values.data() + static_cast<std::size_t>(q) * udims[0];
        for (int x = 0; x < udims[0]; ++x) {
          c[0] = ulo[0] + x;
          o[x] = parts.at(c);
        }
      }
    }
    for (int k = 0; k < StressGrid<Dim>::num_components(); ++k) {
      const Vec<Dim> shift = StressGrid<Dim>::shift(k);
      const VecI<Dim>& dims = stress.dims(k);
      VecI<Dim> from, to;
      bool any = true;
      for (int a = 0; a < Dim; ++a) {
        from[a] = 0;
        to[a] = dims[a] - 1;
        if (grid.periodic(a)) continue;
        const int o = static_cast<int>(2.0 * shift[a]) - 1;
        // 2 c + o + 2 >= lo and 2 c + o <= hi
        const int need = lo[a] - 2 - o;
        from[a] = std::max(from[a], need >= 0 ? (need + 1) / 2 : -((-need) / 2));
        const int top = hi[a] - o;
        to[a] = std::min(to[a], top >= 0 ? top / 2 : -((1 - top) / 2));
        any = any && from[a] <= to[a];
      }
      if (any) for_range<Dim>(from, to, [&](const VecI<Dim>& c) { list.push_back(stress.index(k, c)); });
    }
    struct UnionPhi {
      const PartsUnionPhi<Dim>* parts;
      const VectorX* values;
      VecI<Dim> lo, hi;
      double operator()(const VecI<Dim>& c) const { return parts->at(c); }
    };
    const UnionPhi phi{&parts, &values, ulo, uhi};
#pragma omp parallel for schedule(static) num_threads(team_threads(static_cast<int>(list.size())))
    for (int n = 0; n < static_cast<int>(list.size()); ++n) {
      const int d = list[n];
      const auto [k, c] = stress.coord(d);
      const double fraction = cube_negative_fraction_at<Dim>(
          grid, stress_control_volume_lower<Dim>(stress, d), phi);
      w.fluid_stress[d] = stress_fluid_weight<Dim>(stress, boundary, k, c, fraction);
    }
  }
  scratch.kept_stress = true;
  scratch.kept_fluid_stress = w.fluid_stress.data();
  scratch.kept_boundary = boundary;
  scratch.kept_stress_fixed = fixed_flags;
}
}  // namespace

template <int Dim>
std::vector<CouplingBody<Dim>> coupling_bodies(const std::vector<RigidBody<Dim>>& bodies) {
  std::vector<CouplingBody<Dim>> out;
  out.reserve(bodies.size());
  for (const RigidBody<Dim>& body : bodies)
    out.push_back(CouplingBody<Dim>{body.posed_shape(), body.position, body.is_dynamic(), body.period()});
  return out;
}

template <int Dim>
void solid_weights(const MacGrid<Dim>& grid, const std::vector<CouplingBody<Dim>>& bodies,
                   const std::vector<ShapePtr<Dim>>& static_solids,
                   const std::array<BoundaryType, 2 * Dim>& boundary, double shrink_in_metres,
                   SolidWeights<Dim>& w, SolidWeightsScratch<Dim>& scratch) {
  const SampleLattice<Dim> lattice = half_lattice(grid);
  const int nf = grid.num_faces();
  // (kern25) the bodies whose W_S^u storage is made in this call (zeros from the kernel), for
  // the wall faces' first touch below
  std::vector<char> body_face_fresh(bodies.size(), 0);
  for (std::size_t i = 0; i < bodies.size() && i < w.body_face.size(); ++i)
    body_face_fresh[i] = w.body_face[i].size() != nf;
  for (std::size_t i = w.body_face.size(); i < bodies.size(); ++i) body_face_fresh[i] = 1;

  // raw fractions: every body on its own, the static solids as one union (section 4.4.6 shrink);
  // w.lattice_phi becomes the union of all solids
  VectorX& union_phi = w.lattice_phi;
  const double far = 2.0 * grid.dx();
  // the box of lattice points outside which the union is nowhere negative, while every part has
  // one (bounded bodies, no static solid): the union's classes are then made in that box only
  bool union_box = static_solids.empty() && far + shrink_in_metres >= 0.0;
  VecI<Dim> union_lo = lattice.dims, union_hi = -VecI<Dim>::Ones();
  // whether union_phi holds the union of the parts so far; without static solids the first
  // body writes it directly (min(+infinity, phi) = phi: the same values without the +infinity
  // fill and a pass of min)
  bool have_union = false;
  // static_face and solid_face kept (else W_S^u's static share is 0 off the walls)
  const bool parts = scratch.parts || !static_solids.empty();
  if (static_solids.empty()) {
    // phi is +infinity everywhere: no fraction anywhere
    if (parts)
      w.static_face.setZero(nf);
    else
      w.static_face = VectorX();
  } else {
    solid_phi_on_lattice<Dim>(grid, lattice, static_solids, shrink_in_metres, union_phi);
    have_union = true;
    classify_lattice_cells(grid, lattice, union_phi, scratch.signs);
    face_negative_fractions(grid, lattice, union_phi, scratch.signs, w.static_face);
  }
  w.body_face.resize(bodies.size());
  scratch.fixed_phi.resize(bodies.size());
  scratch.fixed_face.resize(bodies.size());
  scratch.fixed_neg_lo.resize(bodies.size());
  scratch.fixed_neg_hi.resize(bodies.size());
  scratch.fixed_neg_known.resize(bodies.size(), 0);
  // the union kept per part (issue 20): the bodies that never move by their kept phi, the
  // others by their values in their box; no lattice-sized pass per call
  // (with W_F^s at most one body that never moves: stress_weights_in_parts)
  bool in_parts = scratch.union_in_parts && static_solids.empty() &&
                  shrink_in_metres >= 0.0 && !bodies.empty();
  int fixed_body = -1, fixed_count = 0;
  for (std::size_t i = 0; i < bodies.size() && in_parts; ++i) {
    const bool fixed = i < scratch.fixed.size() && scratch.fixed[i];
    const Box<Dim> box = bodies[i].shape->bounds();
    if (!fixed && (box.isEmpty() || !box.min().allFinite() || !box.max().allFinite()))
      in_parts = false;
    if (fixed) {
      fixed_body = static_cast<int>(i);
      ++fixed_count;
    }
  }
  if (scratch.stress && fixed_count > 1) in_parts = false;
  scratch.fixed_stress_test.resize(bodies.size(), 0);
  std::vector<int> part_of(bodies.size(), -1);
  scratch.union_parts.clear();
  // The faces' weights of the last call kept (the same bodies, every output where this call
  // left it: its buffers, not reallocated): only the faces near a moving body, now or in the
  // last call, are visited below; every other face keeps the fixed bodies' weights of the last
  // call, which are those of this call there (no moving body's fraction reaches it). The
  // caller that keeps the outputs must not write into them (Simulation: it reads them only).
  bool incremental = in_parts && scratch.kept && !parts && w.fluid_face.size() == nf &&
                     w.fluid_face.data() == scratch.kept_fluid_face &&
                     scratch.kept_fixed.size() == bodies.size() &&
                     scratch.near.size() == bodies.size() &&
                     scratch.kept_body_face.size() == bodies.size();
  for (std::size_t i = 0; i < bodies.size() && incremental; ++i) {
    const bool fixed = i < scratch.fixed.size() && scratch.fixed[i];
    incremental = w.body_face[i].size() == nf &&
                  w.body_face[i].data() == scratch.kept_body_face[i] &&
                  scratch.kept_fixed[i] == static_cast<char>(fixed) &&
                  (!fixed || scratch.fixed_face[i].size() == nf);
  }
  scratch.kept = false;
  // the faces whose weights are made again (incremental: the moving bodies' faces of the last
  // call and of this one, each once: scratch.face_mark)
  std::vector<int>& touched = scratch.touched;
  touched.clear();
  // (made at the first call that may keep its outputs, not at the first incremental one: the
  // simulation's first call is its set-up, so this face-sized buffer, kept across steps, is
  // placed among the set-up's blocks, not in the hole that the first step's release of a
  // lattice-sized vector leaves in the heap, where it kept the next lattice-sized vector from
  // reusing that hole: 541 MB more peak at the paper's 256x128x256 grid, docs/benchmarks.md)
  if (in_parts && !parts && scratch.face_mark.size() != static_cast<std::size_t>(nf))
    assign_resident(scratch.face_mark, static_cast<std::size_t>(nf),
                    static_cast<unsigned char>(0));  // (resident in one call: kern25)
  const auto touch = [&](int f) {
    if (scratch.face_mark[f]) return;
    scratch.face_mark[f] = 1;
    touched.push_back(f);
  };
  scratch.near.resize(bodies.size());
  if (incremental)
    for (std::size_t i = 0; i < bodies.size(); ++i) {
      const bool fixed = i < scratch.fixed.size() && scratch.fixed[i];
      if (fixed) continue;
      for (const int f : scratch.near[i]) {
        w.body_face[i][f] = 0.0;
        touch(f);
      }
    }
  if (in_parts) {
    scratch.union_parts.begin(lattice, shrink_in_metres);
    for (std::size_t i = 0; i < bodies.size(); ++i) {
      const CouplingBody<Dim>& body = bodies[i];
      const bool fixed = i < scratch.fixed.size() && scratch.fixed[i];
      if (fixed) {
        if (scratch.fixed_phi[i].size() != lattice.size() || scratch.fixed_face[i].size() != nf) {
          // the first call: the body's lattice phi, its fractions and its negative points, kept
          body_phi_on_lattice<Dim>(lattice, *body.shape, shrink_in_metres, far,
                                   scratch.fixed_phi[i]);
          body_face_fractions<Dim>(grid, lattice, scratch.fixed_phi[i], body.shape->bounds(),
                                   scratch.fixed_face[i]);
          scratch.fixed_neg_known[i] = 0;
          scratch.fixed_stress_test[i] = 0;
        }
        if (!scratch.fixed_neg_known[i]) {
          const VectorX& phi = scratch.fixed_phi[i];
          VecI<Dim> lo = VecI<Dim>::Zero(), hi = lattice.dims - VecI<Dim>::Ones();
          if (!body_phi_negative_box<Dim>(lattice, *body.shape, far, lo, hi)) {
            lo = VecI<Dim>::Zero();
            hi = lattice.dims - VecI<Dim>::Ones();
          }
          negative_points<Dim>(lo, hi, [&](const VecI<Dim>& c) { return phi[lattice.index(c)]; },
                               scratch.fixed_neg_lo[i], scratch.fixed_neg_hi[i]);
          scratch.fixed_neg_known[i] = 1;
        }
        if (!incremental) w.body_face[i] = scratch.fixed_face[i];  // (else below, where touched)
        scratch.near[i].clear();
        scratch.union_parts.add_dense(&scratch.fixed_phi[i], scratch.fixed_neg_lo[i],
                                      scratch.fixed_neg_hi[i]);
        continue;
      }
      const int part = scratch.union_parts.num_parts();
      part_of[i] = part;
      VecI<Dim> lo, hi;
      scratch.union_parts.add_boxed(body.shape->bounds(), far, lo, hi);
      VectorX& values = scratch.union_parts.boxed_values(part);
      body_phi_in_box<Dim>(lattice, *body.shape, shrink_in_metres, far, lo, hi, values);
      const VecI<Dim> box_dims = hi - lo + VecI<Dim>::Ones();
      VecI<Dim> neg_lo, neg_hi;
      negative_points<Dim>(lo, hi,
                           [&](const VecI<Dim>& c) {
                             return values[lattice_index<Dim>(c - lo, box_dims)];
                           },
                           neg_lo, neg_hi);
      scratch.union_parts.set_negative_box(part, neg_lo, neg_hi);
      // the fractions read the box's values directly (part_at outside it: the same values)
      struct BoxedPhi {
        const PartsUnionPhi<Dim>* parts;
        int part;
        const VectorX* values;
        VecI<Dim> lo, hi;
        double operator()(const VecI<Dim>& c) const { return parts->part_at(part, c); }
      };
      const BoxedPhi phi{&scratch.union_parts, part, &values, lo, hi};
      body_face_fractions_at<Dim>(grid, phi, body.shape->bounds(), w.body_face[i], !incremental,
                                  scratch.near[i]);
      if (incremental)
        for (const int f : scratch.near[i]) touch(f);
    }
    scratch.union_parts.finish();
    have_union = true;
    if (incremental) {
      // the fixed bodies' raw fractions where the weights are made again
      for (std::size_t i = 0; i < bodies.size(); ++i)
        if (i < scratch.fixed.size() && scratch.fixed[i])
          for (const int f : touched) w.body_face[i][f] = scratch.fixed_face[i][f];
      for (const int f : touched) scratch.face_mark[f] = 0;
    }
  }
  for (std::size_t i = 0; i < bodies.size() && !in_parts; ++i) {
    const CouplingBody<Dim>& body = bodies[i];
    if (union_box) {
      VecI<Dim> lo, hi;
      if (body_phi_negative_box<Dim>(lattice, *body.shape, far, lo, hi)) {
        union_lo = union_lo.cwiseMin(lo);
        union_hi = union_hi.cwiseMax(hi);
      } else {
        union_box = false;
      }
    }
    const bool fixed = i < scratch.fixed.size() && scratch.fixed[i];
    if (fixed && scratch.fixed_phi[i].size() == lattice.size() &&
        scratch.fixed_face[i].size() == nf) {
      // a body that never moves: its values of the first call
      w.body_face[i] = scratch.fixed_face[i];
      if (have_union)
        union_phi = union_phi.cwiseMin(scratch.fixed_phi[i]);
      else
        union_phi = scratch.fixed_phi[i];
      have_union = true;
      continue;
    }
    VectorX& body_phi = have_union ? scratch.body_phi : union_phi;
    body_phi_on_lattice<Dim>(lattice, *body.shape, shrink_in_metres, far, body_phi);
    body_face_fractions<Dim>(grid, lattice, body_phi, body.shape->bounds(), w.body_face[i]);
    if (fixed) {
      scratch.fixed_phi[i] = body_phi;
      scratch.fixed_face[i] = w.body_face[i];
      scratch.fixed_neg_known[i] = 0;
      scratch.fixed_stress_test[i] = 0;
    }
    if (have_union) union_phi = union_phi.cwiseMin(body_phi);
    have_union = true;
  }
  // no solid at all: +infinity everywhere
  if (!have_union && !in_parts) solid_phi_on_lattice<Dim>(grid, lattice, static_solids, shrink_in_metres, union_phi);

  // the body's lattice phi is not needed any more: its memory goes back to the heap for the
  // solve (a lattice-sized vector, 541 MB at the paper's 256x128x256 grid)
  scratch.body_phi = VectorX();

  // overlap rule: scale every contribution by 1/sum where the sum exceeds 1 (the sum in the
  // order static, body 0, body 1, ..., formed per face instead of as a face-sized vector); then
  // W_S^u as the sum of its parts (in the same order), capped at 1, and W_F^u = 1 - W_S^u. A face
  // whose parts were scaled is solid: W_S^u = 1 and W_F^u = 0 exactly. (The scaled parts add up
  // to 1 only to round-off: 1 - 1.1e-16 left W_F^u = 1.1e-16 on faces two touching bodies
  // cover, so a cell inside the overlap with liquid extended into it became a pressure DOF
  // coupled to nothing but the two bodies, whose push apart its pressure and their contact's
  // lambda then shared without bound: boat-on-waves-2d's coupled solve stalled there,
  // docs/particles.md, "energy15".) One pass over the faces; the wall faces are set below.
  if (!parts)
    w.solid_face = VectorX();
  else if (w.solid_face.size() != nf)
    resize_resident(w.solid_face, nf);
  // (written whole below: fresh storage made resident in one call, kern25, core/first_touch.hpp)
  if (w.fluid_face.size() != nf) resize_resident(w.fluid_face, nf);
  // (band23) A first (not incremental) call with the union in parts and no body that never
  // moves: each body's W_S^u is +0 outside its near faces (fresh zeros from the kernel or zeroed
  // whole, body_face_fractions_at), and there (no static part) the pass below gives sum = 0,
  // solid = 0, W_F^u = 1 - 0 = 1 exactly without a scale. So W_F^u = 1 is written on every face
  // and the pass visits the near faces only (each once): the same bits, and the bodies' W_S^u is
  // not read beyond their faces (its pages there stay unprovided: about 49k faults of the
  // kernel's zero page for the bowl at Fig. 2's paper grid)
  bool near_only = !incremental && in_parts && !parts;
  for (std::size_t i = 0; i < bodies.size() && near_only; ++i)
    near_only = !(i < scratch.fixed.size() && scratch.fixed[i]);
  if (near_only) {
    for (std::size_t i = 0; i < bodies.size(); ++i)
      for (const int f : scratch.near[i]) touch(f);
    for (const int f : touched) scratch.face_mark[f] = 0;
    double* fluid = w.fluid_face.data();
#pragma omp parallel for schedule(static) num_threads(team_threads(nf))
    for (int f = 0; f < nf; ++f) fluid[f] = 1.0;
  }
  // every face, or (incremental, near_only) the touched faces only
  const bool listed = incremental || near_only;
  const int passes = listed ? static_cast<int>(touched.size()) : nf;
#pragma omp parallel for schedule(static) num_threads(team_threads(passes))
  for (int n = 0; n < passes; ++n) {
    const int f = listed ? touched[n] : n;
    double static_part = parts ? w.static_face[f] : 0.0;
    double sum = static_part;
    for (const VectorX& body : w.body_face) sum += body[f];
    if (sum > 1.0) {
      const double scale = 1.0 / sum;
      static_part *= scale;
      for (VectorX& body : w.body_face) body[f] *= scale;
    }
    double solid = static_part;
    for (const VectorX& body : w.body_face) solid += body[f];
    solid = sum > 1.0 ? 1.0 : std::min(solid, 1.0);
    if (parts) {
      w.static_face[f] = static_part;
      w.solid_face[f] = solid;
    }
    w.fluid_face[f] = 1.0 - solid;
  }

  // wall faces belong to the wall (the two boundary layers of faces normal to each wall axis):
  // W_S^u = 1 (1 + 0 + ... capped), W_F^u = 0
  // (kern25) On axis 0 the wall faces are the first and the last face of every row of that
  // axis's faces: when a row is at most a page long, the writes below touch every page of a
  // fresh W_S^u's axis-0 block, one page-fault exception each (16k for the bowl at Fig. 2's
  // paper grid). Those pages are made resident in one call instead (core/first_touch.hpp); the
  // values do not change.
  if (!grid.periodic(0) &&
      (boundary[0] == BoundaryType::wall || boundary[1] == BoundaryType::wall)) {
    const long row_bytes = static_cast<long>(sizeof(double)) * grid.face_dims(0)[0];
    if (row_bytes <= 4096)
      for (std::size_t i = 0; i < bodies.size(); ++i)
        if (body_face_fresh[i] && w.body_face[i].size() == nf)
          populate_for_writing(w.body_face[i].data() + grid.face_offset(0),
                               sizeof(double) * static_cast<std::size_t>(grid.face_dims(0).prod()));
  }
  for (int axis = 0; axis < Dim; ++axis) {
    if (grid.periodic(axis)) continue;
    for (int side = 0; side < 2; ++side) {
      if (boundary[2 * axis + side] != BoundaryType::wall) continue;
      VecI<Dim> lo = VecI<Dim>::Zero(), hi = grid.face_dims(axis) - VecI<Dim>::Ones();
      lo[axis] = hi[axis] = side == 0 ? 0 : grid.cells()[axis];
      for_range<Dim>(lo, hi, [&](const VecI<Dim>& coord) {
        const int f = grid.face_index(axis, coord);
        for (VectorX& body : w.body_face) body[f] = 0.0;
        if (parts) {
          w.static_face[f] = 1.0;
          w.solid_face[f] = 1.0;
        }
        w.fluid_face[f] = 0.0;
      });
    }
  }

  if (in_parts && !parts) {
    // the outputs this call leaves, for the next call's incremental pass
    scratch.kept = true;
    scratch.kept_fluid_face = w.fluid_face.data();
    scratch.kept_body_face.resize(bodies.size());
    scratch.kept_fixed.resize(bodies.size());
    for (std::size_t i = 0; i < bodies.size(); ++i) {
      scratch.kept_body_face[i] = w.body_face[i].data();
      scratch.kept_fixed[i] = i < scratch.fixed.size() && scratch.fixed[i];
    }
  }
  if (in_parts) {
    // W_F^s from the parts (its classes, if any, are made in scratch.signs and dropped below)
    if (scratch.stress)
      stress_weights_in_parts<Dim>(grid, lattice, bodies, fixed_body, part_of, boundary, far, w,
                                   scratch);
    else
      w.fluid_stress = VectorX();
    // no classes: the box of the lattice cells with a negative corner (the cells l with
    // l <= p <= l + 1 for a negative point p), as classify_lattice_cells_in_box finds it
    LatticeSigns<Dim>& signs = scratch.signs;
    signs.cells = 2 * grid.cells();
    signs.written_lo = VecI<Dim>::Zero();
    signs.written_hi = -VecI<Dim>::Ones();
    signs.cls.clear();
    signs.row_start.clear();
    signs.mixed_x.clear();
    signs.mixed_fraction.clear();
    signs.phi_data = nullptr;
    signs.phi_size = -1;
    VecI<Dim> lo, hi;
    scratch.union_parts.negative_box(lo, hi);
    if ((lo.array() <= hi.array()).all()) {
      for (int a = 0; a < Dim; ++a) {
        lo[a] = std::max(lo[a] - 1, 0);
        hi[a] = std::min(hi[a], signs.cells[a] - 1);
      }
      signs.lo = lo;
      signs.hi = hi;
    } else {
      signs.lo = signs.cells;
      signs.hi = -VecI<Dim>::Ones();
    }
    return;
  }
  scratch.kept_stress = false;
  // W_F^s from the union of all solids (its classes in the bodies' box when there is one)
  if (union_box)
    classify_lattice_cells_in_box(grid, lattice, union_phi, union_lo, union_hi, scratch.signs);
  else
    classify_lattice_cells(grid, lattice, union_phi, scratch.signs);
  if (scratch.stress)
    stress_fluid_weights(StressGrid<Dim>(grid), lattice, union_phi, scratch.signs, boundary,
                         w.fluid_stress);
  else
    w.fluid_stress = VectorX();
}

template <int Dim>
SolidWeights<Dim> solid_weights(const MacGrid<Dim>& grid,
                                const std::vector<CouplingBody<Dim>>& bodies,
                                const std::vector<ShapePtr<Dim>>& static_solids,
                                const std::array<BoundaryType, 2 * Dim>& boundary,
                                double shrink_in_metres) {
  SolidWeights<Dim> w;
  SolidWeightsScratch<Dim> scratch;
  solid_weights(grid, bodies, static_solids, boundary, shrink_in_metres, w, scratch);
  return w;
}

template <int Dim>
std::vector<int> body_rows(const std::vector<CouplingBody<Dim>>& bodies, BodyGroup group,
                           int* count) {
  std::vector<int> rows(bodies.size(), -1);
  int next = 0;
  for (std::size_t i = 0; i < bodies.size(); ++i) {
    if (!in_group(bodies[i], group)) continue;
    rows[i] = next;
    next += kBodyDofs<Dim>;
  }
  if (count) *count = next;
  return rows;
}

template <int Dim>
SparseMatrix aggregation_matrix(const MacGrid<Dim>& grid,
                                const std::vector<CouplingBody<Dim>>& bodies,
                                const SolidWeights<Dim>& weights, BodyGroup group) {
  int num_rows = 0;
  const std::vector<int> rows = body_rows(bodies, group, &num_rows);
  const double volume = grid.cell_volume();
  std::vector<Triplet> triplets;
  for (std::size_t i = 0; i < bodies.size(); ++i) {
    if (rows[i] < 0) continue;
    for (int f = 0; f < grid.num_faces(); ++f) {
      const double w = weights.body_face[i][f];
      if (w <= 0.0 || weights.solid_face[f] <= 0.0) continue;
      // the body's share of the face's solid volume
      const double share = w / weights.solid_face[f];
      const auto [axis, coord] = grid.face_coord(f);
      const Vec<Dim> e = Vec<Dim>::Unit(axis);
      const Vec<Dim> r = bodies[i].arm(grid.face_center(axis, coord));
      const AngularVec<Dim> torque = moment<Dim>(r, e);
      triplets.emplace_back(rows[i] + axis, f, volume * share);
      for (int k = 0; k < kAngularDofs<Dim>; ++k)
        if (torque[k] != 0.0) triplets.emplace_back(rows[i] + Dim + k, f, volume * share * torque[k]);
    }
  }
  SparseMatrix q(num_rows, grid.num_faces());
  q.setFromTriplets(triplets.begin(), triplets.end());
  return q;
}

template <int Dim>
std::vector<std::pair<int, double>> deformation_rate_row(const StressGrid<Dim>& stress, int dof,
                                                         bool* complete) {
  const MacGrid<Dim>& grid = stress.grid();
  const auto [k, c] = stress.coord(dof);
  const auto [a, b] = StressGrid<Dim>::component_axes(k);
  std::vector<std::pair<int, double>> row;
  bool all = true;
  auto add = [&](int axis, const VecI<Dim>& f, double coef) {
    const int index = grid.face_index_or_outside(axis, f);
    if (index < 0) {
      all = false;
      return;
    }
    row.emplace_back(index, coef);
  };
  const double inv_dx = 1.0 / grid.dx();
  if (a == b) {
    // (D u)_aa = (u_a(c + e_a) - u_a(c)) / dx
    add(a, c, -inv_dx);
    add(a, c + unit_offset<Dim>(a), inv_dx);
  } else {
    // (D u)_ab = 1/2 [(u_a(n) - u_a(n - e_b)) + (u_b(n) - u_b(n - e_a))] / dx
    const double h = 0.5 * inv_dx;
    add(a, c, h);
    add(a, c - unit_offset<Dim>(b), -h);
    add(b, c, h);
    add(b, c - unit_offset<Dim>(a), -h);
  }
  if (complete) *complete = all;
  return row;
}

template <int Dim>
BodyCouplingOperator<Dim>::BodyCouplingOperator(const MacGrid<Dim>& grid,
                                                const std::vector<CouplingBody<Dim>>& bodies,
                                                const SolidWeights<Dim>& weights,
                                                BodyGroup group)
    : BodyCouplingOperator(grid, bodies, weights, group, Columns{}) {}

template <int Dim>
BodyCouplingOperator<Dim>::BodyCouplingOperator(const MacGrid<Dim>& grid,
                                                const std::vector<CouplingBody<Dim>>& bodies,
                                                const SolidWeights<Dim>& weights,
                                                BodyGroup group, const Columns& columns)
    : grid_(grid), stress_(grid), bodies_(bodies), body_face_(weights.body_face) {
  rows_ = body_rows(bodies_, group, &num_rows_);
  surface_cells_.assign(bodies_.size(), {});
  surface_stress_.assign(bodies_.size(), {});
  // the surface: cells and stress DOFs whose column does not cancel, searched within two cells
  // of the body's bounds (face control volumes reach one cell beyond a cell; the shrinkage only
  // moves the surface inward)
  const double margin = 2.0 * grid_.dx();
  for (std::size_t i = 0; i < bodies_.size(); ++i) {
    if (rows_[i] < 0) continue;
    const int body = static_cast<int>(i);
    const Box<Dim> bounds = bodies_[i].shape->bounds();
    Block column;
    const auto [lo, hi] = lattice_range<Dim>(grid_, bounds, Vec<Dim>::Constant(0.5), grid_.cells(), margin);
    if (columns.cells) {
      // the listed cells in the range, in increasing order (the order of the sort below)
      for (const int cell : *columns.cells) {
        const VecI<Dim> c = grid_.cell_coord(cell);
        if ((c.array() < lo.array()).any() || (c.array() > hi.array()).any()) continue;
        if (pressure_column(body, cell, column)) surface_cells_[i].push_back(cell);
      }
    } else {
      for_range<Dim>(lo, hi, [&](const VecI<Dim>& c) {
        const int cell = grid_.cell_index(c);
        if (pressure_column(body, cell, column)) surface_cells_[i].push_back(cell);
      });
      std::sort(surface_cells_[i].begin(), surface_cells_[i].end());
    }
    if (!columns.stress) continue;
    if (columns.stress_dofs) {
      // the listed DOFs in their component's range, in increasing order (the order of the sort
      // below)
      std::array<VecI<Dim>, StressGrid<Dim>::kComponents> slo, shi;
      for (int k = 0; k < StressGrid<Dim>::num_components(); ++k)
        std::tie(slo[k], shi[k]) = lattice_range<Dim>(grid_, bounds, StressGrid<Dim>::shift(k),
                                                      stress_.dims(k), margin);
      for (const int dof : *columns.stress_dofs) {
        const auto [k, c] = stress_.coord(dof);
        if ((c.array() < slo[k].array()).any() || (c.array() > shi[k].array()).any()) continue;
        if (stress_column(body, dof, column)) surface_stress_[i].push_back(dof);
      }
      continue;
    }
    for (int k = 0; k < StressGrid<Dim>::num_components(); ++k) {
      const auto [slo, shi] = lattice_range<Dim>(grid_, bounds, StressGrid<Dim>::shift(k), stress_.dims(k), margin);
      for_range<Dim>(slo, shi, [&](const VecI<Dim>& c) {
        const int dof = stress_.index(k, c);
        if (stress_column(body, dof, column)) surface_stress_[i].push_back(dof);
      });
    }
    std::sort(surface_stress_[i].begin(), surface_stress_[i].end());
  }
}

template <int Dim>
typename BodyCouplingOperator<Dim>::Block BodyCouplingOperator<Dim>::face_block(int body,
                                                                               int face) const {
  Block block = Block::Zero();
  const double w = body_face_[body][face];
  if (w == 0.0) return block;
  const auto [axis, coord] = grid_.face_coord(face);
  const Vec<Dim> e = Vec<Dim>::Unit(axis);
  const Vec<Dim> r = bodies_[body].arm(grid_.face_center(axis, coord));
  const double scale = w * grid_.cell_volume();
  block.template head<Dim>() = scale * e;
  block.template tail<kAngularDofs<Dim>>() = scale * moment<Dim>(r, e);
  return block;
}

template <int Dim>
bool BodyCouplingOperator<Dim>::pressure_column(int body, int cell, Block& column) const {
  const VectorX& w = body_face_[body];
  const VecI<Dim> c = grid_.cell_coord(cell);
  // the 2 Dim faces of the cell: face c (the cell is its plus side, G = +1/dx) and face c + e_a
  // (the cell is its minus side, G = -1/dx)
  std::array<int, 2 * Dim> faces;
  for (int a = 0; a < Dim; ++a) {
    faces[2 * a] = grid_.face_index_or_outside(a, c);
    faces[2 * a + 1] = grid_.face_index_or_outside(a, VecI<Dim>(c + unit_offset<Dim>(a)));
  }
  // cancellation: equal body weight on every face (inside the body or outside it)
  bool uniform = true;
  for (int f : faces) uniform = uniform && w[f] == w[faces[0]];
  if (uniform) return false;
  // column of -Q W_S^u G: -sum_f W_{S,i}(f) dx^Dim [e_a; r_f x e_a] G_fc
  const double inv_dx = 1.0 / grid_.dx();
  column.setZero();
  for (int a = 0; a < Dim; ++a) {
    column -= inv_dx * face_block(body, faces[2 * a]);
    column += inv_dx * face_block(body, faces[2 * a + 1]);
  }
  return true;
}

template <int Dim>
bool BodyCouplingOperator<Dim>::stress_column(int body, int dof, Block& column) const {
  const VectorX& w = body_face_[body];
  bool complete = true;
  const std::vector<std::pair<int, double>> row = deformation_rate_row(stress_, dof, &complete);
  if (row.empty()) return false;
  // cancellation: a complete stencil with equal body weight everywhere
  bool uniform = complete;
  for (const auto& entry : row) uniform = uniform && w[entry.first] == w[row.front().first];
  if (uniform) return false;
  bool any = false;
  for (const auto& entry : row) any = any || w[entry.first] != 0.0;
  if (!any) return false;
  // column of -Q W_S^u D^T M: -M_k sum_f W_{S,i}(f) dx^Dim [e_a; r_f x e_a] D_kf
  const double multiplicity = StressGrid<Dim>::multiplicity(stress_.coord(dof).first);
  column.setZero();
  for (const auto& [face, coef] : row) column -= (multiplicity * coef) * face_block(body, face);
  return true;
}

template <int Dim>
std::vector<typename BodyCouplingOperator<Dim>::SurfaceColumn>
BodyCouplingOperator<Dim>::pressure_columns() const {
  std::vector<SurfaceColumn> out;
  for (std::size_t i = 0; i < bodies_.size(); ++i)
    for (int c : surface_cells_[i]) {
      SurfaceColumn s;
      s.body = static_cast<int>(i);
      s.row = rows_[i];
      s.index = c;
      pressure_column(s.body, c, s.column);
      out.push_back(s);
    }
  return out;
}

template <int Dim>
std::vector<typename BodyCouplingOperator<Dim>::SurfaceColumn>
BodyCouplingOperator<Dim>::stress_columns() const {
  std::vector<SurfaceColumn> out;
  for (std::size_t i = 0; i < bodies_.size(); ++i)
    for (int k : surface_stress_[i]) {
      SurfaceColumn s;
      s.body = static_cast<int>(i);
      s.row = rows_[i];
      s.index = k;
      stress_column(s.body, k, s.column);
      out.push_back(s);
    }
  return out;
}

template <int Dim>
SparseMatrix BodyCouplingOperator<Dim>::pressure_jacobian() const {
  std::vector<Triplet> triplets;
  Block column;
  for (std::size_t i = 0; i < bodies_.size(); ++i)
    for (int c : surface_cells_[i]) {
      pressure_column(static_cast<int>(i), c, column);
      for (int r = 0; r < kBodyDofs<Dim>; ++r)
        if (column[r] != 0.0) triplets.emplace_back(rows_[i] + r, c, column[r]);
    }
  SparseMatrix j(num_rows_, grid_.num_cells());
  j.setFromTriplets(triplets.begin(), triplets.end());
  return j;
}

template <int Dim>
SparseMatrix BodyCouplingOperator<Dim>::stress_jacobian() const {
  std::vector<Triplet> triplets;
  Block column;
  for (std::size_t i = 0; i < bodies_.size(); ++i)
    for (int k : surface_stress_[i]) {
      stress_column(static_cast<int>(i), k, column);
      for (int r = 0; r < kBodyDofs<Dim>; ++r)
        if (column[r] != 0.0) triplets.emplace_back(rows_[i] + r, k, column[r]);
    }
  SparseMatrix j(num_rows_, stress_.num_dofs());
  j.setFromTriplets(triplets.begin(), triplets.end());
  return j;
}

template <int Dim>
VectorX BodyCouplingOperator<Dim>::apply_pressure(const VectorX& p) const {
  VectorX y = VectorX::Zero(num_rows_);
  Block column;
  for (std::size_t i = 0; i < bodies_.size(); ++i)
    for (int c : surface_cells_[i]) {
      pressure_column(static_cast<int>(i), c, column);
      y.template segment<kBodyDofs<Dim>>(rows_[i]) += column * p[c];
    }
  return y;
}

template <int Dim>
VectorX BodyCouplingOperator<Dim>::apply_pressure_transpose(const VectorX& v) const {
  VectorX y = VectorX::Zero(grid_.num_cells());
  Block column;
  for (std::size_t i = 0; i < bodies_.size(); ++i)
    for (int c : surface_cells_[i]) {
      pressure_column(static_cast<int>(i), c, column);
      y[c] += column.dot(v.template segment<kBodyDofs<Dim>>(rows_[i]));
    }
  return y;
}

template <int Dim>
VectorX BodyCouplingOperator<Dim>::apply_stress(const VectorX& tau) const {
  VectorX y = VectorX::Zero(num_rows_);
  Block column;
  for (std::size_t i = 0; i < bodies_.size(); ++i)
    for (int k : surface_stress_[i]) {
      stress_column(static_cast<int>(i), k, column);
      y.template segment<kBodyDofs<Dim>>(rows_[i]) += column * tau[k];
    }
  return y;
}

template <int Dim>
VectorX BodyCouplingOperator<Dim>::apply_stress_transpose(const VectorX& v) const {
  VectorX y = VectorX::Zero(stress_.num_dofs());
  Block column;
  for (std::size_t i = 0; i < bodies_.size(); ++i)
    for (int k : surface_stress_[i]) {
      stress_column(static_cast<int>(i), k, column);
      y[k] += column.dot(v.template segment<kBodyDofs<Dim>>(rows_[i]));
    }
  return y;
}

template <int Dim>
void subtract_body_pressure_rhs(const BodyCouplingOperator<Dim>& op, const MacGrid<Dim>& grid,
                                const VectorX& liquid_cell, const VectorX& v_star,
                                VectorX& b2_cells) {
  // alpha J_p is the J_p of eq. (24)
  const double alpha = 1.0 / grid.cell_volume();
  b2_cells -= alpha * liquid_cell.cwiseProduct(op.apply_pressure_transpose(v_star));
}

template <int Dim>
void subtract_body_stress_rhs(const BodyCouplingOperator<Dim>& op, const MacGrid<Dim>& grid,
                              const VectorX& liquid_stress, const VectorX& v_star,
                              VectorX& b1_full) {
  const double alpha = 1.0 / grid.cell_volume();
  b1_full -= alpha * liquid_stress.cwiseProduct(op.apply_stress_transpose(v_star));
}

template <int Dim>
VectorX group_velocities(const std::vector<RigidBody<Dim>>& bodies, BodyGroup group) {
  std::vector<BodyVec<Dim>> blocks;
  for (const RigidBody<Dim>& body : bodies)
    if (body.is_dynamic() == (group == BodyGroup::two_way))
      blocks.push_back(body.generalized_velocity());
  VectorX v(kBodyDofs<Dim> * static_cast<int>(blocks.size()));
  for (std::size_t i = 0; i < blocks.size(); ++i)
    v.template segment<kBodyDofs<Dim>>(kBodyDofs<Dim> * static_cast<int>(i)) = blocks[i];
  return v;
}

#define MONOLITH_INSTANTIATE(D)                                                                   \
  template std::vector<CouplingBody<D>> coupling_bodies<D>(const std::vector<RigidBody<D>>&);     \
  template SolidWeights<D> solid_weights<D>(const MacGrid<D>&,                                    \
                                            const std::vector<CouplingBody<D>>&,                  \
                                            const std::vector<ShapePtr<D>>&,                      \
                                            const std::array<BoundaryType, 2 * D>&, double);      \
  template void solid_weights<D>(const MacGrid<D>&, const std::vector<CouplingBody<D>>&,          \
                                 const std::vector<ShapePtr<D>>&,                                 \
                                 const std::array<BoundaryType, 2 * D>&, double, SolidWeights<D>&, \
                                 SolidWeightsScratch<D>&);                                        \
  template std::vector<int> body_rows<D>(const std::vector<CouplingBody<D>>&, BodyGroup, int*);   \
  template SparseMatrix aggregation_matrix<D>(const MacGrid<D>&,                                  \
                                              const std::vector<CouplingBody<D>>&,                \
                                              const SolidWeights<D>&, BodyGroup);                 \
  template std::vector<std::pair<int, double>> deformation_rate_row<D>(const StressGrid<D>&, int, \
                                                                       bool*);                    \
  template class BodyCouplingOperator<D>;                                                         \
  template void subtract_body_pressure_rhs<D>(const BodyCouplingOperator<D>&, const MacGrid<D>&,  \
                                              const VectorX&, const VectorX&, VectorX&);          \
  template void subtract_body_stress_rhs<D>(const BodyCouplingOperator<D>&, const MacGrid<D>&,    \
                                            const VectorX&, const VectorX&, VectorX&);            \
  template VectorX group_velocities<D>(const std::vector<RigidBody<D>>&, BodyGroup);

MONOLITH_INSTANTIATE(2)
MONOLITH_INSTANTIATE(3)

#undef MONOLITH_INSTANTIATE

}  // namespace monolith
