#include "reference/grid/stress_grid.hpp"

namespace monolith {

namespace {

/// Tensor index pairs of the components, diagonal first (see stress_grid.hpp).
template <int Dim>
struct ComponentTable;
template <>
struct ComponentTable<2> {
  static constexpr int a[3] = {0, 1, 0};
  static constexpr int b[3] = {0, 1, 1};
};
template <>
struct ComponentTable<3> {
  static constexpr int a[6] = {0, 1, 2, 0, 0, 1};
  static constexpr int b[6] = {0, 1, 2, 1, 2, 2};
};
}  // namespace

template <int Dim>
StressGrid<Dim>::StressGrid(const MacGrid<Dim>& grid) : grid_(grid) {
  offset_[0] = 0;
  for (int k = 0; k < kComponents; ++k) {
    // cells along cell-centred axes; cells + 1 along node-aligned axes unless periodic
    const auto [a, b] = component_axes(k);
    VecI<Dim> d = grid_.cells();
    if (a != b) {
      if (!grid_.periodic(a)) d[a] += 1;
      if (!grid_.periodic(b)) d[b] += 1;
    }
    dims_[k] = d;
    offset_[k + 1] = offset_[k] + d.prod();
  }
}

template <int Dim>
std::pair<int, int> StressGrid<Dim>::component_axes(int k) {
  return {ComponentTable<Dim>::a[k], ComponentTable<Dim>::b[k]};
}

template <int Dim>
int StressGrid<Dim>::component(int a, int b) {
  if (a > b) std::swap(a, b);
  for (int k = 0; k < kComponents; ++k)
    if (ComponentTable<Dim>::a[k] == a && ComponentTable<Dim>::b[k] == b) return k;
  return -1;
}

template <int Dim>
Vec<Dim> StressGrid<Dim>::shift(int k) {
  Vec<Dim> s = Vec<Dim>::Constant(0.5);
  const auto [a, b] = component_axes(k);
  if (a != b) {
    s[a] = 0.0;
    s[b] = 0.0;
  }
  return s;
}

template <int Dim>
Vec<Dim> StressGrid<Dim>::position(int k, const VecI<Dim>& c) const {
  return grid_.origin() + (c.template cast<double>() + shift(k)) * grid_.dx();
}

template <int Dim>
bool StressGrid<Dim>::is_boundary(int k, const VecI<Dim>& c) const {
  const auto [a, b] = component_axes(k);
  if (a == b) return false;
  for (int axis : {a, b})
    if (!grid_.periodic(axis) && (c[axis] == 0 || c[axis] == grid_.cells()[axis])) return true;
  return false;
}

template class StressGrid<2>;
template class StressGrid<3>;

}  // namespace monolith
