// WORKDIR/report.html: one self-contained page per run (issue 32 "See the run"), from the run's
// summary.json and the pose sets it names, so a person sees before training whether to trust the
// poses: the verdict first (status, each refine stage's decision, every warning with the images it
// names, time per stage), then the cameras before and after (a top view of the prior's and the
// refined centres with each correction drawn, coloured by size; a camera links to its row), a
// table per camera (its correction, its σ from the solve, the warnings naming it) and the errors
// against ground truth when there is one. Plain HTML and inline SVG: no script, no network fetch,
// opens offline. Written by the pipeline at the end of every run, also a failed one, and by
// `raytime report --run WORKDIR`.
#pragma once

#include <string>

namespace raytime {

// Writes WORKDIR/report.html (atomically) and returns its path. InputError naming summary.json
// when the work directory has none.
std::string WriteRunReport(const std::string& workdir);

}  // namespace raytime
