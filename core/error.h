// Error types shared by every layer. Input problems are reported with the file (and line, where
// there is one) and what was expected, so a user can fix the input without reading code.
#pragma once

#include <stdexcept>
#include <string>

namespace raytime {

// The offset of the first byte of `text` at or after `from` outside a well-formed UTF-8 sequence
// (RFC 3629: no overlong forms, surrogates or code points beyond U+10FFFF), or std::string::npos.
size_t InvalidUtf8Offset(const std::string& text, size_t from = 0);

// "byte 0xFF at offset 5": the first byte of `text` outside UTF-8, for messages that name it
// without repeating it; "" when `text` is UTF-8.
std::string DescribeInvalidUtf8(const std::string& text);

// `text` with every byte outside a well-formed UTF-8 sequence written as \xHH. Messages quote file
// names and file contents, which on Linux are bytes; summary.json, HDF5 string attributes and the
// JSON on stdout hold only UTF-8, and a message must survive into them.
std::string EscapeInvalidUtf8(const std::string& text);

// Bad user input: a file that does not parse, a missing image, an unknown option key, data a
// stage cannot use (an image without a camera, a pair naming a keypoint that does not exist). The
// message is escaped (EscapeInvalidUtf8) so that reporting it never fails. The one exception type
// for what a user can fix: the CLI prints it without a trace and exits 2, and a stage adapter
// (pipelines/) that catches it adds the file names and rethrows it.
//
// std::invalid_argument stays for a broken precondition of a function (a numeric kernel handed
// arrays of different lengths, FitAlignment on collinear points): a bug, or a condition the caller
// checks for and catches itself (PointsFrame falls back to no points when no Sim(3) fits).
class InputError : public std::runtime_error {
 public:
  explicit InputError(const std::string& message)
      : std::runtime_error(EscapeInvalidUtf8(message)) {}
};

// "path:line: message" (line omitted when 0).
std::string Located(const std::string& path, int line, const std::string& message);

[[noreturn]] void ThrowInput(const std::string& path, int line, const std::string& message);

}  // namespace raytime
