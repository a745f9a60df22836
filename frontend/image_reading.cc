#include "frontend/image_reading.h"

#include <cerrno>
#include <cstring>
#include <fstream>
#include <opencv2/imgcodecs.hpp>

#include "core/error.h"

namespace raytime {
namespace {

// JPEG markers (ITU-T T.81, Table B.1).
constexpr uint8_t kStartOfImage = 0xD8;
constexpr uint8_t kEndOfImage = 0xD9;
constexpr uint8_t kStartOfScan = 0xDA;
constexpr uint8_t kFirstRestart = 0xD0;  // RST0..RST7: no length, only inside scans
constexpr uint8_t kLastRestart = 0xD7;
constexpr uint8_t kTemporary = 0x01;  // TEM: no length

constexpr uint8_t kPngSignature[8] = {0x89, 'P', 'N', 'G', '\r', '\n', 0x1A, '\n'};

std::string HexDigits(uint8_t value) {
  static const char kDigits[] = "0123456789ABCDEF";
  return {kDigits[value >> 4], kDigits[value & 15]};
}

std::string Hex(uint8_t value) { return "0x" + HexDigits(value); }

// "marker 0xFFDA" as T.81 writes markers.
std::string Marker(uint8_t marker) { return "marker 0xFF" + HexDigits(marker); }

bool IsJpeg(const std::vector<uint8_t>& b) {
  return b.size() >= 2 && b[0] == 0xFF && b[1] == kStartOfImage;
}

bool IsPng(const std::vector<uint8_t>& b) {
  return b.size() >= sizeof(kPngSignature) &&
         std::memcmp(b.data(), kPngSignature, sizeof(kPngSignature)) == 0;
}

// Walks the segments from SOI to EOI (T.81 §B.1.1): every marker but SOI, EOI, TEM and RSTn has a
// two-byte length that includes itself; after a scan header comes entropy-coded data, in which
// 0xFF is followed by a stuffed 0x00 or a restart marker until the next real marker (a progressive
// JPEG has several scans). An EXIF thumbnail is a whole JPEG inside an APP1 segment, skipped by
// its length, so its own EOI is never taken for the file's.
void CheckJpeg(const std::string& path, const std::vector<uint8_t>& b) {
  const size_t n = b.size();
  const auto truncated = [&](const std::string& where) {
    ThrowInput(path, 0,
               "truncated JPEG: no end-of-image marker (the file ends at byte " +
                   std::to_string(n) + ", " + where + ")");
  };
  size_t pos = 2;
  while (true) {
    if (pos >= n) truncated("after a complete segment");
    if (b[pos] != 0xFF) {
      ThrowInput(path, 0,
                 "corrupt JPEG: expected a marker at byte " + std::to_string(pos) + ", found " +
                     Hex(b[pos]));
    }
    while (pos < n && b[pos] == 0xFF) ++pos;  // fill bytes (T.81 §B.1.1.2)
    if (pos >= n) truncated("inside a marker");
    const uint8_t marker = b[pos++];
    if (marker == kEndOfImage) return;
    if (marker == kTemporary || (marker >= kFirstRestart && marker <= kLastRestart)) continue;
    if (marker == 0x00 || marker == kStartOfImage) {
      ThrowInput(
          path, 0,
          "corrupt JPEG: unexpected " + Marker(marker) + " at byte " + std::to_string(pos - 2));
    }
    if (pos + 2 > n) truncated("inside the length of the segment of " + Marker(marker));
    const size_t length = (size_t(b[pos]) << 8) | b[pos + 1];
    if (length < 2) {
      ThrowInput(path, 0,
                 "corrupt JPEG: the segment of " + Marker(marker) + " at byte " +
                     std::to_string(pos - 2) + " has length " + std::to_string(length));
    }
    if (pos + length > n) {
      truncated("inside the segment of " + Marker(marker) + " at byte " + std::to_string(pos - 2) +
                " and needs " + std::to_string(length) + " bytes");
    }
    pos += length;
    if (marker != kStartOfScan) continue;
    // Entropy-coded data: up to the next 0xFF that starts a marker.
    while (true) {
      const void* found = std::memchr(b.data() + pos, 0xFF, n - pos);
      if (found == nullptr || static_cast<const uint8_t*>(found) + 1 >= b.data() + n) {
        truncated("inside the compressed data of a scan");
      }
      pos = static_cast<const uint8_t*>(found) - b.data();
      const uint8_t next = b[pos + 1];
      if (next == 0x00 || (next >= kFirstRestart && next <= kLastRestart)) {
        pos += 2;
      } else {
        break;
      }
    }
  }
}

uint32_t BigEndian32(const uint8_t* p) {
  return (uint32_t(p[0]) << 24) | (uint32_t(p[1]) << 16) | (uint32_t(p[2]) << 8) | p[3];
}

// Walks the chunks from the signature to IEND (PNG spec §5.3): length (4 bytes, at most 2^31 - 1),
// type (4), data, CRC (4). The decoder checks the CRCs.
void CheckPng(const std::string& path, const std::vector<uint8_t>& b) {
  const size_t n = b.size();
  size_t pos = sizeof(kPngSignature);
  while (true) {
    if (pos + 8 > n) {
      ThrowInput(path, 0,
                 "truncated PNG: no IEND chunk (the file ends at byte " + std::to_string(n) +
                     ", inside a chunk header)");
    }
    const uint32_t length = BigEndian32(b.data() + pos);
    const std::string type(reinterpret_cast<const char*>(b.data() + pos + 4), 4);
    if (length > 0x7FFFFFFFu) {
      ThrowInput(path, 0,
                 "corrupt PNG: chunk at byte " + std::to_string(pos) + " has length " +
                     std::to_string(length));
    }
    if (pos + 12 + length > n) {
      ThrowInput(path, 0,
                 "truncated PNG: no IEND chunk (the file ends at byte " + std::to_string(n) +
                     ", inside chunk '" + type + "' that starts at byte " + std::to_string(pos) +
                     " and needs " + std::to_string(12 + length) + " bytes)");
    }
    if (type == "IEND") return;
    pos += 12 + length;
  }
}

}  // namespace

void CheckImageStructure(const std::string& path, const std::vector<uint8_t>& bytes) {
  if (IsJpeg(bytes)) {
    CheckJpeg(path, bytes);
  } else if (IsPng(bytes)) {
    CheckPng(path, bytes);
  }
}

cv::Mat ReadImage(const std::string& path, int flags) {
  std::ifstream in(path, std::ios::binary | std::ios::ate);
  if (!in) {
    ThrowInput(
        path, 0,
        std::string("cannot read the image (missing or unreadable: ") + std::strerror(errno) + ")");
  }
  const std::streamoff size = in.tellg();
  if (size < 0) ThrowInput(path, 0, "cannot read the image (not a regular file)");
  if (size == 0) ThrowInput(path, 0, "the image file is empty");
  std::vector<uint8_t> bytes(static_cast<size_t>(size));
  in.seekg(0);
  if (!in.read(reinterpret_cast<char*>(bytes.data()), bytes.size())) {
    ThrowInput(path, 0, "cannot read the image (read error)");
  }
  CheckImageStructure(path, bytes);
  // Decoded from the bytes already read: the file is read once.
  const cv::Mat image = cv::imdecode(bytes, flags);
  if (image.empty()) {
    ThrowInput(path, 0, "cannot decode the image (damaged, or not a format OpenCV decodes)");
  }
  return image;
}

}  // namespace raytime
