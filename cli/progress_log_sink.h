// The CLI's log sink (issue 32): log lines on stderr as before, with the progress bar
// (core/progress.h) erased before each and drawn again after, so a bar and a log line never share
// a terminal line; control characters in messages are escaped (issue 47).
#pragma once

#include <spdlog/sinks/sink.h>

#include <memory>
#include <string>
#include <utility>

#include "core/progress.h"
#include "core/terminal_text.h"

namespace raytime {

class ProgressLogSink : public spdlog::sinks::sink {
 public:
  explicit ProgressLogSink(std::shared_ptr<spdlog::sinks::sink> inner) : inner_(std::move(inner)) {}

  // Control characters in a message (a file name's escape sequences) are shown, not obeyed.
  void log(const spdlog::details::log_msg& message) override {
    const std::string escaped =
        EscapeControlCharacters(std::string(message.payload.data(), message.payload.size()));
    spdlog::details::log_msg shown = message;
    shown.payload = escaped;
    ClearProgressLine();
    inner_->log(shown);
    inner_->flush();
    RedrawProgressLine();
  }
  void flush() override { inner_->flush(); }
  void set_pattern(const std::string& pattern) override { inner_->set_pattern(pattern); }
  void set_formatter(std::unique_ptr<spdlog::formatter> formatter) override {
    inner_->set_formatter(std::move(formatter));
  }

 private:
  std::shared_ptr<spdlog::sinks::sink> inner_;
};

}  // namespace raytime
