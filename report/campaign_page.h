// The campaign report as one HTML page (issue 32 "See the run"): beside report.md, what a
// sweep's reader wants to look at rather than read. Success rate against the perturbation level
// per arm (Wilson 95 % whiskers) and median rotation error against the level, per scene and
// pooled, as SVG plots whose legend shows and hides an arm; Table 5's cells; Table 4 when the
// sweep trained 3DGS; and per scene every run with its swept values, status and each arm's error,
// linked to that run's own page (WORKDIR/report.html). Self-contained like the run page: inline
// SVG and one small inline script (the legend), nothing fetched.
#pragma once

#include <map>
#include <string>
#include <vector>

#include "report/campaign_report.h"
#include "report/sweep_row.h"

namespace raytime {

// `rows` in the sweep's order (as aggregated into `report`); `run_pages` maps a run label to the
// link to its page, relative to where this page is written (a run without one has no link);
// `source` names the sweep in the header.
std::string CampaignReportHtml(const CampaignReport& report, const std::vector<SweepRow>& rows,
                               const std::map<std::string, std::string>& run_pages,
                               const std::string& source);

}  // namespace raytime
