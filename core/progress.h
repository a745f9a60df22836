// Progress of long work on a terminal (issue 32): features, matching, the solve and a trainer
// each draw one line redrawn in place (a bar when the total is known, else the count and a
// detail), cleared when the work ends. Off the terminal (a log file, CI, a sweep's run.log) no
// bar is drawn and the callers' plain log lines are the record. The log and the bar share stderr:
// the CLI's log sink (cli/progress_log_sink.h) clears the bar before a log line and redraws it
// after, so neither garbles the other. Drawing never changes what is computed.
#pragma once

#include <chrono>
#include <cstdio>
#include <string>

namespace raytime {

class ProgressBar {
 public:
  // `task` heads the line ("features", "matches", "refine"); `total` units of work, 0 when not
  // known in advance (the count is shown without a bar).
  ProgressBar(std::string task, int total);
  ~ProgressBar();
  ProgressBar(const ProgressBar&) = delete;
  ProgressBar& operator=(const ProgressBar&) = delete;

  // `done` units finished, with a short `detail` (the image, the pair count, the cost); safe from
  // several threads; redrawn at most 10 times a second.
  void Update(int done, const std::string& detail = std::string());
  // Whether this bar draws (ProgressBarsEnabled() when it was made): a caller then leaves out the
  // per-item log lines the bar replaces.
  bool drawing() const { return drawing_; }

 private:
  std::string task_;
  int total_ = 0;
  bool drawing_ = false;
  std::chrono::steady_clock::time_point start_ = std::chrono::steady_clock::now();
  std::chrono::steady_clock::time_point last_draw_{};
};

// Bars are drawn when stderr is a terminal and RAYTIME_PROGRESS is not "0", or where
// SetProgressOutput gave a stream.
bool ProgressBarsEnabled();

// Draws bars on `stream` at `columns` wide whatever it is (nullptr: back to stderr when it is a
// terminal): for tests, and for the log sink's own stream.
void SetProgressOutput(std::FILE* stream, int columns);

// For the log sink: erase the bar's line before a log line is written, draw it again after (no-op
// when no bar is drawn).
void ClearProgressLine();
void RedrawProgressLine();

// The text of a bar line, `columns` wide at most: task, bar (when total > 0), count, elapsed time,
// time left (when total > 0 and done > 0), detail.
std::string FormatProgressLine(const std::string& task, int done, int total, double seconds,
                               const std::string& detail, int columns);

}  // namespace raytime
