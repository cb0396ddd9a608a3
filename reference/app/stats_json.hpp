#pragma once
/// \file stats_json.hpp
/// One line of stats.jsonl (docs/cli.md): a FrameStats (reference/sim/frame_stats.hpp) with
/// every field of the contract, the scheme by its paper name and the frame's timing per phase.

#include <nlohmann/json.hpp>

#include "reference/sim/frame_stats.hpp"

namespace monolith {

/// The stats.jsonl object of one frame (non-finite numbers are written as null).
nlohmann::json frame_stats_json(const FrameStats& stats);

}  // namespace monolith
