#include "formats/npz.h"

#include <cstdint>
#include <cstring>
#include <fstream>
#include <string_view>
#include <vector>

#include "core/error.h"
#include "formats/text_util.h"

namespace raytime {

namespace {

// Larger than any camera file's array; keeps rows and columns within Eigen's index type.
constexpr uint64_t kMaxDimension = uint64_t{1} << 31;

uint32_t Little(const std::vector<char>& bytes, size_t at, int n) {
  uint32_t value = 0;
  for (int i = n - 1; i >= 0; --i) value = (value << 8) | static_cast<uint8_t>(bytes[at + i]);
  return value;
}

// The value text of `key` in a .npy header dict, e.g. "'<f8'" or "(4, 4)"; "" when absent (or a
// tuple without its closing parenthesis).
std::string HeaderValue(const std::string& header, const std::string& key) {
  const size_t at = header.find("'" + key + "'");
  if (at == std::string::npos) return "";
  size_t start = header.find(':', at);
  if (start == std::string::npos) return "";
  ++start;
  while (start < header.size() && header[start] == ' ') ++start;
  size_t end = start;
  if (start < header.size() && header[start] == '(') {
    end = header.find(')', start);
    if (end == std::string::npos) return "";
    ++end;
  } else {
    while (end < header.size() && header[end] != ',' && header[end] != '}') ++end;
  }
  return header.substr(start, end - start);
}

// The dimensions of a shape tuple such as "(4, 4)", "(4,)" or "()"; false unless every one is a
// whole number >= 0.
bool ParseShape(const std::string& tuple, std::vector<uint64_t>* shape) {
  if (tuple.size() < 2 || tuple.front() != '(' || tuple.back() != ')') return false;
  const std::string inside = tuple.substr(1, tuple.size() - 2);
  size_t start = 0;
  while (start <= inside.size()) {
    size_t comma = inside.find(',', start);
    if (comma == std::string::npos) comma = inside.size();
    const std::string_view field =
        text::Trim(std::string_view(inside).substr(start, comma - start));
    if (!field.empty()) {
      uint64_t dimension = 0;
      if (!text::ParseInt(field, &dimension)) return false;
      shape->push_back(dimension);
    } else if (comma < inside.size()) {
      return false;  // "(,4)" or "(4,,4)"; only a trailing comma may be empty ("(4,)")
    }
    start = comma + 1;
  }
  return true;
}

Eigen::MatrixXd ParseNpy(const std::string& path, const std::string& entry,
                         const std::vector<char>& bytes, size_t begin, size_t size) {
  const auto fail = [&](const std::string& message) {
    ThrowInput(path, 0, "entry " + entry + ": " + message);
  };
  if (size < 10 || std::memcmp(&bytes[begin], "\x93NUMPY", 6) != 0) fail("not a .npy array");
  // Format 1.0 has a 2-byte header length, 2.0 and 3.0 a 4-byte one.
  const int major = static_cast<uint8_t>(bytes[begin + 6]);
  if (major < 1 || major > 3) fail(".npy format version " + std::to_string(major) + " unknown");
  const size_t length_bytes = major == 1 ? 2 : 4;
  if (size < 8 + length_bytes) fail("truncated .npy header");
  const size_t header_length = Little(bytes, begin + 8, static_cast<int>(length_bytes));
  const size_t header_offset = 8 + length_bytes;
  if (header_length > size - header_offset) fail("truncated .npy header");
  const std::string header(&bytes[begin + header_offset], header_length);
  const std::string descr = HeaderValue(header, "descr");
  const bool fortran = HeaderValue(header, "fortran_order") == "True";
  int item = 0;
  if (descr == "'<f8'") item = 8;
  if (descr == "'<f4'") item = 4;
  if (item == 0) fail("dtype " + descr + " is not little-endian float32 or float64");
  std::vector<uint64_t> shape;
  const std::string dims = HeaderValue(header, "shape");
  if (dims.empty()) fail("no 'shape': (...) in the .npy header");
  if (!ParseShape(dims, &shape) || shape.empty() || shape.size() > 2) {
    fail("shape " + dims + " is not 1-D or 2-D (whole numbers >= 0)");
  }
  const uint64_t rows = shape[0], cols = shape.size() == 2 ? shape[1] : 1;
  if (rows > kMaxDimension || cols > kMaxDimension) fail("shape " + dims + " is too large");
  // Within the entry's bytes, without overflowing rows * cols * item.
  const uint64_t available = (size - header_offset - header_length) / item;
  if (cols != 0 && rows > available / cols) fail("truncated data");
  const size_t data = begin + header_offset + header_length;
  Eigen::MatrixXd matrix(static_cast<Eigen::Index>(rows), static_cast<Eigen::Index>(cols));
  for (uint64_t k = 0; k < rows * cols; ++k) {
    double value;
    if (item == 8) {
      std::memcpy(&value, &bytes[data + 8 * k], 8);
    } else {
      float single;
      std::memcpy(&single, &bytes[data + 4 * k], 4);
      value = single;
    }
    const uint64_t r = fortran ? k % rows : k / cols, c = fortran ? k / rows : k % cols;
    matrix(static_cast<Eigen::Index>(r), static_cast<Eigen::Index>(c)) = value;
  }
  return matrix;
}

}  // namespace

std::map<std::string, Eigen::MatrixXd> ReadNpz(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) ThrowInput(path, 0, "file not found or not readable");
  const std::vector<char> bytes((std::istreambuf_iterator<char>(in)), {});
  // The end-of-central-directory record: its signature within the last 64 KiB + 22 bytes.
  size_t eocd = std::string::npos;
  if (bytes.size() >= 22) {
    const size_t lowest = bytes.size() > 65536 + 22 ? bytes.size() - 65536 - 22 : 0;
    for (size_t i = bytes.size() - 22 + 1; i-- > lowest;) {
      if (Little(bytes, i, 4) == 0x06054b50) {
        eocd = i;
        break;
      }
    }
  }
  if (eocd == std::string::npos) ThrowInput(path, 0, "not a .npz (ZIP) archive");
  const uint32_t entries = Little(bytes, eocd + 10, 2);
  size_t at = Little(bytes, eocd + 16, 4);
  std::map<std::string, Eigen::MatrixXd> arrays;
  for (uint32_t e = 0; e < entries; ++e) {
    if (at > bytes.size() || bytes.size() - at < 46 || Little(bytes, at, 4) != 0x02014b50) {
      ThrowInput(path, 0, "damaged ZIP central directory");
    }
    const uint32_t method = Little(bytes, at + 10, 2);
    const uint32_t compressed = Little(bytes, at + 20, 4);
    const uint32_t name_length = Little(bytes, at + 28, 2);
    const uint32_t extra_length = Little(bytes, at + 30, 2);
    const uint32_t comment_length = Little(bytes, at + 32, 2);
    const uint32_t local = Little(bytes, at + 42, 4);
    if (bytes.size() - at - 46 < size_t{name_length} + extra_length + comment_length) {
      ThrowInput(path, 0, "damaged ZIP central directory (an entry runs past the end of the file)");
    }
    std::string name(&bytes[at + 46], name_length);
    at += 46 + name_length + extra_length + comment_length;
    if (method != 0) {
      ThrowInput(path, 0,
                 "entry " + name +
                     " is compressed; raytime reads .npz archives written by np.savez (stored), "
                     "not np.savez_compressed");
    }
    if (size_t{local} + 30 > bytes.size() || Little(bytes, local, 4) != 0x04034b50) {
      ThrowInput(path, 0, "entry " + name + ": damaged ZIP local header");
    }
    const size_t data =
        size_t{local} + 30 + Little(bytes, local + 26, 2) + Little(bytes, local + 28, 2);
    if (data > bytes.size() || compressed > bytes.size() - data) {
      ThrowInput(path, 0, "entry " + name + " is truncated");
    }
    if (name.size() > 4 && name.compare(name.size() - 4, 4, ".npy") == 0) {
      name.erase(name.size() - 4);
    }
    arrays[name] = ParseNpy(path, name, bytes, data, compressed);
  }
  return arrays;
}

}  // namespace raytime
