// The names of the option enums (reference/core/enum_names.hpp and the EnumNames table next to
// each enum): every value has one name, names round-trip, unknown or wrongly spelt names are
// refused, and the tables hold the scene format's names in its documented order.
#include <catch2/catch.hpp>

#include <set>
#include <string>
#include <vector>

#include "reference/sim/frame_stats.hpp"
#include "reference/sim/scene_desc.hpp"
#include "reference/viz/render_spec.hpp"

using namespace monolith;

namespace {

template <class E>
void check_table(const std::vector<std::string>& expected) {
  const std::vector<std::string> names = enum_names<E>();
  CHECK(names == expected);
  CHECK(enum_count<E>() == expected.size());
  CHECK(std::set<std::string>(names.begin(), names.end()).size() == names.size());
  const std::vector<E> values = enum_values<E>();
  REQUIRE(values.size() == names.size());
  for (std::size_t i = 0; i < values.size(); ++i) {
    INFO(names[i]);
    CHECK(enum_name(values[i]) == names[i]);
    CHECK(parse_enum<E>(names[i]) == values[i]);
    CHECK(enum_index(values[i]) == i);
    // names are exact: no other case, no surrounding space
    std::string upper = names[i];
    for (char& c : upper) c = static_cast<char>(std::toupper(static_cast<unsigned char>(c)));
    if (upper != names[i]) CHECK_FALSE(parse_enum<E>(upper).has_value());
    CHECK_FALSE(parse_enum<E>(" " + names[i]).has_value());
  }
  CHECK_FALSE(parse_enum<E>("").has_value());
}

}  // namespace

TEST_CASE("every option enum has one scene name per value, in the documented order", "[unit]") {
  check_table<Backend>({"matrixfree", "explicit"});
  check_table<PreconditionerKind>({"multigrid", "ssor"});
  check_table<PreconditionerChoice>({"auto", "multigrid", "ssor"});
  check_table<CouplingScheme>({"P-C", "C-P", "PC-iterative", "PC-unified", "PC-VC-PC-unified", "PV-C",
                               "C-PV", "PVC-iterative", "PVC-unified"});
  check_table<BodyMotion>({"dynamic", "static", "kinematic"});
  check_table<PathType>({"oscillate"});
  check_table<ShapeType>({"box", "sphere", "bowl", "shell", "halfspace", "polygon", "mesh", "bunny",
                          "union", "difference"});
  check_table<BoundaryType>({"wall", "open", "periodic"});
  check_table<ViscosityModel>({"newtonian", "herschel-bulkley"});
  check_table<ViscosityPreset>({"newtonian", "shear-thinning", "shear-thickening", "bingham"});
  check_table<ColorBy>({"none", "speed", "pressure", "viscosity"});
  check_table<FramePhase>({"total", "solve", "particles", "weights", "extrapolation", "render", "output"});
  check_table<NonconvergencePolicy>({"warn", "fail"});
}

TEST_CASE("the one default of each option is the member initialiser of its struct", "[unit]") {
  // the values docs/scene-format.md documents as defaults
  const SolverSpec solver;
  CHECK(solver.backend == Backend::matrix_free);
  CHECK(solver.preconditioner == PreconditionerChoice::automatic);
  CHECK(solver.pressure_preconditioner == PreconditionerKind::ssor);
  CHECK(solver.scheme == CouplingScheme::pvc_unified);
  CHECK(solver.on_nonconvergence == NonconvergencePolicy::warn);
  CHECK(BodySpec{}.motion == BodyMotion::dynamic);
  CHECK(ViscositySpec{}.model == ViscosityModel::newtonian);
  CHECK_FALSE(ViscositySpec{}.preset.has_value());
  CHECK(RenderSpec{}.color_by == ColorBy::speed);
  for (const BoundaryType b : DomainSpec{}.boundary) CHECK(b == BoundaryType::wall);
  CHECK(ShapeSpec{}.scale == std::vector<double>{1.0});
  // the dimension-dependent ones, in one function each
  CHECK(default_gravity(2) == std::vector<double>{0.0, -9.81});
  CHECK(default_gravity(3) == std::vector<double>{0.0, -9.81, 0.0});
  CHECK(ParticleSpec{}.count_per_cell(2) == 4);
  CHECK(ParticleSpec{}.count_per_cell(3) == 8);
  ParticleSpec dense;
  dense.per_cell = 27;
  CHECK(dense.count_per_cell(2) == 27);
}
