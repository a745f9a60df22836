#include "report/html.h"

#include <cmath>
#include <cstdio>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <vector>

#include "core/error.h"
#include "formats/capture.h"

namespace raytime {

std::string HtmlEscape(const std::string& text) {
  std::string out;
  out.reserve(text.size());
  for (const char c : text) {
    switch (c) {
      case '&':
        out += "&amp;";
        break;
      case '<':
        out += "&lt;";
        break;
      case '>':
        out += "&gt;";
        break;
      case '"':
        out += "&quot;";
        break;
      default:
        out += c;
    }
  }
  return out;
}

std::string HtmlNumber(double value, int digits) {
  if (!std::isfinite(value)) return "–";
  char buffer[64];
  std::snprintf(buffer, sizeof(buffer), "%.*g", digits, value);
  return buffer;
}

std::string HtmlNumber(const nlohmann::json& value, int digits) {
  return value.is_number() ? HtmlNumber(value.get<double>(), digits) : "–";
}

std::string HtmlRow(const std::vector<std::string>& cells, const char* tag, const std::string& id) {
  std::string row = id.empty() ? "<tr>" : "<tr id=\"" + HtmlEscape(id) + "\">";
  const std::string open = std::string("<") + tag + ">", close = std::string("</") + tag + ">";
  for (const std::string& cell : cells) row += open + cell + close;
  return row + "</tr>";
}

const nlohmann::json& JsonAt(const nlohmann::json& json, const char* key) {
  static const nlohmann::json kNull;
  if (!json.is_object()) return kNull;
  const auto it = json.find(key);
  return it == json.end() ? kNull : *it;
}

nlohmann::json JsonObject(const nlohmann::json& json, const char* key) {
  const nlohmann::json& member = JsonAt(json, key);
  return member.is_object() ? member : nlohmann::json::object();
}

nlohmann::json JsonArray(const nlohmann::json& json, const char* key) {
  const nlohmann::json& member = JsonAt(json, key);
  return member.is_array() ? member : nlohmann::json::array();
}

std::string JsonText(const nlohmann::json& json, const char* key, const std::string& otherwise) {
  const nlohmann::json& member = JsonAt(json, key);
  return member.is_string() ? member.get<std::string>() : otherwise;
}

namespace {

std::string Base64(const std::vector<unsigned char>& bytes) {
  static const char kAlphabet[] =
      "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
  std::string out;
  out.reserve((bytes.size() + 2) / 3 * 4);
  for (size_t i = 0; i < bytes.size(); i += 3) {
    const unsigned value = (bytes[i] << 16) | (i + 1 < bytes.size() ? bytes[i + 1] << 8 : 0) |
                           (i + 2 < bytes.size() ? bytes[i + 2] : 0);
    out += kAlphabet[(value >> 18) & 63];
    out += kAlphabet[(value >> 12) & 63];
    out += i + 1 < bytes.size() ? kAlphabet[(value >> 6) & 63] : '=';
    out += i + 2 < bytes.size() ? kAlphabet[value & 63] : '=';
  }
  return out;
}

}  // namespace

std::string ThumbnailDataUri(const std::string& path, int width) {
  if (width <= 0) return std::string();
  // The strongest reduction the decoder offers (a JPEG's DCT scaling by 1/2, 1/4 or 1/8) that
  // still leaves `width` pixels: a 1920-pixel frame decodes at 1/8, a 720-pixel one at 1/4, a
  // small render whole. A file whose header ReadImageSize does not know (neither JPEG nor PNG) is
  // left to the decoder whole.
  int reduction = 1;
  try {
    const int full_width = ReadImageSize(path).width;
    while (reduction < 8 && full_width / (2 * reduction) >= width) reduction *= 2;
  } catch (const InputError&) {
  }
  const int flag = reduction == 8   ? cv::IMREAD_REDUCED_COLOR_8
                   : reduction == 4 ? cv::IMREAD_REDUCED_COLOR_4
                   : reduction == 2 ? cv::IMREAD_REDUCED_COLOR_2
                                    : cv::IMREAD_COLOR;
  cv::Mat image = cv::imread(path, flag);
  if (image.empty()) return std::string();
  if (image.cols > width) {
    const int height = std::max(
        1, static_cast<int>(std::lround(static_cast<double>(image.rows) * width / image.cols)));
    cv::resize(image, image, cv::Size(width, height), 0, 0, cv::INTER_AREA);
  }
  std::vector<unsigned char> jpeg;
  if (!cv::imencode(".jpg", image, jpeg, {cv::IMWRITE_JPEG_QUALITY, 65})) return std::string();
  return "data:image/jpeg;base64," + Base64(jpeg);
}

const char* PageStyle() {
  return "body{font-family:sans-serif;margin:2em;max-width:76em}"
         "table{border-collapse:collapse}td,th{border:1px solid #ccc;padding:2px 6px;"
         "text-align:right}td:first-child{text-align:left}.status.ok{color:#070}"
         ".status.ok_with_warnings{color:#a60}.status.failed,.status.interrupted,.error{color:#b00}"
         "svg,canvas{border:1px solid #ddd}";
}

}  // namespace raytime
