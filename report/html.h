// Small pieces the run page and the campaign page are written with (issue 32): plain HTML text,
// numbers as a person reads them, images inlined as data URIs so a page opens offline on its own.
#pragma once

#include <nlohmann/json.hpp>
#include <string>
#include <vector>

namespace raytime {

// `text` with &, <, > and " escaped: safe inside an element and a quoted attribute.
std::string HtmlEscape(const std::string& text);

// `value` with `digits` significant digits; "–" for a value that is not a finite number.
std::string HtmlNumber(double value, int digits = 3);
std::string HtmlNumber(const nlohmann::json& value, int digits = 3);

// One table row: each of `cells` (HTML already) in a `tag` element ("td", or "th" for a header
// row), the row's id attribute `id` when it is not empty.
std::string HtmlRow(const std::vector<std::string>& cells, const char* tag = "td",
                    const std::string& id = std::string());

// Members of JSON that other runs wrote (summaries, older versions), read without throwing: the
// member under `key`, or null / an empty object / an empty array / `otherwise` when `json` is no
// object or the member is absent or of another type.
const nlohmann::json& JsonAt(const nlohmann::json& json, const char* key);
nlohmann::json JsonObject(const nlohmann::json& json, const char* key);
nlohmann::json JsonArray(const nlohmann::json& json, const char* key);
std::string JsonText(const nlohmann::json& json, const char* key,
                     const std::string& otherwise = std::string());

// The image at `path` scaled to `width` pixels wide, as a JPEG data URI ("" when it cannot be
// read: the page says so instead of failing). Decoded at the smallest of 1/8, 1/4, 1/2 and full
// size that is at least `width` wide (a JPEG's DCT scaling: a 1920×1440 frame in a few
// milliseconds).
std::string ThumbnailDataUri(const std::string& path, int width);

// The CSS every raytime page shares (tables, status colours).
const char* PageStyle();

}  // namespace raytime
