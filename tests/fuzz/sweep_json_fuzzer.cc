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
  const std::string path = fuzz::ScratchPath("sweep.json");
  fuzz::WriteFile(path, std::string_view(reinterpret_cast<const char*>(data), size));
  try {
    const CampaignReport report = AggregateCampaign(ReadSweepRows(path));
    CampaignReportMarkdown(report, path);
    CampaignCellsCsv(report);
    CampaignSplatCsv(report);
  } catch (const InputError&) {
  }
  return 0;
}
