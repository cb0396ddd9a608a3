/// \file staggered_projections.cpp
/// The contact-only QP operators of the staggered projections (staggered_projections.hpp).

#include "reference/contact/staggered_projections.hpp"

#include <limits>

namespace monolith {

template <int Dim>
ContactQpOperators<Dim>::ContactQpOperators(const ContactSystem<Dim>& system,
                                            const StaggeredSettings& settings) {
  const int nc = system.num_contacts();
  zero_ = VectorX::Zero(nc);
  infinity_ = VectorX::Constant(nc, std::numeric_limits<double>::infinity());
  if (nc == 0) return;
  friction_ = system.mu.maxCoeff() > 0.0 && system.num_body_dofs() > 0;
  const Colouring colours =
      welsh_powell(contact_adjacency(system.dynamic_pairs, system.num_dynamic_bodies));
  a33_ = std::make_unique<ColouredSparseOperator>(system.a33(), colours);
  a33_boosted_ = std::make_unique<DiagonalBoost>(*a33_, settings.diagonal_boost);
  normal_settings_ = with_norm_estimate(*a33_boosted_, settings.mprgp);
  if (!friction_) return;
  a44_ = std::make_unique<ColouredSparseOperator>(system.a44(), expand_colouring(colours, Dim - 1));
  a44_boosted_ = std::make_unique<DiagonalBoost>(*a44_, settings.diagonal_boost);
  friction_settings_ = with_norm_estimate(*a44_boosted_, settings.mprgp);
}

template class ContactQpOperators<2>;
template class ContactQpOperators<3>;

}  // namespace monolith
