#include "pipelines/pipeline.h"

#include <fcntl.h>
#include <sys/file.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <filesystem>
#include <string>

#include "core/error.h"
#include "pipelines/stage.h"
#include "pipelines/sweep.h"

namespace fs = std::filesystem;

namespace raytime {
namespace {

// One run at a time in a work directory: two runs into one interleave their stages' outputs
// (the summary of one beside the refined poses of the other). An exclusive flock on
// WORKDIR/.raytime/run.lock, released by the kernel however the holder ends (kill -9 included);
// the file holds the holder's pid, for the refusal's message. A file system that cannot lock
// (some network mounts) runs unlocked rather than not at all.
class WorkdirLock {
 public:
  explicit WorkdirLock(const std::string& workdir) {
    const fs::path dir = fs::path(workdir) / ".raytime";
    std::error_code error;
    fs::create_directories(dir, error);
    if (error) {
      // Name the part of the path in the way (a file where a folder goes), not only the whole.
      fs::path blocking = dir;
      std::error_code ignored;
      while (!blocking.empty() && !fs::exists(blocking, ignored)) blocking = blocking.parent_path();
      const bool file_in_way = !blocking.empty() && !fs::is_directory(blocking, ignored);
      throw InputError(workdir + ": cannot create the work directory (" + error.message() +
                       (file_in_way ? ": " + blocking.string() + " is a file, not a folder" : "") +
                       ")");
    }
    const std::string path = (dir / "run.lock").string();
    fd_ = ::open(path.c_str(), O_CREAT | O_RDWR | O_CLOEXEC, 0644);
    if (fd_ < 0) {
      throw InputError(workdir + ": cannot write in the work directory (" + std::strerror(errno) +
                       ")");
    }
    if (::flock(fd_, LOCK_EX | LOCK_NB) != 0) {
      const int reason = errno;
      if (reason == EWOULDBLOCK) {
        char buffer[32] = {0};
        const ssize_t n = ::pread(fd_, buffer, sizeof(buffer) - 1, 0);
        const std::string pid = n > 0 ? std::string(buffer, static_cast<size_t>(n)) : "?";
        ::close(fd_);
        fd_ = -1;
        throw InputError(workdir + ": another raytime run (pid " + pid +
                         ") is using this work directory; wait for it to end, or give this run "
                         "another --workdir");
      }
      return;  // no locks on this file system
    }
    const std::string pid = std::to_string(::getpid());
    if (::ftruncate(fd_, 0) == 0) {
      [[maybe_unused]] const ssize_t written = ::pwrite(fd_, pid.data(), pid.size(), 0);
    }
  }
  ~WorkdirLock() {
    if (fd_ >= 0) ::close(fd_);
  }
  WorkdirLock(const WorkdirLock&) = delete;
  WorkdirLock& operator=(const WorkdirLock&) = delete;

 private:
  int fd_ = -1;
};

// The pipeline's stages configured once for the checks below, with their ids; a stage whose
// options do not configure is left out (said by the stage when it runs).
using ConfiguredStageList = std::vector<std::pair<std::string, std::unique_ptr<Stage>>>;
ConfiguredStageList ConfiguredStages(const PipelineSpec& spec) {
  ConfiguredStageList stages;
  for (const PipelineStageSpec& stage_spec : spec.stages) {
    std::unique_ptr<Stage> stage =
        ConfiguredStageOrNull(stage_spec.type, stage_spec.options, spec.path);
    if (stage) stages.emplace_back(stage_spec.id, std::move(stage));
  }
  return stages;
}

// The work directory is refused where it is, or lies inside, a folder a stage reads whole (the
// dataset's image folder): raytime would write summary.json among the images and read it back as
// one. Resolved as the operating system resolves paths (links followed).
void RefuseWorkdirInInputFolder(const ConfiguredStageList& stages, const std::string& workdir) {
  std::error_code error;
  const fs::path work = fs::weakly_canonical(fs::absolute(workdir), error);
  if (error) return;
  for (const auto& [stage_id, stage] : stages) {
    for (const std::string& folder : stage->InputFolders()) {
      const fs::path input = fs::weakly_canonical(fs::absolute(folder), error);
      if (error) continue;
      const fs::path inside = work.lexically_relative(input);
      if (inside.empty() || *inside.begin() == "..") continue;
      throw InputError(workdir + ": the work directory is " +
                       (inside == "." ? std::string("") : "inside ") + "the folder " +
                       input.string() + " that stage " + stage_id +
                       " reads whole (the dataset's images): raytime would write its files among "
                       "them and read them back as images; give a --workdir outside it");
    }
  }
}

// A stage would write over a file the pipeline reads (a nerfstudio dataset's transforms.json,
// which export nerfstudio_in_place writes in the work directory, when the work directory is the
// dataset's folder): refused before anything runs, since a failed run's stale outputs are moved
// aside and the user's file would go with them.
void RefuseOutputsOverInputs(const ConfiguredStageList& stages, const std::string& workdir) {
  std::vector<std::pair<std::string, std::string>> outputs;  // path, stage id
  std::vector<std::string> inputs;
  for (const auto& [stage_id, stage] : stages) {
    for (const std::string& output : stage->ExtraOutputs()) {
      outputs.emplace_back((fs::path(workdir) / output).string(), stage_id);
    }
    try {
      const std::vector<std::string> files = stage->ExternalFiles();
      inputs.insert(inputs.end(), files.begin(), files.end());
    } catch (const std::exception&) {
      // An input that does not load is said by its stage when it runs.
    }
  }
  std::error_code error;
  for (const auto& [output, stage_id] : outputs) {
    for (const std::string& input : inputs) {
      if (!fs::equivalent(output, input, error)) continue;
      throw InputError(input + ": stage " + stage_id + " would write over this file, which the " +
                       "pipeline reads (the work directory " + workdir +
                       " is the dataset's folder); give another --workdir");
    }
  }
}

}  // namespace

nlohmann::json RunPipeline(const PipelineSpec& spec, const RunOptions& options) {
  const std::string workdir = !options.workdir.empty() ? options.workdir : spec.workdir;
  if (workdir.empty()) {
    throw InputError(spec.path + ": no work directory (set 'workdir' or pass --workdir)");
  }
  std::error_code error;
  if (!options.cache_dir.empty() && fs::exists(options.cache_dir, error) &&
      !fs::is_directory(options.cache_dir, error)) {
    throw InputError(options.cache_dir + ": the cache folder (--cache_dir) is a file");
  }
  if (!spec.sweep.empty()) {
    const WorkdirLock lock(workdir);
    return RunSweep(spec, workdir, options);
  }
  ValidatePipeline(spec);
  const ConfiguredStageList stages = ConfiguredStages(spec);
  RefuseWorkdirInInputFolder(stages, workdir);
  RefuseOutputsOverInputs(stages, workdir);
  const WorkdirLock lock(workdir);
  return RunStages(spec, workdir, options);
}

}  // namespace raytime
