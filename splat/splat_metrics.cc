#include "splat/splat_metrics.h"

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <regex>

#include "core/atomic_file.h"
#include "core/error.h"

namespace fs = std::filesystem;
using nlohmann::json;

namespace raytime {
namespace {

// A step or iteration from the digits of a file or key name; -1 when it does not fit (a name
// with 30 digits is not a step any trainer wrote).
int64_t StepNumber(const std::string& digits) {
  if (digits.empty() || digits.size() > 15) return -1;
  return std::stoll(digits);
}

json ParseJsonFile(const std::string& path) {
  if (!fs::is_regular_file(path)) ThrowInput(path, 0, "metrics file not found");
  const std::string text = ReadTextFile(path);
  json document = json::parse(text, nullptr, false);
  if (document.is_discarded()) {
    // Python's json module writes NaN and Infinity, which are not JSON: a diverged training.
    const bool non_finite =
        text.find("NaN") != std::string::npos || text.find("Infinity") != std::string::npos;
    ThrowInput(path, 0,
               non_finite ? "metrics are NaN or Infinity (the training diverged?); not valid JSON"
                          : "not valid JSON");
  }
  if (!document.is_object()) ThrowInput(path, 0, "expected a JSON object");
  return document;
}

// object[key] as a number within [low, high]; NaN when absent and optional.
double Number(const json& object, const std::string& key, double low, double high, bool required,
              const std::string& path, const std::string& where) {
  const auto it = object.find(key);
  if (it == object.end() || it->is_null()) {
    if (required) ThrowInput(path, 0, where + "has no '" + key + "'");
    return TrainerMetrics::kNone;
  }
  if (!it->is_number()) ThrowInput(path, 0, where + "'" + key + "' is not a number");
  const double value = it->get<double>();
  if (!(value >= low && value <= high)) {
    ThrowInput(path, 0,
               where + "'" + key + "' = " + it->dump() + " is outside [" + json(low).dump() + ", " +
                   json(high).dump() + "]");
  }
  return value;
}

// PSNR of [0, 1] images is not negative, and finite unless a render is its ground truth; SSIM is
// in [-1, 1];
// LPIPS (a distance) is not negative.
constexpr double kMaxPsnr = 1000.0;

void ReadPsnrSsimLpips(const json& object, const std::string& psnr_key, const std::string& ssim_key,
                       const std::string& lpips_key, const std::string& path,
                       const std::string& where, TrainerMetrics* metrics) {
  metrics->psnr = Number(object, psnr_key, 0.0, kMaxPsnr, true, path, where);
  metrics->ssim = Number(object, ssim_key, -1.0, 1.0, true, path, where);
  metrics->lpips = Number(object, lpips_key, 0.0, 1e6, false, path, where);
}

bool IsImage(const fs::path& path) { return path.extension() == ".png"; }

}  // namespace

TrainerMetrics ReadGsplatStats(const std::string& result_dir) {
  const fs::path stats = fs::path(result_dir) / "stats";
  if (!fs::is_directory(stats)) {
    ThrowInput(stats.string(), 0, "no stats folder (gsplat writes val_step<N>.json there)");
  }
  static const std::regex kName(R"(val_step([0-9]+)\.json)");
  std::string best;
  int64_t best_step = -1;
  for (const auto& entry : fs::directory_iterator(stats)) {
    const std::string name = entry.path().filename().string();
    std::smatch match;
    if (!entry.is_regular_file() || !std::regex_match(name, match, kName)) continue;
    const int64_t step = StepNumber(match[1].str());
    if (step > best_step) {
      best_step = step;
      best = entry.path().string();
    }
  }
  if (best.empty()) {
    ThrowInput(stats.string(), 0,
               "no val_step<N>.json (the training ended before its first eval step?)");
  }
  const json document = ParseJsonFile(best);
  TrainerMetrics metrics;
  metrics.file = best;
  metrics.step = best_step;
  ReadPsnrSsimLpips(document, "psnr", "ssim", "lpips", best, "", &metrics);
  const auto gaussians = document.find("num_GS");
  if (gaussians != document.end() && gaussians->is_number_integer() &&
      gaussians->get<int64_t>() >= 0) {
    metrics.num_gaussians = gaussians->get<int64_t>();
  }
  return metrics;
}

TrainerMetrics ReadInriaResults(const std::string& model_dir) {
  const std::string path = (fs::path(model_dir) / "results.json").string();
  const json document = ParseJsonFile(path);
  static const std::regex kKey(R"(ours_([0-9]+))");
  std::string best;
  int64_t best_step = -1;
  for (const auto& [key, value] : document.items()) {
    std::smatch match;
    if (!std::regex_match(key, match, kKey)) continue;
    const int64_t step = StepNumber(match[1].str());
    if (step > best_step) {
      best_step = step;
      best = key;
    }
  }
  if (best.empty()) ThrowInput(path, 0, "no entry 'ours_<iteration>' (metrics.py writes one)");
  const json& entry = document[best];
  if (!entry.is_object()) ThrowInput(path, 0, "'" + best + "' is not an object");
  TrainerMetrics metrics;
  metrics.file = path;
  metrics.step = best_step;
  ReadPsnrSsimLpips(entry, "PSNR", "SSIM", "LPIPS", path, "'" + best + "' ", &metrics);
  return metrics;
}

TrainerMetrics ReadNerfstudioEval(const std::string& path) {
  const json document = ParseJsonFile(path);
  const auto results = document.find("results");
  if (results == document.end() || !results->is_object()) {
    ThrowInput(path, 0, "no 'results' object (ns-eval writes one)");
  }
  TrainerMetrics metrics;
  metrics.file = path;
  ReadPsnrSsimLpips(*results, "psnr", "ssim", "lpips", path, "'results' ", &metrics);
  const auto checkpoint = document.find("checkpoint");
  if (checkpoint != document.end() && checkpoint->is_string()) {
    static const std::regex kCheckpoint(R"(step-([0-9]+)\.ckpt$)");
    const std::string name = checkpoint->get<std::string>();
    std::smatch match;
    if (std::regex_search(name, match, kCheckpoint)) metrics.step = StepNumber(match[1].str());
  }
  return metrics;
}

TrainerMetrics ReadTrainerMetrics(const std::string& trainer, const std::string& result_dir) {
  if (trainer == "gsplat") return ReadGsplatStats(result_dir);
  if (trainer == "inria") return ReadInriaResults(result_dir);
  if (trainer == "nerfstudio") {
    return ReadNerfstudioEval((fs::path(result_dir) / "eval.json").string());
  }
  throw InputError("unknown trainer '" + trainer + "' (gsplat, inria, nerfstudio)");
}

std::vector<HeldOutView> TrainerHeldOutViews(const std::string& trainer,
                                             const std::string& result_dir,
                                             const TrainerMetrics& metrics,
                                             std::string* absent_reason) {
  std::vector<HeldOutView> views;
  if (trainer == "inria") {
    const fs::path method =
        fs::path(result_dir) / "test" / ("ours_" + std::to_string(metrics.step));
    if (!fs::is_directory(method / "renders") || !fs::is_directory(method / "gt")) {
      *absent_reason = "no " + method.string() + "/{renders,gt} (render.py saves them)";
      return views;
    }
    return ViewsOfFolderPair((method / "renders").string(), (method / "gt").string());
  }
  // gsplat and nerfstudio: side-by-side files, in index order.
  fs::path folder;
  std::regex name;
  if (trainer == "gsplat") {
    folder = fs::path(result_dir) / "renders";
    name = std::regex("val_step" + std::to_string(metrics.step) + R"(_[0-9]+\.png)");
  } else {
    folder = fs::path(result_dir) / "eval_renders";
    name = std::regex(R"(eval_img_[0-9]+\.png)");
  }
  std::vector<std::string> files;
  if (fs::is_directory(folder)) {
    for (const auto& entry : fs::directory_iterator(folder)) {
      const std::string file = entry.path().filename().string();
      if (entry.is_regular_file() && IsImage(entry.path()) && std::regex_match(file, name)) {
        files.push_back(entry.path().string());
      }
    }
  }
  std::sort(files.begin(), files.end());
  for (const auto& file : files) views.push_back({file, ""});
  if (views.empty()) {
    *absent_reason = trainer == "gsplat"
                         ? "no " + folder.string() + "/val_step" + std::to_string(metrics.step) +
                               "_*.png (gsplat saves them at each eval step)"
                         : "no " + folder.string() +
                               "/eval_img_*.png (ns-eval saves them with --render-output-path " +
                               folder.string() + ")";
  }
  return views;
}

}  // namespace raytime
