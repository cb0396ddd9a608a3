// Benchmark and figure maker (not a test) for the non-Newtonian scenes of section 6.4
// (docs/non-newtonian.md, docs/benchmarks.md "Non-Newtonian models per frame"):
//   fig9    Fig. 9: the shear-thinning liquid bunny (thinning-bunny-drop-Nd) with
//           solver.staggered_iterations 1, 2, 3 (and 8 for reference): the residual of each
//           viscosity round of the last step of frame 10 (the paper's convergence plot, log
//           scale, against the round), the largest last-round residual per frame, and a picture
//           with one row per iteration count;
//   models  Figs. 10 and 11: the liquid bunny thrown onto the ground (liquid-drop-PRESET-Nd)
//           and the rigid bunny dropped into a block (bunny-into-block-PRESET-Nd) for the four
//           presets: wall time per frame (timing.total) and pressure-viscosity(-contact) time
//           per frame (timing.solve, the paper's per-frame figure), solver iterations, the
//           liquid's x extent (Fig. 10) or the bunny's height (Fig. 11), and a picture with one
//           row per model (coloured by effective viscosity).
// Each scene runs as `monolith run NAME --frames K` would (the scene file's settings).
//
// Run: build/bench/bench_non_newtonian [fig9|models|all] [2|3|23] [out_dir] [threads] [frames]
//   frames  0 (default): the scene files' own frame counts (fig9 runs 10 frames + the rest of
//           the picture's columns only in 2D)
// Writes OUT/non-newtonian-fig9-residuals-Nd.ppm, OUT/non-newtonian-fig9-Nd.ppm,
// OUT/non-newtonian-fig10-Nd.ppm, OUT/non-newtonian-fig11-Nd.ppm and prints the tables.
#include <omp.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <iostream>
#include <memory>
#include <string>
#include <vector>

#include "reference/app/scene_file.hpp"
#include "reference/sim/frame_stats.hpp"
#include "reference/sim/simulation.hpp"
#include "reference/viz/plot.hpp"
#include "reference/viz/render.hpp"

using namespace monolith;

namespace {

const std::vector<std::string> kPresets = {"newtonian", "shear-thinning", "shear-thickening",
                                           "bingham"};

/// Tiles rows of equally sized pictures with a caption above each row (the project's font).
Image montage(const std::vector<std::vector<Image>>& rows, const std::vector<std::string>& captions,
              int tile) {
  const int caption = 14, gap = 2;
  std::size_t cols = 0;
  for (const auto& r : rows) cols = std::max(cols, r.size());
  const int w = static_cast<int>(cols) * (tile + gap) + gap;
  const int h = static_cast<int>(rows.size()) * (tile + caption + gap) + gap;
  Image out(w, h, {255, 255, 255});
  for (std::size_t r = 0; r < rows.size(); ++r) {
    const int y0 = gap + static_cast<int>(r) * (tile + caption + gap);
    draw_text(out, gap + 2, y0 + 3, captions[r], {20, 20, 20}, 1);
    for (std::size_t c = 0; c < rows[r].size(); ++c) {
      const Image& img = rows[r][c];
      const int x0 = gap + static_cast<int>(c) * (tile + gap);
      // nearest-neighbour resample of the frame into the tile
      for (int y = 0; y < tile; ++y)
        for (int x = 0; x < tile; ++x)
          out.set(x0 + x, y0 + caption + y, img.get(x * img.width / tile, y * img.height / tile));
    }
  }
  return out;
}

/// One run: the scene with overrides, `frames` frames, renders at the frames in `shots`.
struct Run {
  std::vector<FrameStats> frames;
  std::vector<Image> pictures;
  double seconds = 0.0;
};

Run run_scene(const std::string& name, const std::vector<std::string>& overrides, int frames,
              const std::vector<int>& shots, int tile) {
  SceneFile scene = load_scene(name, overrides);
  if (frames <= 0) frames = scene.time.frames;
  RenderSpec spec = scene.render;
  spec.size = {2 * tile, 2 * tile};
  spec.color_by = ColorBy::viscosity;
  auto sim = make_simulation(scene);
  Run r;
  const auto t0 = std::chrono::steady_clock::now();
  for (int f = 1; f <= frames; ++f) {
    r.frames.push_back(sim->advance_frame());
    if (std::find(shots.begin(), shots.end(), f) != shots.end()) r.pictures.push_back(render_simulation(*sim, spec));
  }
  r.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  return r;
}

double mean(const std::vector<FrameStats>& f, FramePhase phase) {
  double s = 0.0;
  for (const auto& x : f) s += x.timing[phase];
  return f.empty() ? 0.0 : s / static_cast<double>(f.size());
}

long mean_iterations(const std::vector<FrameStats>& f) {
  long s = 0;
  for (const auto& x : f) s += x.solver.iterations;
  return f.empty() ? 0 : s / static_cast<long>(f.size());
}

void fig9(int dim, const std::string& out, int frames) {
  const std::string name = "thinning-bunny-drop-" + std::to_string(dim) + "d";
  const int tile = 128;
  const std::vector<int> shots = {5, 10, 20, 30};
  if (frames <= 0) frames = dim == 2 ? 30 : 10;
  PlotSpec plot;
  plot.title = "Fig. 9 (" + std::to_string(dim) + "D): residual of each viscosity round, frame 10";
  plot.x_label = "round of Algorithm 2";
  plot.y_label = "||tau - 2 N(g) g|| / ||tau||";
  plot.log_y = true;
  std::vector<std::vector<Image>> rows;
  std::vector<std::string> captions;
  std::printf("\nFig. 9, %s, %d frames\n", name.c_str(), frames);
  std::printf("| iterations | frame 10: residual per round | max last-round residual over frames 1-%d | "
              "x extent at the end (m) | s/frame |\n|---|---|---|---|---|\n", frames);
  for (int rounds : {1, 2, 3, 8}) {
    const Run r = run_scene(name, {"solver.staggered_iterations=" + std::to_string(rounds)}, frames,
                            rounds <= 3 ? shots : std::vector<int>{}, tile);
    const FrameStats& f10 = r.frames.at(std::min<std::size_t>(9, r.frames.size() - 1));
    PlotSeries s;
    s.label = std::to_string(rounds) + (rounds == 1 ? " iteration" : " iterations");
    s.marker = Marker::circle;
    std::string list;
    for (std::size_t k = 0; k < f10.solver.viscosity_residuals.size(); ++k) {
      s.x.push_back(static_cast<double>(k + 1));
      s.y.push_back(std::max(f10.solver.viscosity_residuals[k], 1e-16));
      list += (k ? ", " : "") + format_number(f10.solver.viscosity_residuals[k], 2);
    }
    plot.series.push_back(s);
    double worst = 0.0;
    for (const auto& f : r.frames) worst = std::max(worst, f.solver.max_viscosity_residual);
    const FrameStats& last = r.frames.back();
    std::printf("| %d | %s | %s | %.3f | %.2f |\n", rounds, list.c_str(),
                format_number(worst, 2).c_str(),
                last.liquid_bounds_upper[0] - last.liquid_bounds_lower[0],
                r.seconds / static_cast<double>(r.frames.size()));
    if (!r.pictures.empty()) {
      rows.push_back(r.pictures);
      std::string which;
      for (std::size_t k = 0; k < r.pictures.size(); ++k) which += (k ? ", " : "") + std::to_string(shots[k]);
      captions.push_back(std::to_string(rounds) + " iteration(s): frames " + which + " (30 fps)");
    }
  }
  write_plot(plot, out + "/non-newtonian-fig9-residuals-" + std::to_string(dim) + "d.ppm");
  montage(rows, captions, tile).write_ppm(out + "/non-newtonian-fig9-" + std::to_string(dim) + "d.ppm");
}

void models(int dim, const std::string& out, int frames) {
  const int tile = 128;
  const std::vector<int> shots = {2, 4, 8, 15};
  for (const std::string stem : {"liquid-drop-", "bunny-into-block-"}) {
    const bool body = stem == "bunny-into-block-";
    std::vector<std::vector<Image>> rows;
    std::vector<std::string> captions;
    std::printf("\n%s, %dD\n", body ? "Fig. 11 (bunny into a block)" : "Fig. 10 (liquid bunny drop)", dim);
    std::printf("| model | frames | wall s/frame | solve s/frame | ratio to Newtonian (solve) | "
                "iterations/frame | %s |\n|---|---|---|---|---|---|---|\n",
                body ? "bunny height at 0.1 / 0.2 / 0.3 / 0.5 s (m)" : "x extent at 0.067 / 0.133 / 0.267 / 0.5 s (m)");
    double newtonian_solve = 0.0;
    for (const auto& preset : kPresets) {
      const std::string name = stem + preset + "-" + std::to_string(dim) + "d";
      const Run r = run_scene(name, {}, frames, shots, tile);
      const double solve = mean(r.frames, FramePhase::solve);
      if (preset == "newtonian") newtonian_solve = solve;
      std::string shape;
      const std::vector<int> at = body ? std::vector<int>{3, 6, 9, 15} : shots;
      for (int f : at) {
        if (f > static_cast<int>(r.frames.size())) continue;
        const FrameStats& s = r.frames[f - 1];
        const double v = body ? s.bodies.at(0).position[1]
                              : s.liquid_bounds_upper[0] - s.liquid_bounds_lower[0];
        shape += (shape.empty() ? "" : " / ") + format_number(v, 3);
      }
      std::printf("| %s | %zu | %.2f | %.2f | %.2f | %ld | %s |\n", preset.c_str(), r.frames.size(),
                  mean(r.frames, FramePhase::total), solve,
                  newtonian_solve > 0.0 ? solve / newtonian_solve : 0.0, mean_iterations(r.frames),
                  shape.c_str());
      std::fflush(stdout);
      rows.push_back(r.pictures);
      std::string times;
      const char* labels[] = {"0.067", "0.133", "0.267", "0.5"};
      for (std::size_t k = 0; k < r.pictures.size(); ++k) times += std::string(k ? ", " : "") + labels[k];
      captions.push_back(preset + ": t = " + times + " s");
    }
    montage(rows, captions, tile)
        .write_ppm(out + "/non-newtonian-fig" + (body ? "11" : "10") + "-" + std::to_string(dim) + "d.ppm");
  }
}

}  // namespace

int main(int argc, char** argv) {
  const std::string what = argc > 1 ? argv[1] : "all";
  const std::string dims = argc > 2 ? argv[2] : "2";
  const std::string out = argc > 3 ? argv[3] : ".";
  const int threads = argc > 4 ? std::atoi(argv[4]) : 1;
  const int frames = argc > 5 ? std::atoi(argv[5]) : 0;
  omp_set_num_threads(std::max(1, threads));
  try {
    for (char d : dims) {
      const int dim = d - '0';
      if (dim != 2 && dim != 3) continue;
      if (what == "fig9" || what == "all") fig9(dim, out, frames);
      if (what == "models" || what == "all") models(dim, out, frames);
    }
  } catch (const std::exception& e) {
    std::cerr << "bench_non_newtonian: " << e.what() << "\n";
    return 1;
  }
  return 0;
}
