#pragma once
/// \file backend.hpp
/// The two representations of every linear system of the step (docs/design.md, "Two back
/// ends"): assembled sparse matrices, the reference the tests compare with, and stencils applied
/// on the fly in parallel without a global matrix, the production path. Both run the same
/// solvers through LinearOperator (linear_operator.hpp) and give the same answers to round-off.

#include "reference/core/enum_names.hpp"

namespace monolith {

/// `solver.backend` of a scene: "matrixfree" (the default, SceneDesc's SolverSpec) or
/// "explicit".
enum class Backend { matrix_free, explicit_matrices };

template <>
struct EnumNames<Backend> {
  static constexpr std::array<std::pair<Backend, const char*>, 2> values{
      {{Backend::matrix_free, "matrixfree"}, {Backend::explicit_matrices, "explicit"}}};
};

}  // namespace monolith
