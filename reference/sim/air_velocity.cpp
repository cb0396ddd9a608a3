#include "reference/sim/air_velocity.hpp"

#include <omp.h>

#include <algorithm>
#include <utility>

#include "reference/core/parallel.hpp"
#include "reference/grid/box_rows.hpp"
#include "reference/grid/face_neighbour.hpp"
#include "reference/particles/particles.hpp"

namespace monolith {

template <int Dim>
void extrapolate_air_velocity(const MacGrid<Dim>& grid, VectorX& u, std::vector<char>& valid,
                              int layers, const std::array<VecI<Dim>, Dim>* box_lo,
                              const std::array<VecI<Dim>, Dim>* box_hi) {
  const int nf = grid.num_faces();
  valid.resize(nf, 0);
  if (layers <= 0) return;
  // the rows of faces searched: per axis the box grown by one face (on a periodic axis whose
  // grown box would wrap, the whole axis), or every face
  std::vector<std::pair<int, int>> rows;  // (first face, faces in the row)
  long work = nf;
  std::array<VecI<Dim>, Dim> lo{}, hi{};
  if (box_lo != nullptr) {
    lo = *box_lo;
    hi = *box_hi;
    work = 0;
    for (int axis = 0; axis < Dim; ++axis) {
      if ((lo[axis].array() > hi[axis].array()).any()) continue;
      const VecI<Dim> dims = grid.face_dims(axis);
      for (int b = 0; b < Dim; ++b) {
        if (grid.periodic(b) && (lo[axis][b] - 1 < 0 || hi[axis][b] + 1 >= dims[b])) {
          lo[axis][b] = 0;
          hi[axis][b] = dims[b] - 1;
        } else {
          lo[axis][b] = std::max(lo[axis][b] - 1, 0);
          hi[axis][b] = std::min(hi[axis][b] + 1, dims[b] - 1);
        }
      }
      const BoxRows<Dim> box(dims, lo[axis], hi[axis]);
      for (int r = 0; r < box.rows(); ++r)
        rows.push_back({grid.face_index(axis, box.start(r)), box.nx});
      work += static_cast<long>(box.rows()) * box.nx;
    }
  } else {
    rows.push_back({0, nf});
  }
  // the first ring: values written to u (no estimate reads an invalid face's u), flags set
  // after the loop (every estimate reads the flags of entry)
  const int count = static_cast<int>(rows.size());
  const int team = team_threads(work);
  std::vector<std::vector<int>> filled(team);
#pragma omp parallel num_threads(team)
  {
    std::vector<int>& mine = filled[omp_get_thread_num()];
#pragma omp for schedule(static)
    for (int r = 0; r < count; ++r)
      for (int f = rows[r].first; f < rows[r].first + rows[r].second; ++f) {
        if (valid[f] != 0) continue;
        const auto [axis, coord] = grid.face_coord(f);
        const VecI<Dim> dims = grid.face_dims(axis);
        const auto along = [&](int b, int step) {
          return face_along(grid, axis, dims, coord, f, b, step);
        };
        const auto ok = [&](int g) { return g >= 0 && valid[g] != 0; };
        double linear_sum = 0.0, mean_sum = 0.0;
        int linear_count = 0, mean_count = 0;
        for (int b = 0; b < Dim; ++b) {
          const int m1 = along(b, -1), p1 = along(b, 1);
          const bool vm1 = ok(m1), vp1 = ok(p1);
          // extrapolate_velocity's average: every valid neighbour, -1 then +1, axis by axis
          if (vm1) mean_sum += u[m1], ++mean_count;
          if (vp1) mean_sum += u[p1], ++mean_count;
          if (vm1 && vp1) {
            linear_sum += 0.5 * (u[m1] + u[p1]);
            ++linear_count;
          } else if (vm1 || vp1) {
            const int n1 = vm1 ? m1 : p1;
            const int n2 = along(b, vm1 ? -2 : 2);
            if (ok(n2) && n2 != n1) {
              linear_sum += 2.0 * u[n1] - u[n2];
              ++linear_count;
            }
          }
        }
        if (mean_count == 0) continue;
        u[f] = linear_count > 0 ? linear_sum / linear_count : mean_sum / mean_count;
        mine.push_back(f);
      }
  }
  long total = 0;
  for (const auto& list : filled) {
    for (const int f : list) valid[f] = 1;
    total += static_cast<long>(list.size());
  }
  if (layers == 1 || total == 0) return;
  // the further rings: averaging, every valid face now within the grown boxes
  if (box_lo != nullptr) {
    extrapolate_velocity<Dim>(grid, u, valid, layers - 1, lo, hi);
  } else {
    extrapolate_velocity(grid, u, valid, layers - 1);
  }
}

template void extrapolate_air_velocity<2>(const MacGrid<2>&, VectorX&, std::vector<char>&, int,
                                          const std::array<VecI<2>, 2>*,
                                          const std::array<VecI<2>, 2>*);
template void extrapolate_air_velocity<3>(const MacGrid<3>&, VectorX&, std::vector<char>&, int,
                                          const std::array<VecI<3>, 3>*,
                                          const std::array<VecI<3>, 3>*);

}  // namespace monolith
