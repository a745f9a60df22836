#include "core/progress.h"

#include <sys/ioctl.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <mutex>

#include "core/interrupt.h"

namespace raytime {
namespace {

// The one line on screen: bars do not nest (an inner bar replaces the outer one's line until it
// ends).
struct ProgressScreen {
  std::mutex mutex;
  std::FILE* forced_stream = nullptr;
  int forced_columns = 0;
  std::string line;  // drawn now; empty: nothing on screen
};

ProgressScreen& Screen() {
  static ProgressScreen screen;
  return screen;
}

std::FILE* StreamLocked(const ProgressScreen& screen) {
  return screen.forced_stream != nullptr ? screen.forced_stream : stderr;
}

int ColumnsLocked(const ProgressScreen& screen) {
  if (screen.forced_stream != nullptr) return screen.forced_columns;
  winsize size{};
  if (::ioctl(STDERR_FILENO, TIOCGWINSZ, &size) == 0 && size.ws_col > 0) return size.ws_col;
  return 80;
}

void EraseLocked(ProgressScreen& screen) {
  if (screen.line.empty()) return;
  std::fputs("\r\033[K", StreamLocked(screen));
  std::fflush(StreamLocked(screen));
}

void DrawLocked(ProgressScreen& screen) {
  if (screen.line.empty()) return;
  std::fputs(("\r\033[K" + screen.line).c_str(), StreamLocked(screen));
  std::fflush(StreamLocked(screen));
}

std::string Duration(double seconds) {
  char text[32];
  if (seconds < 60) {
    std::snprintf(text, sizeof(text), "%.0f s", seconds);
  } else if (seconds < 3600) {
    std::snprintf(text, sizeof(text), "%d min %02d s", static_cast<int>(seconds) / 60,
                  static_cast<int>(seconds) % 60);
  } else {
    std::snprintf(text, sizeof(text), "%d h %02d min", static_cast<int>(seconds) / 3600,
                  static_cast<int>(seconds) % 3600 / 60);
  }
  return text;
}

// The number of UTF-8 characters of `text` (what a terminal shows, for the bar's block glyphs).
size_t Glyphs(const std::string& text) {
  size_t n = 0;
  for (const char c : text) n += (static_cast<unsigned char>(c) & 0xC0) != 0x80;
  return n;
}

// `text` cut to `glyphs` characters, never inside a UTF-8 sequence.
std::string CutToGlyphs(const std::string& text, size_t glyphs) {
  size_t n = 0;
  for (size_t i = 0; i < text.size(); ++i) {
    if ((static_cast<unsigned char>(text[i]) & 0xC0) != 0x80 && n++ == glyphs) {
      return text.substr(0, i);
    }
  }
  return text;
}

}  // namespace

std::string FormatProgressLine(const std::string& task, int done, int total, double seconds,
                               const std::string& detail, int columns) {
  std::string line = task + " ";
  if (total > 0) {
    constexpr int kBarWidth = 24;
    const double share = std::clamp(static_cast<double>(done) / total, 0.0, 1.0);
    const int filled = static_cast<int>(std::floor(share * kBarWidth));
    for (int k = 0; k < kBarWidth; ++k) line += k < filled ? "█" : "░";
    line += " " + std::to_string(done) + "/" + std::to_string(total) + " " + Duration(seconds);
    if (done > 0 && done < total) {
      line += ", ~" + Duration(seconds * (total - done) / done) + " left";
    }
  } else {
    line += std::to_string(done) + ", " + Duration(seconds);
  }
  if (!detail.empty()) line += "  " + detail;
  // One line: a wrapped line could not be erased with a carriage return.
  const size_t width = static_cast<size_t>(std::max(columns - 1, 10));
  return Glyphs(line) > width ? CutToGlyphs(line, width) : line;
}

bool ProgressBarsEnabled() {
  ProgressScreen& screen = Screen();
  std::lock_guard<std::mutex> lock(screen.mutex);
  if (screen.forced_stream != nullptr) return true;
  const char* setting = std::getenv("RAYTIME_PROGRESS");
  if (setting != nullptr && std::string(setting) == "0") return false;
  return ::isatty(STDERR_FILENO) == 1;
}

void SetProgressOutput(std::FILE* stream, int columns) {
  ProgressScreen& screen = Screen();
  std::lock_guard<std::mutex> lock(screen.mutex);
  screen.forced_stream = stream;
  screen.forced_columns = columns;
  screen.line.clear();
}

void ClearProgressLine() {
  ProgressScreen& screen = Screen();
  std::lock_guard<std::mutex> lock(screen.mutex);
  EraseLocked(screen);
}

void RedrawProgressLine() {
  ProgressScreen& screen = Screen();
  std::lock_guard<std::mutex> lock(screen.mutex);
  DrawLocked(screen);
}

ProgressBar::ProgressBar(std::string task, int total)
    : task_(std::move(task)), total_(total), drawing_(ProgressBarsEnabled()) {}

ProgressBar::~ProgressBar() {
  if (!drawing_) return;
  ProgressScreen& screen = Screen();
  std::lock_guard<std::mutex> lock(screen.mutex);
  EraseLocked(screen);
  screen.line.clear();
}

void ProgressBar::Update(int done, const std::string& detail) {
  // Every long loop reports here, drawn or not: where an in-process run stops (core/interrupt.h).
  StopPoint();
  if (!drawing_) return;
  const auto now = std::chrono::steady_clock::now();
  ProgressScreen& screen = Screen();
  std::lock_guard<std::mutex> lock(screen.mutex);
  const bool last = total_ > 0 && done >= total_;
  if (!last && now - last_draw_ < std::chrono::milliseconds(100)) return;
  last_draw_ = now;
  screen.line =
      FormatProgressLine(task_, done, total_, std::chrono::duration<double>(now - start_).count(),
                         detail, ColumnsLocked(screen));
  DrawLocked(screen);
}

}  // namespace raytime
