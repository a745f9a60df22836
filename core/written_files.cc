#include "core/written_files.h"

#include <algorithm>
#include <chrono>
#include <cstdint>
#include <ctime>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <sstream>
#include <stdexcept>
#include <vector>

#include "core/atomic_file.h"
#include "core/content_hash.h"

namespace fs = std::filesystem;
using nlohmann::json;

namespace raytime {
namespace {

// Files up to this size are also identified by their contents (a 3dgs folder's images, hundreds
// of megabytes in all, are each below it; a longer file is identified by size and time alone).
constexpr std::uintmax_t kHashedFileBytes = 64ull << 20;

int64_t ModificationNs(const fs::path& file) {
  const auto time = fs::last_write_time(file).time_since_epoch();
  return std::chrono::duration_cast<std::chrono::nanoseconds>(time).count();
}

// What identifies a file raytime wrote: its size and modification time (nanoseconds), which a
// user's edit or replacement changes, and for files up to kHashedFileBytes its contents, so that
// a copy of the folder (cp -r, which sets new times) is still raytime's.
json Stamp(const fs::path& file) {
  const std::uintmax_t size = fs::file_size(file);
  json stamp = {{"size", size}, {"mtime_ns", ModificationNs(file)}};
  if (size <= kHashedFileBytes) stamp["xxh3"] = HashFileContents(file.string());
  return stamp;
}

// Whether `file` is the one `stamp` records: same size, and the same time or the same contents.
bool Matches(const fs::path& file, const json& stamp) {
  if (!stamp.is_object() || stamp.value("size", std::uintmax_t(0)) != fs::file_size(file)) {
    return false;
  }
  if (stamp.value("mtime_ns", int64_t(0)) == ModificationNs(file)) return true;
  return stamp.contains("xxh3") && stamp["xxh3"] == HashFileContents(file.string());
}

// The record of `folder`: relative path -> stamp; empty when it has none or it does not parse
// (then nothing in the folder counts as raytime's).
json ReadRecord(const fs::path& folder) {
  std::ifstream in(folder / kWrittenFilesRecord);
  if (!in) return json::object();
  std::stringstream text;
  text << in.rdbuf();
  const json record = json::parse(text.str(), nullptr, false);
  if (!record.is_object() || !record.contains("files") || !record["files"].is_object()) {
    return json::object();
  }
  return record["files"];
}

bool IsFolder(const fs::path& path) {
  std::error_code error;
  return fs::is_directory(fs::symlink_status(path, error));
}

bool Exists(const fs::path& path) {
  std::error_code error;
  return fs::exists(fs::symlink_status(path, error));
}

// Whether the record lists a file below the folder `relative` ("" for the top).
bool RecordsBelow(const json& files, const std::string& relative) {
  const std::string prefix = relative + "/";
  const auto& map = files.get_ref<const json::object_t&>();
  const auto it = map.lower_bound(prefix);
  return it != map.end() && it->first.rfind(prefix, 0) == 0;
}

void CollectNotWritten(const fs::path& folder, const fs::path& relative, const json& files,
                       std::vector<std::string>* out) {
  for (const auto& entry : fs::directory_iterator(folder / relative)) {
    const fs::path rel = relative / entry.path().filename();
    const std::string key = rel.generic_string();
    if (relative.empty() && key == kWrittenFilesRecord) continue;
    if (IsFolder(entry.path())) {
      if (RecordsBelow(files, key)) {
        CollectNotWritten(folder, rel, files, out);
      } else {
        out->push_back(key);
      }
      continue;
    }
    const auto it = files.find(key);
    std::error_code error;
    const bool regular = fs::is_regular_file(fs::symlink_status(entry.path(), error));
    if (it == files.end() || !regular || !Matches(entry.path(), *it)) out->push_back(key);
  }
}

// The entries of the folder `entry` of `from`, as paths relative to `from`.
std::vector<std::string> ChildEntries(const std::string& from, const std::string& entry) {
  std::vector<std::string> children;
  for (const auto& child : fs::directory_iterator(fs::path(from) / entry)) {
    children.push_back((fs::path(entry) / child.path().filename()).generic_string());
  }
  return children;
}

void WriteRecord(const fs::path& folder, const json& files) {
  WriteTextFileAtomically(
      (folder / kWrittenFilesRecord).string(),
      json{{"what", "the files raytime wrote in this folder; it replaces or moves only these"},
           {"files", files}}
              .dump(1) +
          "\n");
}

}  // namespace

void RecordWrittenFiles(const std::string& folder) {
  json files = json::object();
  for (fs::recursive_directory_iterator it(folder), end; it != end; ++it) {
    if (IsFolder(it->path())) continue;
    const std::string key = fs::relative(it->path(), folder).generic_string();
    if (key == kWrittenFilesRecord) continue;
    files[key] = Stamp(it->path());
  }
  WriteRecord(folder, files);
}

void RecordWrittenFile(const std::string& folder, const std::string& relative) {
  json files = ReadRecord(folder);
  files[fs::path(relative).generic_string()] = Stamp(fs::path(folder) / relative);
  WriteRecord(folder, files);
}

std::vector<std::string> FilesNotWritten(const std::string& folder) {
  std::vector<std::string> out;
  if (!IsFolder(folder)) return out;
  CollectNotWritten(folder, "", ReadRecord(folder), &out);
  std::sort(out.begin(), out.end());
  return out;
}

std::vector<std::string> CollidingEntries(const std::vector<std::string>& entries,
                                          const std::string& from, const std::string& to) {
  std::vector<std::string> colliding;
  for (const std::string& entry : entries) {
    // A path through one of `to`'s files cannot be made.
    bool blocked = false;
    for (fs::path prefix = fs::path(entry).parent_path(); !prefix.empty() && !blocked;
         prefix = prefix.parent_path()) {
      blocked = Exists(fs::path(to) / prefix) && !IsFolder(fs::path(to) / prefix);
    }
    const fs::path source = fs::path(from) / entry, target = fs::path(to) / entry;
    if (blocked || (Exists(target) && !(IsFolder(source) && IsFolder(target)))) {
      colliding.push_back(entry);
    } else if (Exists(target)) {
      // Two folders: their contents must not collide either.
      for (const std::string& c : CollidingEntries(ChildEntries(from, entry), from, to)) {
        colliding.push_back(c);
      }
    }
  }
  return colliding;
}

void CarryEntriesOver(const std::vector<std::string>& entries, const std::string& from,
                      const std::string& to) {
  for (const std::string& entry : entries) {
    const fs::path source = fs::path(from) / entry, target = fs::path(to) / entry;
    if (IsFolder(source) && IsFolder(target)) {
      CarryEntriesOver(ChildEntries(from, entry), from, to);
      continue;
    }
    std::error_code error;
    fs::create_directories(target.parent_path(), error);
    fs::rename(source, target, error);
    if (error) {
      throw std::runtime_error("cannot move " + source.string() + " to " + target.string() + ": " +
                               error.message());
    }
  }
}

std::string UnusedPath(const std::string& wanted) {
  std::string path = wanted;
  for (int k = 1; Exists(path); ++k) path = wanted + "." + std::to_string(k);
  return path;
}

std::string DatedUnusedPath(const std::string& path) {
  return UnusedPath(path + "." + std::to_string(std::time(nullptr)));
}

}  // namespace raytime
