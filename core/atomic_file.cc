#include "core/atomic_file.h"

#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <sstream>

#include "core/error.h"

namespace fs = std::filesystem;

namespace raytime {

namespace {
std::string TemporarySibling(const std::string& path) {
  const fs::path p(path);
  return (p.parent_path() / ("." + p.filename().string() + ".tmp." + std::to_string(getpid())))
      .string();
}
}  // namespace

void WriteAtomically(const std::string& path,
                     const std::function<void(const std::string&)>& write) {
  const fs::path parent = fs::path(path).parent_path();
  if (!parent.empty()) fs::create_directories(parent);
  const std::string tmp = TemporarySibling(path);
  try {
    write(tmp);
    fs::rename(tmp, path);
  } catch (...) {
    std::error_code ignored;
    fs::remove(tmp, ignored);
    throw;
  }
}

void WriteDirectoryAtomically(const std::string& path,
                              const std::function<void(const std::string&)>& write) {
  const fs::path parent = fs::path(path).parent_path();
  if (!parent.empty()) fs::create_directories(parent);
  const std::string tmp = TemporarySibling(path);
  std::error_code ignored;
  fs::remove_all(tmp, ignored);
  try {
    fs::create_directories(tmp);
    write(tmp);
    const std::string old = tmp + ".old";
    fs::remove_all(old, ignored);
    if (fs::exists(path)) fs::rename(path, old);
    fs::rename(tmp, path);
    fs::remove_all(old, ignored);
  } catch (...) {
    fs::remove_all(tmp, ignored);
    throw;
  }
}

void WriteTextFileAtomically(const std::string& path, const std::string& contents) {
  WriteAtomically(path, [&](const std::string& tmp) {
    std::ofstream out(tmp, std::ios::binary);
    out << contents;
    out.close();
    if (!out) throw std::runtime_error("cannot write " + tmp);
  });
}

std::string ReadTextFile(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) ThrowInput(path, 0, "cannot open file for reading");
  std::ostringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

}  // namespace raytime
