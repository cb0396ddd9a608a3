#include "reference/solvers/colouring.hpp"

#include <algorithm>
#include <numeric>
#include <stdexcept>

namespace monolith {

namespace {
/// Sorts every list and removes duplicates.
void sort_unique(std::vector<std::vector<int>>& lists) {
  for (auto& l : lists) {
    std::sort(l.begin(), l.end());
    l.erase(std::unique(l.begin(), l.end()), l.end());
  }
}
}  // namespace

Colouring welsh_powell(const std::vector<std::vector<int>>& adjacency) {
  const int n = static_cast<int>(adjacency.size());
  // vertices by decreasing degree, ties by index (stable sort of 0..n-1)
  std::vector<int> order(n);
  std::iota(order.begin(), order.end(), 0);
  std::stable_sort(order.begin(), order.end(), [&](int a, int b) {
    return adjacency[a].size() > adjacency[b].size();
  });

  // greedy: the smallest colour not used by a coloured neighbour
  Colouring result;
  result.colour_of.assign(n, -1);
  std::vector<int> used_by;  // used_by[c] == v: colour c is taken by a neighbour of v
  int num_colours = 0;
  for (int v : order) {
    for (int w : adjacency[v]) {
      if (w < 0 || w >= n) throw std::invalid_argument("welsh_powell: neighbour index out of range");
      const int c = result.colour_of[w];
      if (c >= 0) used_by[c] = v;
    }
    int c = 0;
    while (c < num_colours && used_by[c] == v) ++c;
    if (c == num_colours) {
      ++num_colours;
      used_by.push_back(-1);
    }
    result.colour_of[v] = c;
  }

  // vertex lists per colour, increasing
  result.colours.assign(num_colours, {});
  for (int v = 0; v < n; ++v) result.colours[result.colour_of[v]].push_back(v);
  return result;
}

std::vector<std::vector<int>> matrix_adjacency(const SparseMatrix& a) {
  if (a.rows() != a.cols()) throw std::invalid_argument("matrix_adjacency: matrix not square");
  std::vector<std::vector<int>> adjacency(a.rows());
  // both (i, j) and (j, i) for every stored non-zero off-diagonal entry
  for (int i = 0; i < a.outerSize(); ++i)
    for (SparseMatrix::InnerIterator it(a, i); it; ++it)
      if (it.value() != 0.0 && it.row() != it.col()) {
        adjacency[it.row()].push_back(static_cast<int>(it.col()));
        adjacency[it.col()].push_back(static_cast<int>(it.row()));
      }
  sort_unique(adjacency);
  return adjacency;
}

std::vector<std::vector<int>> contact_adjacency(const std::vector<std::pair<int, int>>& contact_bodies,
                                                int num_bodies) {
  const int k = static_cast<int>(contact_bodies.size());
  // contacts of every dynamic body
  std::vector<std::vector<int>> contacts_of(std::max(num_bodies, 0));
  for (int c = 0; c < k; ++c) {
    const auto [b0, b1] = contact_bodies[c];
    for (int b : {b0, b1}) {
      if (b < -1 || b >= num_bodies) throw std::invalid_argument("contact_adjacency: body index out of range");
      if (b >= 0 && (contacts_of[b].empty() || contacts_of[b].back() != c)) contacts_of[b].push_back(c);
    }
  }
  // all pairs of contacts on one body
  std::vector<std::vector<int>> adjacency(k);
  for (const auto& list : contacts_of)
    for (int c : list)
      for (int d : list)
        if (c != d) adjacency[c].push_back(d);
  sort_unique(adjacency);
  return adjacency;
}

Colouring expand_colouring(const Colouring& vertex_colouring, int block_size) {
  if (block_size < 1) throw std::invalid_argument("expand_colouring: block_size < 1");
  const int n = static_cast<int>(vertex_colouring.colour_of.size());
  Colouring result;
  result.colour_of.resize(static_cast<size_t>(n) * block_size);
  result.colours.assign(static_cast<size_t>(vertex_colouring.num_colours()) * block_size, {});
  for (int v = 0; v < n; ++v)
    for (int k = 0; k < block_size; ++k) {
      const int row = v * block_size + k;
      const int c = vertex_colouring.colour_of[v] * block_size + k;
      result.colour_of[row] = c;
      result.colours[c].push_back(row);  // rows visited in increasing order
    }
  return result;
}

bool is_proper_colouring(const std::vector<std::vector<int>>& adjacency, const Colouring& colouring) {
  const int n = static_cast<int>(adjacency.size());
  if (static_cast<int>(colouring.colour_of.size()) != n) return false;
  // every vertex listed exactly once, in the list of its colour
  std::vector<int> seen(n, 0);
  for (int c = 0; c < colouring.num_colours(); ++c)
    for (int v : colouring.colours[c]) {
      if (v < 0 || v >= n || colouring.colour_of[v] != c) return false;
      ++seen[v];
    }
  for (int v = 0; v < n; ++v)
    if (seen[v] != 1) return false;
  // no edge inside a colour
  for (int v = 0; v < n; ++v)
    for (int w : adjacency[v])
      if (w != v && colouring.colour_of[w] == colouring.colour_of[v]) return false;
  return true;
}

}  // namespace monolith
