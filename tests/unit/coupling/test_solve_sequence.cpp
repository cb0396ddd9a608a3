// Tests of the one scheme dispatcher (reference/coupling/solve_sequence.hpp): which solves each
// sequence runs and in which order, what the PC-VC-PC sequence returns, and Algorithm 2's rounds
// around the viscous solve (eta from the velocities the solve starts from, updated after each).
#include <catch2/catch.hpp>

#include <string>
#include <vector>

#include "reference/coupling/solve_sequence.hpp"

using namespace monolith;

namespace {

struct State {
  VectorX u, pressure, stress;
};

VectorX scalar(double x) { return VectorX::Constant(1, x); }

}  // namespace

TEST_CASE("solve_sequence: the sequence of every scheme, with and without viscous liquid",
          "[sequence]") {
  CHECK(solve_sequence(CouplingScheme::pc_vc_pc_unified, true) == SolveSequence::decoupled);
  CHECK(solve_sequence(CouplingScheme::pvc_iterative, true) == SolveSequence::unified);
  CHECK(solve_sequence(CouplingScheme::pc_unified, true) == SolveSequence::pressure);
  CHECK(solve_sequence(CouplingScheme::pc_vc_pc_unified, false) == SolveSequence::pressure);
}

TEST_CASE("run_solve_sequence: the stages in order, PC-VC-PC returns p1 + p3 and tau2",
          "[sequence]") {
  std::vector<std::string> log;
  // each stage adds to u; pressure solves return p = u, the viscous ones tau = 10 u
  auto pressure = [&](const State& from, SolveStage stage) {
    log.push_back(solve_stage_name(stage));
    State out = from;
    out.u = from.u + scalar(1.0);
    out.pressure = out.u;
    return out;
  };
  auto unified = [&](const State& from, const VectorX* eta) {
    log.push_back(std::string("Stokes") + (eta ? " eta" : ""));
    State out = from;
    out.u = from.u + scalar(eta ? (*eta)[0] : 2.0);
    out.pressure = out.u;
    out.stress = 10.0 * out.u;
    return out;
  };
  auto viscous = [&](const State& from, const VectorX* eta) {
    log.push_back(std::string("viscosity") + (eta ? " eta" : ""));
    State out = from;
    out.u = from.u + scalar(eta ? (*eta)[0] : 2.0);
    out.stress = 10.0 * out.u;
    return out;
  };
  const State start{scalar(0.0), scalar(-7.0), scalar(-9.0)};
  ViscosityRounds newtonian;

  State end = run_solve_sequence(SolveSequence::pressure, start, newtonian, pressure, unified, viscous);
  CHECK(log == std::vector<std::string>{"pressure"});
  CHECK(end.pressure[0] == 1.0);
  CHECK(end.stress[0] == -9.0);  // no stress solve: the stress is left as it was

  log.clear();
  end = run_solve_sequence(SolveSequence::decoupled, start, newtonian, pressure, unified, viscous);
  CHECK(log == std::vector<std::string>{"first pressure", "viscosity", "second pressure"});
  // u: 0 -> 1 (p1 = 1) -> 3 (tau2 = 30) -> 4 (p3 = 4)
  CHECK(end.u[0] == 4.0);
  CHECK(end.pressure[0] == 1.0 + 4.0);
  CHECK(end.stress[0] == 30.0);

  // Algorithm 2: eta^1 from the start of the viscous solve, every round from that start
  std::vector<double> initial_from;
  ViscosityRounds rounds;
  rounds.rounds = 3;
  rounds.initial = [&](const VectorX& u) {
    initial_from.push_back(u[0]);
    return scalar(1.0);
  };
  rounds.update = [&](const VectorX& tau, const VectorX& eta) { return eta + 0.001 * tau; };
  log.clear();
  end = run_solve_sequence(SolveSequence::decoupled, start, rounds, pressure, unified, viscous);
  CHECK(log == std::vector<std::string>{"first pressure", "viscosity eta", "viscosity eta",
                                        "viscosity eta", "second pressure"});
  REQUIRE(initial_from.size() == 1);
  CHECK(initial_from[0] == 1.0);  // the first pressure solve's u
  // eta: 1 -> 1 + 0.001 * 20 = 1.02 -> 1.02 + 0.001 * 20.2 = 1.0402; every round from u = 1
  CHECK(end.stress[0] == Approx(10.0 * (1.0 + 1.0402)));
  CHECK(end.u[0] == Approx(1.0 + 1.0402 + 1.0));

  log.clear();
  initial_from.clear();
  end = run_solve_sequence(SolveSequence::unified, start, rounds, pressure, unified, viscous);
  CHECK(log == std::vector<std::string>{"Stokes eta", "Stokes eta", "Stokes eta"});
  CHECK(initial_from == std::vector<double>{0.0});
}
