#pragma once
/// \file oracle.hpp
/// The oracle commands of docs/cli.md and docs/oracle.md:
///   monolith export SCENE --frame N [--step K] --out DIR [--set KEY=VALUE]...
///   monolith verify DIR CANDIDATE.mtx [--tolerance T]
/// export runs the scene to frame N and writes that frame's step K's coupled system of eq. (24)
/// (SystemExport, reference/coupling/system_export.hpp) as Matrix Market files and
/// manifest.json; verify judges a candidate solution against such a folder.

#include <ostream>
#include <string>
#include <vector>

#include "reference/app/runner.hpp"
#include "reference/coupling/system_export.hpp"

namespace monolith {

/// Writes every matrix and vector of `e` as DIR/<name>.mtx and DIR/manifest.json; `context`
/// (scene, frame, step, scheme, ...) is merged into the manifest. Throws InputError when a
/// file cannot be written.
void write_system_export(const SystemExport& e, const std::string& dir,
                         const nlohmann::json& context);

/// `monolith export ...` (args after the command name). Returns 0; throws InputError (exit 2)
/// for bad input: unknown scene, frame beyond the scene's end, a step the frame does not have, a
/// scene without a coupled step (no liquid or no dynamic body), an unwritable DIR.
int export_command(const std::vector<std::string>& args, std::ostream& out,
                   const SimulationFactory& factory);

/// The result of verify: the checks and the tolerance they were held to.
struct VerifyReport {
  SolutionCheck check;
  double tolerance = 0.0;
  int size = 0;
};

/// Reads DIR (manifest.json, A.mtx, b.mtx, x.mtx, mu.mtx) and the candidate and checks it
/// (check_solution). tolerance <= 0: the manifest's. Throws InputError for unreadable or
/// mis-sized input.
VerifyReport verify_solution(const std::string& dir, const std::string& candidate, double tolerance);

/// `monolith verify ...`: prints the checks; returns 0 if they pass, 1 if not; throws InputError
/// (exit 2) for unreadable or mis-sized input.
int verify_command(const std::vector<std::string>& args, std::ostream& out);

}  // namespace monolith
