#include "splat/splat_trainer.h"

#include <signal.h>

#include <unistd.h>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <map>
#include <mutex>
#include <sstream>

#include "core/error.h"
#include "core/interrupt.h"
#include "core/process.h"
#include "core/progress.h"
#include "core/timing.h"
#include "splat/held_out_render.h"

namespace fs = std::filesystem;

namespace raytime {
namespace {

const std::vector<std::string> kPlaceholders = {"data_dir", "result_dir", "pose_set", "train_dir",
                                                "steps",    "downscale",  "seed",     "binary"};

// Where a run's train-only view of the export goes (RESULT/train_view, held_out_render.h).
std::string TrainViewDir(const std::string& result_dir) {
  return (fs::path(result_dir) / "train_view").string();
}

// The splats OpenSplat's default command writes (-o).
std::string OpenSplatPly(const std::string& result_dir) {
  return (fs::path(result_dir) / "splat.ply").string();
}

std::string NumberText(double value) {
  std::ostringstream text;
  text << value;
  return text.str();
}

// `name` looked up on PATH as a shell would (a name with a '/' is taken as it is); "" when absent.
std::string FindExecutable(const std::string& name) {
  if (name.find('/') != std::string::npos) return fs::exists(name) ? name : std::string();
  const char* path = std::getenv("PATH");
  std::istringstream dirs(path == nullptr ? "" : path);
  std::string dir;
  while (std::getline(dirs, dir, ':')) {
    const fs::path candidate = fs::path(dir.empty() ? "." : dir) / name;
    if (::access(candidate.c_str(), X_OK) == 0) return candidate.string();
  }
  return std::string();
}

// OpenSplat's build as scripts/install_opensplat.sh records it: BIN/../share/opensplat/commit
// beside BIN/opensplat; "" when the binary was installed otherwise.
std::string OpenSplatCommit(const std::string& binary) {
  const std::string found = FindExecutable(binary.empty() ? "opensplat" : binary);
  if (found.empty()) return std::string();
  std::ifstream in(fs::path(found).parent_path().parent_path() / "share" / "opensplat" / "commit");
  std::string commit;
  std::getline(in, commit);
  return commit;
}

// Seconds a stopped trainer gets to end on SIGTERM before its group is killed.
constexpr double kStopGrace_s = 10.0;
// What a failed run's summary quotes from the log.
constexpr size_t kTailLines = 20;
constexpr size_t kTailChars = 4000;

// `value` as one shell word: unchanged when it holds only characters no shell treats specially,
// else in single quotes (a quote inside closes, escapes and reopens them).
std::string ShellWord(const std::string& value) {
  static const std::string kPlain =
      "abcdefghijklmnopqrstuvwxyzABCDEFGHIJKLMNOPQRSTUVWXYZ0123456789@%+=:,./_-";
  if (!value.empty() && value.find_first_not_of(kPlain) == std::string::npos) return value;
  std::string quoted = "'";
  for (const char c : value) quoted += c == '\'' ? std::string("'\\''") : std::string(1, c);
  return quoted + "'";
}

// Placeholder-like names: a typo such as {data-dir} or {datadir} is an error rather than text the
// shell receives; brace expansions ({a,b}, {1..3}) and awk programs do not look like this.
bool IsNameChar(char c) {
  return std::isalnum(static_cast<unsigned char>(c)) || c == '_' || c == '-';
}

// The "{name}"s of `text` that are not a shell's "${name}", in order.
std::vector<std::string> BracedNames(const std::string& text) {
  std::vector<std::string> names;
  for (size_t open = text.find('{'); open != std::string::npos; open = text.find('{', open + 1)) {
    const size_t close = text.find('}', open + 1);
    if (close == std::string::npos) break;
    const std::string name = text.substr(open + 1, close - open - 1);
    if (name.empty() || !std::all_of(name.begin(), name.end(), IsNameChar)) continue;
    if (open > 0 && text[open - 1] == '$') continue;
    names.push_back(name);
  }
  return names;
}

// The non-empty lines of the last `max_bytes` of the log. Progress bars redraw one line with
// carriage returns: each redraw counts as a line.
std::vector<std::string> LogLines(const std::string& path, std::streamoff max_bytes) {
  std::ifstream in(path, std::ios::binary);
  if (!in) return {};
  in.seekg(0, std::ios::end);
  const std::streamoff size = in.tellg();
  in.seekg(std::max<std::streamoff>(0, size - max_bytes));
  const std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  std::vector<std::string> lines;
  std::string line;
  for (const char c : text) {
    if (c != '\n' && c != '\r') {
      line += c;
      continue;
    }
    if (!line.empty()) lines.push_back(line);
    line.clear();
  }
  if (!line.empty()) lines.push_back(line);
  return lines;
}

// The last kTailLines lines of the log (at most kTailChars), for a failure's summary.
std::string LogTail(const std::string& path) {
  const std::vector<std::string> lines = LogLines(path, 64 * 1024);
  std::string tail;
  for (size_t i = lines.size() > kTailLines ? lines.size() - kTailLines : 0; i < lines.size();
       ++i) {
    tail += lines[i] + "\n";
  }
  if (tail.size() > kTailChars) tail = tail.substr(tail.size() - kTailChars);
  return tail;
}

std::string Absolute(const std::string& path) {
  return fs::absolute(fs::path(path)).lexically_normal().string();
}

// The last line of the trainer's log so far that is not blank, trailing spaces trimmed (the
// progress line's detail); "" when there is none.
std::string LastLogLine(const std::string& path) {
  std::vector<std::string> lines = LogLines(path, 4096);
  for (auto line = lines.rbegin(); line != lines.rend(); ++line) {
    line->erase(line->find_last_not_of(' ') + 1);
    if (!line->empty()) return *line;
  }
  return std::string();
}

// Runs the command to its end or its timeout; fills the process fields of `summary`.
void RunCommand(const SplatTrainerOptions& options, const SplatJob& job, SplatRunSummary* summary) {
  {
    std::ofstream log(job.log_path, std::ios::trunc);
    log << "$ " << summary->command << "\n" << std::flush;
    if (!log) ThrowInput(job.log_path, 0, "cannot write the trainer's log");
  }
  ProcessOptions process;
  process.output_path = job.log_path;
  process.append_output = true;
  process.working_dir = options.working_dir;
  process.new_process_group = true;
  const auto start = std::chrono::steady_clock::now();
  const pid_t pid = StartProcess({"/bin/sh", "-c", summary->command}, process);
  // The trainer has its own group, so a terminal's Ctrl-C does not reach it: stop it with us.
  std::mutex mutex;
  bool running = true;
  const InterruptAction stop_on_interrupt([&](int) {
    std::lock_guard<std::mutex> lock(mutex);
    if (running) SignalProcessGroup(pid, SIGTERM);
  });

  ProcessStatus status;
  bool ended = false;
  // On a terminal, a line with the time trained and the log's last line (the trainer's own step
  // and loss, whatever its format), checked once a second; elsewhere one wait.
  ProgressBar bar("splat: training, s", 0);
  if (bar.drawing()) {
    while (!ended) {
      const double left = options.timeout_s > 0.0 ? options.timeout_s - SecondsSince(start) : 1.0;
      if (left <= 0.0) break;
      ended = WaitProcessFor(pid, std::min(1.0, left), &status);
      bar.Update(static_cast<int>(SecondsSince(start)), LastLogLine(job.log_path));
    }
  } else if (options.timeout_s > 0.0) {
    ended = WaitProcessFor(pid, options.timeout_s, &status);
  } else {
    status = WaitProcess(pid);
    ended = true;
  }
  if (!ended) {
    summary->timed_out = true;
    SignalProcessGroup(pid, SIGTERM);
    if (!WaitProcessFor(pid, kStopGrace_s, &status)) {
      SignalProcessGroup(pid, SIGKILL);
      status = WaitProcess(pid);
    }
  }
  {
    std::lock_guard<std::mutex> lock(mutex);
    running = false;
  }
  summary->seconds = SecondsSince(start);
  if (Interrupting()) AwaitInterruptExit();
  // Whatever the command left running in the background (a viewer, a server) ends with it: a
  // hook that returns must not leave a GPU busy.
  if (SignalProcessGroup(pid, SIGTERM)) {
    std::ofstream(job.log_path, std::ios::app)
        << "\n[raytime] stopped the processes the command left running (SIGTERM to its group)\n";
  }
  summary->exit_code = status.exit_code;
  summary->signal = status.signal;
  if (summary->timed_out) {
    summary->status = "failed";
    summary->error = "timed out after " + std::to_string(std::lround(options.timeout_s)) +
                     " s (timeout_s) and was stopped";
  } else if (!status.Succeeded()) {
    summary->status = "failed";
    summary->error = "the command " + status.Describe();
  }
}

// OpenSplat leaves RESULT/splat.ply and no metrics: raytime's own render of every held-out view is
// the score (RESULT/renders, RESULT/gt), at the trained resolution.
void ScoreOpenSplat(const SplatTrainerOptions& options, SplatRunSummary* summary) {
  const std::string ply = OpenSplatPly(summary->result_dir);
  if (!fs::exists(ply)) {
    summary->status = "failed";
    summary->error = "the command succeeded but wrote no " + ply;
    return;
  }
  summary->metrics_file = ply;
  summary->step = options.steps;
  try {
    HeldOutRenderOptions render;
    render.downscale = options.downscale;
    render.render = SplatRenderOptionsOf("opensplat");
    const GaussianSplats splats = ReadGaussianSplatPly(ply);
    const size_t broken = CountNonFiniteGaussians(splats);
    if (broken > 0) {
      summary->status = "failed";
      summary->error = std::to_string(broken) + " of " + std::to_string(splats.size()) +
                       " Gaussians in " + ply +
                       " are not finite: the training diverged or the trainer is broken; not "
                       "scored";
      return;
    }
    const HeldOutScore score =
        RenderAndScoreHeldOutViews(splats, summary->data_dir, summary->result_dir, render);
    summary->raytime_images = score.num_images;
    summary->raytime_psnr = score.psnr;
    summary->raytime_ssim = score.ssim;
  } catch (const InputError& e) {
    summary->status = "failed";
    summary->error = std::string("its splats could not be rendered and scored: ") + e.what();
  }
}

}  // namespace

void SplatTrainerOptions::CheckRelations(const Requirement& require) const {
  for (const std::string& name : BracedNames(command)) {
    require(std::find(kPlaceholders.begin(), kPlaceholders.end(), name) != kPlaceholders.end(),
            "option 'command': unknown placeholder {" + name +
                "} (the placeholders are {data_dir}, {result_dir} and {pose_set}; a shell "
                "variable is written ${" +
                name + "})");
  }
}

std::string DefaultSplatCommand(const std::string& trainer) {
  if (trainer == "gsplat") {
    // examples/simple_trainer.py in a gsplat checkout; --data_factor 1: the export is already at
    // the resolution to train on (gsplat's default 4 downsamples); without --disable_viewer the
    // script keeps its viewer alive after training and never exits.
    return "python examples/simple_trainer.py default --data_dir {data_dir} --result_dir "
           "{result_dir} --data_factor 1 --disable_viewer";
  }
  if (trainer == "inria") {
    // The reference code's evaluation recipe (its README): train with the every-8th split, render
    // the held-out views, score them into MODEL/results.json.
    return "python train.py -s {data_dir} -m {result_dir} --eval && python render.py -m "
           "{result_dir} && python metrics.py -m {result_dir}";
  }
  if (trainer == "opensplat") {
    // The train-only view (the held-out frames never reach it) with the export's images;
    // --keep-crs: the .ply in the export's frame, where raytime renders the held-out cameras;
    // --num-downscales 0: trained at the resolution it is scored at from the first step (its
    // default starts at a quarter and doubles every 3,000 steps: a short CPU run never left
    // 1/8 of the photos at downscale 2).
    return "{binary} {train_dir} --colmap-image-path {data_dir}/images -o {result_dir}/splat.ply "
           "--keep-crs -n {steps} -d {downscale} --num-downscales 0";
  }
  if (trainer == "nerfstudio") {
    // A fixed experiment name and timestamp put config.yml where ns-eval can be told; tensorboard
    // instead of the default visualizer so training ends without a viewer or a login.
    return "ns-train splatfacto --data {data_dir} --output-dir {result_dir} --experiment-name "
           "raytime --timestamp run --vis tensorboard && ns-eval --load-config "
           "{result_dir}/raytime/splatfacto/run/config.yml --output-path {result_dir}/eval.json "
           "--render-output-path {result_dir}/eval_renders";
  }
  throw InputError("unknown trainer '" + trainer + "' (gsplat, inria, nerfstudio, opensplat)");
}

std::string ExpandSplatCommand(const SplatTrainerOptions& options, const SplatJob& job) {
  const std::string command =
      options.command.empty() ? DefaultSplatCommand(options.trainer) : options.command;
  const std::map<std::string, std::string> values = {
      {"data_dir", ShellWord(Absolute(job.data_dir))},
      {"result_dir", ShellWord(Absolute(job.result_dir))},
      {"pose_set", ShellWord(job.pose_set)},
      {"train_dir", ShellWord(TrainViewDir(Absolute(job.result_dir)))},
      {"steps", std::to_string(options.steps)},
      {"downscale", NumberText(options.downscale)},
      {"seed", std::to_string(options.seed)},
      {"binary", ShellWord(options.binary.empty() ? std::string("opensplat") : options.binary)}};
  std::string expanded;
  size_t pos = 0;
  while (pos < command.size()) {
    const size_t open = command.find('{', pos);
    if (open == std::string::npos) break;
    const size_t close = command.find('}', open + 1);
    if (close == std::string::npos) break;
    const auto value = values.find(command.substr(open + 1, close - open - 1));
    if (value == values.end() || (open > 0 && command[open - 1] == '$')) {
      expanded += command.substr(pos, open + 1 - pos);
      pos = open + 1;
      continue;
    }
    expanded += command.substr(pos, open - pos) + value->second;
    pos = close + 1;
  }
  return expanded + command.substr(std::min(pos, command.size()));
}

SplatRunSummary RunSplatTrainer(const SplatTrainerOptions& options, const SplatJob& job) {
  if (!options.working_dir.empty() && !fs::is_directory(options.working_dir)) {
    ThrowInput(options.working_dir, 0,
               "the trainer's working directory (option 'working_dir') does not exist");
  }
  SplatRunSummary summary;
  summary.pose_set = job.pose_set;
  summary.trainer = options.trainer;
  summary.status = "ok";
  summary.reused = job.reuse_result;
  summary.command = ExpandSplatCommand(options, job);
  summary.data_dir = Absolute(job.data_dir);
  summary.result_dir = Absolute(job.result_dir);
  summary.log_path = job.log_path;

  if (!job.reuse_result) {
    // A fresh folder: metrics an earlier run left must never pass for this run's.
    fs::remove_all(summary.result_dir);
    fs::create_directories(summary.result_dir);
    if (!job.log_path.empty()) fs::create_directories(fs::path(job.log_path).parent_path());
    const std::string command =
        options.command.empty() ? DefaultSplatCommand(options.trainer) : options.command;
    if (command.find("{train_dir}") != std::string::npos) {
      try {
        WriteTrainOnlyView(summary.data_dir, TrainViewDir(summary.result_dir), options.seed,
                           options.random_init_points);
      } catch (const InputError& e) {
        summary.status = "failed";
        summary.error = std::string("no train-only view of the export: ") + e.what();
        return summary;
      }
    }
    RunCommand(options, job, &summary);
  }
  if (options.trainer == "opensplat") {
    summary.trainer_version = OpenSplatCommit(options.binary);
    if (summary.ok()) ScoreOpenSplat(options, &summary);
    if (!summary.ok()) summary.log_tail = LogTail(job.log_path);
    return summary;
  }

  if (summary.ok()) {
    try {
      const TrainerMetrics metrics = ReadTrainerMetrics(options.trainer, summary.result_dir);
      summary.metrics_file = metrics.file;
      summary.step = metrics.step;
      summary.psnr = metrics.psnr;
      summary.ssim = metrics.ssim;
      summary.lpips = metrics.lpips;
      summary.num_gaussians = metrics.num_gaussians;
    } catch (const InputError& e) {
      summary.status = "failed";
      summary.error = std::string("the command succeeded but its metrics do not read: ") + e.what();
    }
  }
  if (summary.ok()) {
    TrainerMetrics step;
    step.step = summary.step;
    try {
      const std::vector<HeldOutView> views =
          TrainerHeldOutViews(options.trainer, summary.result_dir, step, &summary.raytime_note);
      if (!views.empty()) {
        const HeldOutScore score = ScoreHeldOutViews(views);
        summary.raytime_images = score.num_images;
        summary.raytime_psnr = score.psnr;
        summary.raytime_ssim = score.ssim;
      }
    } catch (const InputError& e) {
      summary.raytime_note = std::string("renders not scored: ") + e.what();
    }
  }
  if (!summary.ok()) summary.log_tail = LogTail(job.log_path);
  return summary;
}

}  // namespace raytime
