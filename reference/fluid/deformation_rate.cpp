#include "reference/fluid/deformation_rate.hpp"

#include <vector>

namespace monolith {

template <int Dim>
SparseMatrix deformation_rate_matrix(const StressGrid<Dim>& stress) {
  std::vector<Triplet> triplets;
  triplets.reserve(static_cast<size_t>(stress.num_dofs()) * 4);
  for (int row = 0; row < stress.num_dofs(); ++row)
    for_each_deformation_rate_entry(stress, row,
                                    [&](int col, double w) { triplets.emplace_back(row, col, w); });
  SparseMatrix d(stress.num_dofs(), stress.grid().num_faces());
  d.setFromTriplets(triplets.begin(), triplets.end());
  return d;
}

template <int Dim>
SparseMatrix deformation_rate_matrix(const MacGrid<Dim>& grid) {
  return deformation_rate_matrix(StressGrid<Dim>(grid));
}

template SparseMatrix deformation_rate_matrix<2>(const StressGrid<2>&);
template SparseMatrix deformation_rate_matrix<3>(const StressGrid<3>&);
template SparseMatrix deformation_rate_matrix<2>(const MacGrid<2>&);
template SparseMatrix deformation_rate_matrix<3>(const MacGrid<3>&);

}  // namespace monolith
