// libFuzzer target: a sweep's sweep.json as `raytime report` reads it (report/sweep_row.h:
// ReadSweepRows; report/campaign_report.h: AggregateCampaign, then the report formats). The
// input is the file.
#include <string>
#include <string_view>

#include "core/error.h"
#include "report/campaign_report.h"
#include "tests/fuzz/fuzz_util.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace raytime;
  return fuzz::ReadAsFile(data, size, "sweep.json", [](const std::string& path) {
    const CampaignReport report = AggregateCampaign(ReadSweepRows(path));
    CampaignReportMarkdown(report, path);
    CampaignCellsCsv(report);
    CampaignSplatCsv(report);
  });
}
