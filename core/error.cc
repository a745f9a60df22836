#include "core/error.h"

#include <cstdio>

namespace raytime {

size_t InvalidUtf8Offset(const std::string& text, size_t from) {
  const auto byte = [&](size_t i) { return static_cast<unsigned char>(text[i]); };
  size_t i = from;
  while (i < text.size()) {
    const unsigned char lead = byte(i);
    size_t length = 0;
    unsigned char low = 0x80, high = 0xBF;  // the range of the second byte
    if (lead < 0x80) {
      length = 1;
    } else if (lead >= 0xC2 && lead <= 0xDF) {
      length = 2;
    } else if (lead >= 0xE0 && lead <= 0xEF) {
      length = 3;
      if (lead == 0xE0) low = 0xA0;   // overlong
      if (lead == 0xED) high = 0x9F;  // surrogates
    } else if (lead >= 0xF0 && lead <= 0xF4) {
      length = 4;
      if (lead == 0xF0) low = 0x90;   // overlong
      if (lead == 0xF4) high = 0x8F;  // beyond U+10FFFF
    } else {
      return i;
    }
    if (i + length > text.size()) return i;
    for (size_t k = 1; k < length; ++k) {
      const unsigned char lo = k == 1 ? low : 0x80, hi = k == 1 ? high : 0xBF;
      if (byte(i + k) < lo || byte(i + k) > hi) return i;
    }
    i += length;
  }
  return std::string::npos;
}

std::string EscapeInvalidUtf8(const std::string& text) {
  std::string out;
  size_t begin = 0;
  while (begin < text.size()) {
    const size_t bad = InvalidUtf8Offset(text, begin);
    if (bad == std::string::npos) {
      out.append(text, begin, std::string::npos);
      break;
    }
    out.append(text, begin, bad - begin);
    char hex[8];
    std::snprintf(hex, sizeof(hex), "\\x%02X", static_cast<unsigned char>(text[bad]));
    out += hex;
    begin = bad + 1;
  }
  return out;
}

std::string DescribeInvalidUtf8(const std::string& text) {
  const size_t offset = InvalidUtf8Offset(text);
  if (offset == std::string::npos) return "";
  char hex[8];
  std::snprintf(hex, sizeof(hex), "0x%02X", static_cast<unsigned char>(text[offset]));
  return std::string("byte ") + hex + " at offset " + std::to_string(offset);
}

std::string Located(const std::string& path, int line, const std::string& message) {
  if (line > 0) return path + ":" + std::to_string(line) + ": " + message;
  return path + ": " + message;
}

void ThrowInput(const std::string& path, int line, const std::string& message) {
  throw InputError(Located(path, line, message));
}

}  // namespace raytime
