// Locale-independent number parsing and printing shared by the text formats. std::from_chars /
// std::to_chars ignore the C locale, so a host program that sets a comma-decimal locale still
// reads and writes files other tools understand.
#pragma once

#include <cctype>
#include <charconv>
#include <cmath>
#include <string>
#include <string_view>
#include <system_error>
#include <vector>

#include "core/error.h"

namespace raytime::text {

inline std::vector<std::string_view> SplitWhitespace(std::string_view line) {
  std::vector<std::string_view> tokens;
  size_t i = 0;
  while (i < line.size()) {
    while (i < line.size() && std::isspace(static_cast<unsigned char>(line[i]))) ++i;
    const size_t start = i;
    while (i < line.size() && !std::isspace(static_cast<unsigned char>(line[i]))) ++i;
    if (i > start) tokens.push_back(line.substr(start, i - start));
  }
  return tokens;
}

inline std::string_view Trim(std::string_view s) {
  while (!s.empty() && std::isspace(static_cast<unsigned char>(s.front()))) s.remove_prefix(1);
  while (!s.empty() && std::isspace(static_cast<unsigned char>(s.back()))) s.remove_suffix(1);
  return s;
}

// Finite numbers only: a NaN or infinity in a pose or intrinsics file is always a mistake.
inline bool ParseDouble(std::string_view token, double* value) {
  const char* end = token.data() + token.size();
  const auto [ptr, ec] = std::from_chars(token.data(), end, *value);
  return ec == std::errc() && ptr == end && std::isfinite(*value);
}

template <typename Int>
bool ParseInt(std::string_view token, Int* value) {
  const char* end = token.data() + token.size();
  const auto [ptr, ec] = std::from_chars(token.data(), end, *value);
  return ec == std::errc() && ptr == end;
}

// 17 significant digits (printf's %.17g) so every double reads back bit-identical.
inline std::string FormatDouble(double value) {
  char buffer[32];
  const auto result =
      std::to_chars(buffer, buffer + sizeof(buffer), value, std::chars_format::general, 17);
  return std::string(buffer, result.ptr);
}

// The lines of `contents` without newlines or trailing carriage returns; line k (1-based) of the
// file is element k - 1. The views point into `contents`.
inline std::vector<std::string_view> SplitLines(const std::string& contents) {
  std::vector<std::string_view> lines;
  size_t start = 0;
  while (start < contents.size()) {
    size_t end = contents.find('\n', start);
    if (end == std::string::npos) end = contents.size();
    std::string_view line(contents.data() + start, end - start);
    if (!line.empty() && line.back() == '\r') line.remove_suffix(1);
    lines.push_back(line);
    start = end + 1;
  }
  return lines;
}

// Every whitespace-separated number of a file's `contents`, with the line each stands on; an
// InputError naming `path` and the line at a token that is not a finite number.
struct NumbersWithLines {
  std::vector<double> values;
  std::vector<int> lines;  // 1-based, one per value
};
inline NumbersWithLines ParseNumbers(const std::string& path, const std::string& contents) {
  NumbersWithLines numbers;
  const auto lines = SplitLines(contents);
  for (size_t k = 0; k < lines.size(); ++k) {
    for (const std::string_view token : SplitWhitespace(lines[k])) {
      double value;
      if (!ParseDouble(token, &value)) {
        ThrowInput(path, static_cast<int>(k + 1),
                   "'" + std::string(token) + "' is not a finite number");
      }
      numbers.values.push_back(value);
      numbers.lines.push_back(static_cast<int>(k + 1));
    }
  }
  return numbers;
}

}  // namespace raytime::text
