#pragma once
/// \file colouring.hpp
/// Graph colouring for parallel Gauss-Seidel / SOR sweeps (section 4.3): rows (or contacts) of
/// one colour share no off-diagonal entry, so all rows of a colour can be relaxed at the same
/// time without changing the result. Colours by Welsh & Powell (1967).

#include <utility>
#include <vector>

#include "reference/core/common.hpp"

namespace monolith {

/// A colouring of the vertices 0..n-1.
struct Colouring {
  /// colours[c] = the vertices of colour c, each list increasing; every vertex is in one list.
  std::vector<std::vector<int>> colours;
  /// colour_of[v] = the colour of vertex v (size n).
  std::vector<int> colour_of;
  int num_colours() const { return static_cast<int>(colours.size()); }
};

/// Welsh-Powell: vertices by decreasing degree (ties by increasing index, so the result is
/// deterministic), each gets the smallest colour not used by an already coloured neighbour.
/// Uses at most max-degree + 1 colours. adjacency[i] = neighbours of i (symmetric, no self loops;
/// duplicates are tolerated).
Colouring welsh_powell(const std::vector<std::vector<int>>& adjacency);

/// The adjacency of a square sparse matrix's off-diagonal pattern: i ~ j when A_ij != 0 or
/// A_ji != 0 (i != j), symmetrised; each list increasing and without duplicates.
std::vector<std::vector<int>> matrix_adjacency(const SparseMatrix& a);

/// The adjacency of contacts: contacts k and l are adjacent when they share a dynamic body.
/// contact_bodies[k] = the two bodies of contact k, each in [0, num_bodies) or -1 for "no
/// dynamic body" (a static or kinematic body, which couples nothing). Lists increasing, unique.
std::vector<std::vector<int>> contact_adjacency(const std::vector<std::pair<int, int>>& contact_bodies,
                                                int num_bodies);

/// The colouring of rows grouped in blocks of block_size consecutive rows per vertex (e.g. the
/// Dim-1 friction rows of one contact): row v * block_size + k gets colour
/// colour_of[v] * block_size + k, so rows of one block never share a colour (they usually couple)
/// and rows of adjacent vertices never do either. Proper for the block matrix when the vertex
/// colouring is proper for the vertex graph.
Colouring expand_colouring(const Colouring& vertex_colouring, int block_size);

/// True when no two adjacent vertices share a colour and every vertex has exactly one colour.
bool is_proper_colouring(const std::vector<std::vector<int>>& adjacency, const Colouring& colouring);

}  // namespace monolith
