// Reading an image file for the front end, with its structure checked before it is decoded.
//
// OpenCV's decoders accept damaged files: libjpeg decodes a truncated JPEG into an image whose
// missing part is flat grey and says so only in one warning on stderr that names no file (issue
// 13: 958 SIFT keypoints instead of 4,758), and features of half an image are a wrong result that
// looks right. So a JPEG must reach its end-of-image marker through well-formed segments and a PNG
// its IEND chunk; this walks the segment and chunk headers once (a scan over the compressed data
// for the next marker, no decoding), far cheaper than the decode that follows.
#pragma once

#include <cstdint>
#include <opencv2/core.hpp>
#include <string>
#include <vector>

namespace raytime {

// Throws InputError naming `path` and what is wrong (e.g. "truncated JPEG: no end-of-image marker
// ...") when `bytes`, a whole file, is a JPEG or PNG whose structure ends early or is broken. Data
// after a JPEG's end-of-image marker or a PNG's IEND chunk is allowed (some cameras append it), as
// are progressive JPEGs (several scans) and EXIF thumbnails (inside an APP1 segment). Other formats
// pass unchecked: their decoder is the only check.
void CheckImageStructure(const std::string& path, const std::vector<uint8_t>& bytes);

// Reads and decodes the image at `path` as cv::imread(path, flags) does (including the EXIF
// orientation), after CheckImageStructure. A missing, unreadable, damaged or undecodable file is
// an InputError naming it.
cv::Mat ReadImage(const std::string& path, int flags);

}  // namespace raytime
