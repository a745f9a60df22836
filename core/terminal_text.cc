#include "core/terminal_text.h"

#include <cstdio>

#include "core/error.h"

namespace raytime {

std::string EscapeControlCharacters(const std::string& text) {
  const std::string valid = EscapeInvalidUtf8(text);
  std::string out;
  out.reserve(valid.size());
  char hex[8];
  for (size_t i = 0; i < valid.size(); ++i) {
    const unsigned char c = static_cast<unsigned char>(valid[i]);
    const bool c0 = (c < 0x20 && c != '\n' && c != '\t') || c == 0x7F;
    // U+0080..U+009F: 0xC2 followed by 0x80..0x9F.
    const bool c1 = c == 0xC2 && i + 1 < valid.size() &&
                    static_cast<unsigned char>(valid[i + 1]) >= 0x80 &&
                    static_cast<unsigned char>(valid[i + 1]) <= 0x9F;
    if (c0) {
      std::snprintf(hex, sizeof(hex), "\\x%02X", c);
      out += hex;
    } else if (c1) {
      std::snprintf(hex, sizeof(hex), "\\x%02X", static_cast<unsigned char>(valid[++i]));
      out += "\\u00";
      out += hex + 2;
    } else {
      out += valid[i];
    }
  }
  return out;
}

}  // namespace raytime
