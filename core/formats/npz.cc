#include "core/formats/npz.h"

#include <cstdint>
#include <cstring>
#include <fstream>
#include <vector>

#include "core/error.h"

namespace raytime {

namespace {

uint32_t Little(const std::vector<char>& bytes, size_t at, int n) {
  uint32_t value = 0;
  for (int i = n - 1; i >= 0; --i) value = (value << 8) | static_cast<uint8_t>(bytes[at + i]);
  return value;
}

// The value text of `key` in a .npy header dict, e.g. "'<f8'" or "(4, 4)".
std::string HeaderValue(const std::string& header, const std::string& key) {
  const size_t at = header.find("'" + key + "'");
  if (at == std::string::npos) return "";
  size_t start = header.find(':', at);
  if (start == std::string::npos) return "";
  ++start;
  while (start < header.size() && header[start] == ' ') ++start;
  size_t end = start;
  if (header[start] == '(') {
    end = header.find(')', start) + 1;
  } else {
    while (end < header.size() && header[end] != ',' && header[end] != '}') ++end;
  }
  return header.substr(start, end - start);
}

Eigen::MatrixXd ParseNpy(const std::string& path, const std::string& entry,
                         const std::vector<char>& bytes, size_t begin, size_t size) {
  const auto fail = [&](const std::string& message) {
    ThrowInput(path, 0, "entry " + entry + ": " + message);
  };
  if (size < 10 || std::memcmp(&bytes[begin], "\x93NUMPY", 6) != 0) fail("not a .npy array");
  const int major = static_cast<uint8_t>(bytes[begin + 6]);
  const size_t header_length =
      major == 1 ? Little(bytes, begin + 8, 2) : Little(bytes, begin + 8, 4);
  const size_t header_start = begin + (major == 1 ? 10 : 12);
  if (header_start + header_length > begin + size) fail("truncated .npy header");
  const std::string header(&bytes[header_start], header_length);
  const std::string descr = HeaderValue(header, "descr");
  const bool fortran = HeaderValue(header, "fortran_order") == "True";
  int item = 0;
  if (descr == "'<f8'") item = 8;
  if (descr == "'<f4'") item = 4;
  if (item == 0) fail("dtype " + descr + " is not little-endian float32 or float64");
  std::vector<long> shape;
  const std::string dims = HeaderValue(header, "shape");
  for (size_t i = 1; i + 1 < dims.size();) {
    size_t end = dims.find_first_of(",)", i);
    const std::string number = dims.substr(i, end - i);
    if (number.find_first_not_of(' ') != std::string::npos) shape.push_back(std::stol(number));
    i = end + 1;
  }
  if (shape.empty() || shape.size() > 2) fail("shape " + dims + " is not 1-D or 2-D");
  const long rows = shape[0], cols = shape.size() == 2 ? shape[1] : 1;
  const size_t data = header_start + header_length;
  if (data + static_cast<size_t>(rows * cols * item) > begin + size) fail("truncated data");
  Eigen::MatrixXd matrix(rows, cols);
  for (long k = 0; k < rows * cols; ++k) {
    double value;
    if (item == 8) {
      std::memcpy(&value, &bytes[data + 8 * k], 8);
    } else {
      float single;
      std::memcpy(&single, &bytes[data + 4 * k], 4);
      value = single;
    }
    const long r = fortran ? k % rows : k / cols, c = fortran ? k / rows : k % cols;
    matrix(r, c) = value;
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
    if (at + 46 > bytes.size() || Little(bytes, at, 4) != 0x02014b50) {
      ThrowInput(path, 0, "damaged ZIP central directory");
    }
    const uint32_t method = Little(bytes, at + 10, 2);
    const uint32_t compressed = Little(bytes, at + 20, 4);
    const uint32_t name_length = Little(bytes, at + 28, 2);
    const uint32_t extra_length = Little(bytes, at + 30, 2);
    const uint32_t comment_length = Little(bytes, at + 32, 2);
    const uint32_t local = Little(bytes, at + 42, 4);
    std::string name(&bytes[at + 46], name_length);
    at += 46 + name_length + extra_length + comment_length;
    if (method != 0) {
      ThrowInput(path, 0,
                 "entry " + name +
                     " is compressed; raytime reads .npz archives written by np.savez (stored), "
                     "not np.savez_compressed");
    }
    if (local + 30 > bytes.size() || Little(bytes, local, 4) != 0x04034b50) {
      ThrowInput(path, 0, "entry " + name + ": damaged ZIP local header");
    }
    const size_t data = local + 30 + Little(bytes, local + 26, 2) + Little(bytes, local + 28, 2);
    if (data + compressed > bytes.size()) ThrowInput(path, 0, "entry " + name + " is truncated");
    if (name.size() > 4 && name.compare(name.size() - 4, 4, ".npy") == 0) {
      name.erase(name.size() - 4);
    }
    arrays[name] = ParseNpy(path, name, bytes, data, compressed);
  }
  return arrays;
}

}  // namespace raytime
