// Progress lines (core/progress.h) and the CLI's log sink around them (cli/progress_log_sink.h):
// known lines, a bar drawn and erased on a stream, a log line that erases the bar and draws it
// again after itself.
#include <gtest/gtest.h>
#include <spdlog/logger.h>
#include <spdlog/sinks/ostream_sink.h>

#include <cstdio>
#include <memory>
#include <sstream>
#include <string>

#include "cli/progress_log_sink.h"
#include "core/progress.h"

namespace raytime {
namespace {

std::string Contents(std::FILE* stream) {
  std::fflush(stream);
  std::rewind(stream);
  std::string text;
  char buffer[4096];
  size_t n;
  while ((n = std::fread(buffer, 1, sizeof(buffer), stream)) > 0) text.append(buffer, n);
  return text;
}

TEST(ProgressTest, LinesSayTheCountTheTimeAndWhatIsLeft) {
  EXPECT_EQ(FormatProgressLine("features", 5, 10, 10.0, "a.jpg", 200),
            "features ████████████░░░░░░░░░░░░ 5/10 10 s, ~10 s left  a.jpg");
  EXPECT_EQ(FormatProgressLine("matches", 10, 10, 75.0, "", 200),
            "matches ████████████████████████ 10/10 1 min 15 s");
  // No total: the count and the time, no bar.
  EXPECT_EQ(FormatProgressLine("refine: iteration", 7, 0, 3.2, "cost 1.5", 200),
            "refine: iteration 7, 3 s  cost 1.5");
  // One terminal line at most, cut between characters, never inside a block glyph.
  const std::string cut = FormatProgressLine("features", 3, 10, 1.0, "a-long-image-name.jpg", 20);
  EXPECT_EQ(cut, "features ███████░░░");  // 3/10 of 24 cells: 7 filled
}

TEST(ProgressTest, ABarIsDrawnInPlaceAndErasedWhenTheWorkEnds) {
  std::FILE* stream = std::tmpfile();
  ASSERT_NE(stream, nullptr);
  SetProgressOutput(stream, 200);
  {
    ProgressBar bar("features", 2);
    EXPECT_TRUE(bar.drawing());
    bar.Update(1, "a.jpg");
    bar.Update(2, "b.jpg");  // the last update is drawn however soon it comes
  }
  const std::string text = Contents(stream);
  SetProgressOutput(nullptr, 0);
  std::fclose(stream);
  EXPECT_EQ(text,
            "\r\033[Kfeatures ████████████░░░░░░░░░░░░ 1/2 0 s, ~0 s left  a.jpg"
            "\r\033[Kfeatures ████████████████████████ 2/2 0 s  b.jpg"
            "\r\033[K");
}

TEST(ProgressTest, ALogLineErasesTheBarAndTheBarComesBackAfterIt) {
  std::FILE* stream = std::tmpfile();
  ASSERT_NE(stream, nullptr);
  SetProgressOutput(stream, 200);
  std::ostringstream log;
  spdlog::logger logger(
      "progress_test",
      std::make_shared<ProgressLogSink>(std::make_shared<spdlog::sinks::ostream_sink_st>(log)));
  logger.set_pattern("%v");
  {
    ProgressBar bar("matches", 0);
    bar.Update(3, "2 verified");
    logger.info("a log line");
  }
  logger.info("after the bar");  // nothing to erase or draw
  const std::string text = Contents(stream);
  SetProgressOutput(nullptr, 0);
  std::fclose(stream);
  EXPECT_EQ(log.str(), "a log line\nafter the bar\n");
  const std::string bar = "\r\033[Kmatches 3, 0 s  2 verified";
  EXPECT_EQ(text, bar + "\r\033[K" + bar + "\r\033[K");
}

}  // namespace
}  // namespace raytime
