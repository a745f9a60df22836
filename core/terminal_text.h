// Text for a terminal (issue 47): what a log line quotes (file names, file contents) is shown,
// never obeyed.
#pragma once

#include <string>

namespace raytime {

// `text` with bytes outside UTF-8 escaped (EscapeInvalidUtf8) and every control character but the
// newline and the tab (C0, DEL, and C1 as U+0080..U+009F) written as \xHH or \u00HH: a file name
// with escape sequences in it retitled the terminal and recoloured the log.
std::string EscapeControlCharacters(const std::string& text);

}  // namespace raytime
