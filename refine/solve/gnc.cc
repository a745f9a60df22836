#include "refine/solve/gnc.h"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <cmath>

#include "core/interrupt.h"
#include "core/timing.h"

namespace raytime {

GncProgress::GncProgress(int stage, int num_stages, double scale_px2)
    : stage_(stage),
      num_stages_(num_stages),
      scale_px2_(scale_px2),
      bar_(fmt::format("refine: GNC stage {}/{} a = {:g} px², iteration", stage, num_stages,
                       scale_px2),
           0) {}

void GncProgress::Report(int iteration, double cost) {
  StopPoint();  // an in-process run's Ctrl-C ends the solve here (core/interrupt.h)
  if (bar_.drawing()) {
    bar_.Update(iteration, fmt::format("cost {:.6g}", cost));
    return;
  }
  constexpr std::chrono::seconds kProgressInterval{15};
  const auto now = std::chrono::steady_clock::now();
  if (now - last_ < kProgressInterval) return;
  last_ = now;
  spdlog::info(
      fmt::format("refine: GNC stage {}/{} a = {:g} px²: iteration {}, cost {:.6g}, {:.0f} s",
                  stage_, num_stages_, scale_px2_, iteration, cost, SecondsSince(start_)));
}

std::vector<int> ResidualHistogram(const std::vector<double>& norms_px) {
  const std::vector<double>& edges = ResidualHistogramEdgesPx();
  std::vector<int> counts(edges.size() + 1, 0);
  for (const double norm : norms_px) {
    // Non-finite norms (a point behind a camera) fall in the last bin with the largest.
    const auto bin =
        std::isnan(norm) ? edges.end() : std::upper_bound(edges.begin(), edges.end(), norm);
    ++counts[bin - edges.begin()];
  }
  return counts;
}

double GncSettings::StageTolerance(int stage) const {
  const bool last = stage + 1 == static_cast<int>(scales.size());
  return last && ends_solve ? function_tolerance : intermediate_function_tolerance;
}

std::vector<GncStageSummary> SolveGnc(GncBackend* backend, const GncSettings& settings) {
  std::vector<GncStageSummary> stages;
  const int num_stages = static_cast<int>(settings.scales.size());
  for (int s = 0; s < num_stages; ++s) {
    StopPoint();
    const double scale = settings.scales[s];
    GncStageSummary stage;
    {
      // Its progress line ends with the stage, before the stage's log line.
      GncProgress progress(s + 1, num_stages, scale);
      stage = backend->SolveStage(scale, settings.StageTolerance(s), settings, &progress);
    }
    // A Ceres stage aborted by a stop request ends here (ceres_gnc.cc).
    StopPoint();
    stage.function_tolerance = settings.StageTolerance(s);
    if (settings.residual_norms) {
      backend->Publish();
      stage.residual_histogram = ResidualHistogram(settings.residual_norms());
    }
    spdlog::info(
        fmt::format("refine: GNC stage {}/{} a = {:g} px²: {} iterations, cost {:.6g} -> {:.6g}, "
                    "{:.2f} s ({}, {})",
                    s + 1, num_stages, scale, stage.iterations, stage.initial_cost,
                    stage.final_cost, stage.seconds, NameOf(stage.termination), backend->Name()));
    stages.push_back(stage);
    if (stage.termination == GncTermination::kFailure) break;
  }
  return stages;
}

}  // namespace raytime
