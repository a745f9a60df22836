#include "report/sweep_row.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <limits>
#include <type_traits>

#include "core/atomic_file.h"
#include "core/error.h"
#include "core/json_fields.h"

namespace raytime {

using nlohmann::json;

json SweepSplatResult::ToJson() const { return FieldsToJson(*this); }

SweepSplatResult SweepSplatResult::FromJson(const json& object) {
  return FieldsFromJson<SweepSplatResult>(object);
}

namespace {

std::string NumberText(double value) {
  if (!std::isfinite(value)) return "";
  char buffer[32];
  std::snprintf(buffer, sizeof(buffer), "%.17g", value);
  return buffer;
}

std::string Joined(const std::vector<std::string>& values) {
  std::string text;
  for (const auto& value : values) text += (text.empty() ? "" : ";") + value;
  return text;
}

}  // namespace

const std::string* SweepRow::Swept(const std::string& key) const {
  for (const auto& [name, value] : swept) {
    if (name == key) return &value;
  }
  return nullptr;
}

json SweepRow::ToJson() const {
  // Swept keys as [key, value] pairs: a JSON object would lose their order.
  json out = {{"run", run}, {"swept", json::array()}, {"status", status}};
  for (const auto& [key, value] : swept) out["swept"].push_back({key, value});
  if (!error.empty()) out["error"] = error;
  out["seconds"] = seconds;
  out["stage_seconds"] = stage_seconds;
  out["errors"] = json::object();
  for (const auto& [arm, by_alignment] : errors) {
    for (const auto& [alignment, e] : by_alignment) out["errors"][arm][alignment] = e;
  }
  out["pose_set_stage"] = pose_set_stage;
  out["guardrails_fired"] = guardrails_fired;
  out["warnings"] = warnings;
  if (!splat.empty()) {
    out["splat"] = json::object();
    for (const auto& [id, by_pose_set] : splat) {
      for (const auto& [pose_set, result] : by_pose_set) {
        out["splat"][id][pose_set] = result.ToJson();
      }
    }
  }
  return out;
}

SweepRow SweepRow::FromJson(const json& in, const std::string& where) {
  if (!in.is_object() || !in.contains("run") || !in.contains("status")) {
    throw InputError(where + ": not a sweep row (an object with 'run' and 'status')");
  }
  SweepRow row;
  try {
    row.run = in.at("run").get<std::string>();
    row.status = in.at("status").get<std::string>();
    row.error = in.value("error", "");
    row.seconds = in.value("seconds", 0.0);
    if (in.contains("swept")) {
      for (const auto& pair : in.at("swept")) {
        row.swept.emplace_back(pair.at(0).get<std::string>(), pair.at(1).get<std::string>());
      }
    }
    if (in.contains("stage_seconds")) {
      for (const auto& [id, value] : in.at("stage_seconds").items()) {
        row.stage_seconds[id] =
            value.is_number() ? value.get<double>() : std::numeric_limits<double>::quiet_NaN();
      }
    }
    if (in.contains("errors")) {
      for (const auto& [arm, by_alignment] : in.at("errors").items()) {
        for (const auto& [alignment, e] : by_alignment.items()) {
          row.errors[arm][alignment] = e.get<PoseErrorStatistics>();
        }
      }
    }
    if (in.contains("pose_set_stage")) {
      row.pose_set_stage = in.at("pose_set_stage").get<std::map<std::string, std::string>>();
    }
    if (in.contains("guardrails_fired")) {
      row.guardrails_fired =
          in.at("guardrails_fired").get<std::map<std::string, std::vector<std::string>>>();
    }
    if (in.contains("warnings")) row.warnings = in.at("warnings").get<std::vector<std::string>>();
    if (in.contains("splat")) {
      for (const auto& [id, by_pose_set] : in.at("splat").items()) {
        for (const auto& [pose_set, result] : by_pose_set.items()) {
          if (!result.is_object())
            throw InputError(where + ": splat." + id + "." + pose_set + " is not an object");
          row.splat[id][pose_set] = SweepSplatResult::FromJson(result);
        }
      }
    }
  } catch (const json::exception& e) {
    throw InputError(where + ": malformed sweep row: " + e.what());
  }
  return row;
}

std::vector<std::pair<std::string, std::string>> SweepRow::Columns() const {
  std::vector<std::pair<std::string, std::string>> columns = {{"run", run}};
  for (const auto& [key, value] : swept) columns.emplace_back(key, value);
  columns.emplace_back("status", status);
  columns.emplace_back("error", error);
  columns.emplace_back("seconds", NumberText(seconds));
  for (const auto& [id, value] : stage_seconds) {
    columns.emplace_back("seconds." + id, NumberText(value));
  }
  for (const auto& [arm, by_alignment] : errors) {
    for (const auto& [alignment, e] : by_alignment) {
      const std::string prefix = "metrics." + arm + "." + alignment + ".";
      PoseErrorStatistics::VisitFields(e, [&](const char* field, const auto& value) {
        using Field = std::decay_t<decltype(value)>;
        if constexpr (std::is_same_v<Field, bool>) {
          columns.emplace_back(prefix + field, value ? "true" : "false");
        } else if constexpr (std::is_floating_point_v<Field>) {
          columns.emplace_back(prefix + field, NumberText(value));
        } else {
          columns.emplace_back(prefix + field, std::to_string(value));
        }
      });
    }
  }
  for (const auto& [id, by_pose_set] : splat) {
    for (const auto& [pose_set, r] : by_pose_set) {
      const std::string prefix = "metrics." + id + "." + pose_set + ".";
      SweepSplatResult::VisitFields(r, [&](const char* field, const auto& value) {
        if constexpr (std::is_floating_point_v<std::decay_t<decltype(value)>>) {
          columns.emplace_back(prefix + field, NumberText(value));
        } else {
          columns.emplace_back(prefix + field, value);
        }
      });
    }
  }
  for (const auto& [id, fired] : guardrails_fired) {
    columns.emplace_back("guardrails." + id, Joined(fired));
  }
  columns.emplace_back("warnings", Joined(warnings));
  return columns;
}

std::string CsvField(const std::string& text) {
  if (text.find_first_of(",\"\r\n") == std::string::npos) return text;
  std::string quoted = "\"";
  for (char c : text) quoted += c == '"' ? std::string("\"\"") : std::string(1, c);
  return quoted + "\"";
}

void WriteSweepTables(const std::string& workdir, const std::vector<SweepRow>& rows) {
  std::vector<std::string> header;
  std::vector<std::map<std::string, std::string>> cells;
  for (const SweepRow& row : rows) {
    std::map<std::string, std::string> by_column;
    for (const auto& [column, value] : row.Columns()) {
      if (std::find(header.begin(), header.end(), column) == header.end()) {
        header.push_back(column);
      }
      by_column[column] = value;
    }
    cells.push_back(std::move(by_column));
  }
  std::string csv;
  for (size_t c = 0; c < header.size(); ++c) csv += (c ? "," : "") + CsvField(header[c]);
  csv += "\n";
  for (const auto& row : cells) {
    for (size_t c = 0; c < header.size(); ++c) {
      const auto it = row.find(header[c]);
      csv += (c ? "," : "") + (it == row.end() ? std::string() : CsvField(it->second));
    }
    csv += "\n";
  }
  json table = json::array();
  for (const SweepRow& row : rows) table.push_back(row.ToJson());
  WriteTextFileAtomically((std::filesystem::path(workdir) / "sweep.csv").string(), csv);
  WriteTextFileAtomically((std::filesystem::path(workdir) / "sweep.json").string(), table.dump(2));
}

std::vector<SweepRow> ReadSweepRows(const std::string& path) {
  const std::string text = ReadTextFile(path);
  json rows;
  try {
    rows = json::parse(text);
  } catch (const json::parse_error& e) {
    const size_t end = std::min<size_t>(e.byte, text.size());
    const int line = 1 + static_cast<int>(std::count(text.begin(), text.begin() + end, '\n'));
    ThrowInput(path, line,
               "not valid JSON (expected the sweep.json `raytime run` writes for a sweep): " +
                   std::string(e.what()));
  } catch (const json::exception& e) {  // out_of_range for a number beyond double (1e999)
    ThrowInput(path, 0,
               "not valid JSON (expected the sweep.json `raytime run` writes for a sweep): " +
                   std::string(e.what()));
  }
  if (!rows.is_array()) {
    ThrowInput(path, 0,
               "expected a JSON array of sweep rows, got " + std::string(rows.type_name()));
  }
  std::vector<SweepRow> out;
  for (size_t i = 0; i < rows.size(); ++i) {
    out.push_back(SweepRow::FromJson(rows[i], path + ": sweep row " + std::to_string(i + 1)));
  }
  return out;
}

}  // namespace raytime
