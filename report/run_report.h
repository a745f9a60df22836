// WORKDIR/report.html: one self-contained page per run (issue 32 "See the run"), from the run's
// summary.json, the pose sets it names, the refine stage's fit per image and pair
// (kSolveDiagnosticsJson) and the images, so a person sees before training whether to trust the
// poses: the verdict first (status, the refine decision, every warning with the images it names
// as thumbnails), then the cameras before and after (top and side views of the centres and an
// orbit view of the frusta, prior grey, reference blue, refined coloured by its correction), a
// table per camera (correction, σ from the solve, residual median, pairs, matches, flags), a
// residual histogram per GNC stage, the pair-consistency matrix, the errors against ground truth
// and the splat metrics when there are any, time per stage. A click on a camera anywhere opens its
// panel: its image, its numbers, its worst pairs (CSS :target, no script needed). The orbit view
// is the one script (run_report_orbit.js, inlined); images are inlined as data URIs; nothing is
// fetched: the file opens offline on its own. Written by the pipeline at the end of every run,
// also a failed one, and by `raytime report --run WORKDIR`. tests/browser/check_run_page.py
// opens and clicks it in headless Chromium.
#pragma once

#include <string>

namespace raytime {

// Writes WORKDIR/report.html (atomically) and returns its path. InputError naming summary.json
// when the work directory has none.
std::string WriteRunReport(const std::string& workdir);

}  // namespace raytime
