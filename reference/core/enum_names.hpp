#pragma once
/// \file enum_names.hpp
/// The names of enum values: the scene format's strings ("matrixfree", "PVC-unified",
/// "static", ...) become enums in exactly one place, the scene parser (reference/app/
/// scene_file.cpp), through parse_enum, and go back to text only where an output writes them
/// (stats.jsonl's scheme, messages) through enum_name. Every option enum of the core (back end,
/// coupling scheme, body motion, shape type, boundary, viscosity model, ...) specialises
/// EnumNames next to its declaration, listing each value once with its name in the order the
/// scene format documents them.

#include <array>
#include <cstddef>
#include <optional>
#include <stdexcept>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

namespace monolith {

/// Specialised next to each enum E with
///   static constexpr std::array<std::pair<E, const char*>, N> values{{{E::a, "a"}, ...}};
/// every value of E once, in the documented order of its names.
template <class E>
struct EnumNames;

/// The name of `value` (throws std::invalid_argument for a value missing from the table,
/// which a complete table never has).
template <class E>
std::string enum_name(E value) {
  for (const auto& [e, name] : EnumNames<E>::values)
    if (e == value) return name;
  throw std::invalid_argument("enum_name: a value without a name");
}

/// The value named `name`, or nothing for a name that is not in the table: the only comparison
/// of option strings in the library.
template <class E>
std::optional<E> parse_enum(std::string_view name) {
  for (const auto& [e, text] : EnumNames<E>::values)
    if (name == text) return e;
  return std::nullopt;
}

/// Every name, in table order (for messages such as `one of "wall", "open", "periodic"`).
template <class E>
std::vector<std::string> enum_names() {
  std::vector<std::string> out;
  for (const auto& entry : EnumNames<E>::values) out.emplace_back(entry.second);
  return out;
}

/// Every value, in table order (to loop over all schemes, all back ends, ...).
template <class E>
std::vector<E> enum_values() {
  std::vector<E> out;
  for (const auto& entry : EnumNames<E>::values) out.push_back(entry.first);
  return out;
}

/// The number of values of E.
template <class E>
constexpr std::size_t enum_count() {
  return EnumNames<E>::values.size();
}

/// The position of `value` in the table (0 .. enum_count<E>() - 1), e.g. to index a per-value
/// array; throws std::invalid_argument for a value missing from the table.
template <class E>
constexpr std::size_t enum_index(E value) {
  for (std::size_t i = 0; i < EnumNames<E>::values.size(); ++i)
    if (EnumNames<E>::values[i].first == value) return i;
  throw std::invalid_argument("enum_index: a value without a name");
}

}  // namespace monolith
