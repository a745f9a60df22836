#include "pipelines/run_report.h"

#include <Eigen/Eigenvalues>
#include <algorithm>
#include <cmath>
#include <filesystem>
#include <map>
#include <nlohmann/json.hpp>
#include <set>
#include <vector>

#include "core/atomic_file.h"
#include "core/error.h"
#include "core/geometry.h"
#include "core/hdf5_store.h"
#include "core/types.h"
#include "pipelines/pair_selection.h"

namespace fs = std::filesystem;

namespace raytime {
namespace {

using nlohmann::json;

std::string Escape(const std::string& text) {
  std::string out;
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

std::string Number(const json& value, int digits = 3) {
  if (!value.is_number()) return "–";
  char buffer[64];
  std::snprintf(buffer, sizeof(buffer), "%.*g", digits, value.get<double>());
  return buffer;
}

std::string Number(double value, int digits = 3) {
  return std::isfinite(value) ? Number(json(value), digits) : "–";
}

std::string Text(const json& object, const char* key) {
  const auto it = object.find(key);
  return it != object.end() && it->is_string() ? it->get<std::string>() : std::string();
}

// The refine stage the page is about: the last one that ran, with its prior and refined pose sets.
struct RefinedRun {
  std::string stage_id;
  json summary;  // the stage's summary
  std::string prior_set, refined_set;
  PoseSet prior, refined;
};

// The pose set `name` from the HDF5 file of the stage that wrote it (summary.json's pose_sets).
PoseSet ReadPoseSetOfRun(const std::string& workdir, const json& run, const std::string& name) {
  const auto& sets = run.value("pose_sets", json::object());
  const auto it = sets.find(name);
  if (it == sets.end()) return PoseSet();
  const fs::path file = fs::path(workdir) / (it->get<std::string>() + ".h5");
  if (!fs::exists(file)) return PoseSet();
  return Hdf5Reader(file.string()).ReadPoseSet(name);
}

RefinedRun FindRefinedRun(const std::string& workdir, const json& run) {
  RefinedRun out;
  for (const json& stage : run.value("stages", json::array())) {
    if (Text(stage, "type") != "refine" || !stage.contains("summary")) continue;
    out.stage_id = Text(stage, "id");
    out.summary = stage["summary"];
    out.refined_set = Text(out.summary, "pose_set");
    out.prior_set = stage.value("options", json::object()).value("prior", std::string("prior"));
  }
  if (out.stage_id.empty()) return out;
  out.prior = ReadPoseSetOfRun(workdir, run, out.prior_set);
  out.refined = ReadPoseSetOfRun(workdir, run, out.refined_set);
  return out;
}

// Per image, the warning codes that name it.
std::map<std::string, std::set<std::string>> FlagsByImage(const json& run) {
  std::map<std::string, std::set<std::string>> flags;
  for (const json& warning : run.value("warnings", json::array())) {
    for (const json& image : warning.value("images", json::array())) {
      if (image.is_string()) flags[image.get<std::string>()].insert(Text(warning, "code"));
    }
  }
  return flags;
}

std::string VerdictSection(const json& run, const RefinedRun& refined) {
  const std::string status = Text(run, "status");
  std::string html = "<section id=\"verdict\"><h2>Verdict</h2><p class=\"status " + Escape(status) +
                     "\">Status: <b>" + Escape(status) + "</b>";
  if (run.contains("seconds")) html += " in " + Number(run["seconds"]) + " s";
  html += "</p>";
  if (!Text(run, "error").empty())
    html += "<p class=\"error\">" + Escape(Text(run, "error")) + "</p>";
  if (!refined.stage_id.empty()) {
    const json& s = refined.summary;
    html +=
        "<p>" + Escape(refined.stage_id) + ": decision <b>" + Escape(Text(s, "decision")) + "</b>";
    const json fired = s.value("guardrails", json::object()).value("fired", json::array());
    html += fired.empty() ? ", no guardrail fired" : ", guardrails fired: " + Escape(fired.dump());
    const json u = s.value("uncertainty", json::object());
    if (u.value("computed", false)) {
      html += "; keypoint noise " + Number(u["sigma_px"]) + " px, median σ " +
              Number(u["median_rotation_deg"]) + "° rotation, " + Number(u["median_centre"]) +
              " centre";
    }
    html += "</p>";
  }
  const json warnings = run.value("warnings", json::array());
  html += "<h3>Warnings (" + std::to_string(warnings.size()) + ")</h3>";
  if (warnings.empty()) html += "<p>None.</p>";
  html += "<ul>";
  for (const json& warning : warnings) {
    html += "<li><code>" + Escape(Text(warning, "code")) + "</code> " +
            Escape(Text(warning, "message"));
    const json images = warning.value("images", json::array());
    if (!images.empty()) {
      html += "<br>Images:";
      for (const json& image : images) {
        if (image.is_string()) {
          html += " <a href=\"#cam-" + Escape(image.get<std::string>()) + "\">" +
                  Escape(image.get<std::string>()) + "</a>";
        }
      }
    }
    html += "</li>";
  }
  html += "</ul></section>";
  return html;
}

std::string StagesSection(const json& run) {
  std::string html =
      "<section id=\"stages\"><h2>Stages</h2><table><tr><th>stage</th><th>type</th>"
      "<th>status</th><th>seconds</th></tr>";
  for (const json& stage : run.value("stages", json::array())) {
    html += "<tr><td>" + Escape(Text(stage, "id")) + "</td><td>" + Escape(Text(stage, "type")) +
            "</td><td>" + Escape(Text(stage, "status")) + "</td><td>" +
            Number(stage.value("seconds", json()), 3) + "</td></tr>";
  }
  return html + "</table></section>";
}

// A colour from green (no correction) to red (the largest), by the share of the largest.
std::string CorrectionColour(double share) {
  const int red = static_cast<int>(std::lround(40 + 200 * std::clamp(share, 0.0, 1.0)));
  const int green = static_cast<int>(std::lround(170 - 130 * std::clamp(share, 0.0, 1.0)));
  return "rgb(" + std::to_string(red) + "," + std::to_string(green) + ",60)";
}

// The frame the views share: the refined centres' mean and principal directions (columns,
// ascending spread), and each camera's centre correction with the largest of them.
struct CentreFrame {
  Eigen::Vector3d mean = Eigen::Vector3d::Zero();
  Eigen::Matrix3d axes = Eigen::Matrix3d::Identity();
  std::map<std::string, double> correction;  // refined cameras with a prior pose
  double largest = 0.0;
};

CentreFrame CentreFrameOf(const RefinedRun& refined) {
  CentreFrame frame;
  const auto& solved = refined.refined.world_from_cam;
  for (const auto& [name, pose] : solved) frame.mean += pose.translation;
  frame.mean /= static_cast<double>(std::max<size_t>(solved.size(), 1));
  Eigen::Matrix3d scatter = Eigen::Matrix3d::Zero();
  for (const auto& [name, pose] : solved) {
    const Eigen::Vector3d d = pose.translation - frame.mean;
    scatter += d * d.transpose();
    const auto prior = refined.prior.world_from_cam.find(name);
    if (prior == refined.prior.world_from_cam.end()) continue;
    const double correction = (prior->second.translation - pose.translation).norm();
    frame.correction[name] = correction;
    frame.largest = std::max(frame.largest, correction);
  }
  frame.axes = Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d>(scatter).eigenvectors();
  return frame;
}

// One view of the centres: across, the main direction; up, the principal direction
// `vertical_axis` (1: the second, a top view; 0: the least, a side view), at one scale, the height
// following the spread. Prior grey, refined coloured by its centre correction with the correction
// drawn; each refined camera links to its table row.
std::string CamerasSvg(const RefinedRun& refined, const CentreFrame& frame, const std::string& view,
                       int vertical_axis) {
  const auto& solved = refined.refined.world_from_cam;
  const Eigen::Vector3d u = frame.axes.col(2);
  const Eigen::Vector3d v = frame.axes.col(vertical_axis);
  const auto project = [&](const Eigen::Vector3d& x) {
    return Eigen::Vector2d((x - frame.mean).dot(u), (x - frame.mean).dot(v));
  };
  std::vector<Eigen::Vector2d> points;
  for (const auto& [name, pose] : solved) {
    points.push_back(project(pose.translation));
    const auto prior = refined.prior.world_from_cam.find(name);
    if (prior != refined.prior.world_from_cam.end()) {
      points.push_back(project(prior->second.translation));
    }
  }
  Eigen::Vector2d lo = points.front(), hi = points.front();
  for (const auto& p : points) {
    lo = lo.cwiseMin(p);
    hi = hi.cwiseMax(p);
  }
  const double width = 640.0, margin = 20.0;
  const double extent = std::max(hi.x() - lo.x(), 1e-12);
  const double scale = (width - 2 * margin) / extent;
  const double height = std::max(160.0, (hi.y() - lo.y()) * scale + 2 * margin);
  const auto to_svg = [&](const Eigen::Vector2d& p) {
    return Eigen::Vector2d(margin + (p.x() - lo.x()) * scale,
                           height - margin - (p.y() - lo.y()) * scale);
  };
  std::string svg = "<svg id=\"cameras-" + view +
                    "\" xmlns=\"http://www.w3.org/2000/svg\" width=\"" + Number(width, 4) +
                    "\" height=\"" + Number(height, 4) + "\" role=\"img\"><title>Camera centres, " +
                    view + " view: prior grey, refined coloured by correction</title>";
  for (const auto& [name, pose] : solved) {
    const Eigen::Vector2d r = to_svg(project(pose.translation));
    const auto prior = refined.prior.world_from_cam.find(name);
    double share = 0.0;
    if (prior != refined.prior.world_from_cam.end()) {
      const Eigen::Vector2d p = to_svg(project(prior->second.translation));
      share = frame.largest > 0 ? frame.correction.at(name) / frame.largest : 0.0;
      svg += "<line x1=\"" + Number(p.x(), 6) + "\" y1=\"" + Number(p.y(), 6) + "\" x2=\"" +
             Number(r.x(), 6) + "\" y2=\"" + Number(r.y(), 6) + "\" stroke=\"" +
             CorrectionColour(share) + "\"/><circle cx=\"" + Number(p.x(), 6) + "\" cy=\"" +
             Number(p.y(), 6) + "\" r=\"3\" fill=\"#999\"/>";
    }
    svg += "<a href=\"#cam-" + Escape(name) + "\"><circle class=\"camera\" cx=\"" +
           Number(r.x(), 6) + "\" cy=\"" + Number(r.y(), 6) + "\" r=\"5\" fill=\"" +
           CorrectionColour(share) + "\"><title>" + Escape(name) + "</title></circle></a>";
  }
  return svg + "</svg>";
}

std::string CamerasViews(const RefinedRun& refined) {
  if (refined.refined.world_from_cam.size() < 2) {
    return "<p>Fewer than two refined cameras: no view.</p>";
  }
  const CentreFrame frame = CentreFrameOf(refined);
  return CamerasSvg(refined, frame, "top", 1) + " " + CamerasSvg(refined, frame, "side", 0);
}

std::string CamerasSection(const RefinedRun& refined, const json& run) {
  if (refined.stage_id.empty())
    return "<section id=\"cameras\"><h2>Cameras</h2><p>No refine stage ran.</p></section>";
  std::string html = "<section id=\"cameras\"><h2>Cameras: " + Escape(refined.prior_set) + " → " +
                     Escape(refined.refined_set) +
                     "</h2><p>Top view (the centres' two main directions) and side view (the "
                     "main and the least direction): prior grey, refined coloured green to red by "
                     "the size of its correction, the correction drawn; a camera links to its "
                     "row.</p>" +
                     CamerasViews(refined);
  const json sigma =
      refined.summary.value("uncertainty", json::object()).value("cameras", json::object());
  const auto flags = FlagsByImage(run);
  html +=
      "<table id=\"camera-table\"><tr><th>image</th><th>rotation correction (°)</th>"
      "<th>centre correction</th><th>σ rotation (°)</th><th>σ centre</th><th>flags</th></tr>";
  std::set<std::string> unique;
  for (const auto& [name, pose] : refined.prior.world_from_cam) unique.insert(name);
  for (const auto& [name, pose] : refined.refined.world_from_cam) unique.insert(name);
  // Capture order: a video's "2.jpg" before "10.jpg".
  std::vector<std::string> names(unique.begin(), unique.end());
  std::sort(names.begin(), names.end(), NaturalNameLess);
  for (const auto& name : names) {
    const auto prior = refined.prior.world_from_cam.find(name);
    const auto solved = refined.refined.world_from_cam.find(name);
    std::string rotation = "–", centre = "–";
    if (prior != refined.prior.world_from_cam.end() &&
        solved != refined.refined.world_from_cam.end()) {
      rotation = Number(
          DegreesFromRadians(RotationDistance(prior->second.rotation, solved->second.rotation)));
      centre = Number((prior->second.translation - solved->second.translation).norm());
    }
    const json s = sigma.is_object() && sigma.contains(name) ? sigma[name] : json::object();
    std::string flag_text;
    const auto it = flags.find(name);
    if (it != flags.end()) {
      for (const auto& code : it->second) flag_text += (flag_text.empty() ? "" : ", ") + code;
    }
    if (solved == refined.refined.world_from_cam.end()) {
      flag_text += std::string(flag_text.empty() ? "" : ", ") + "not refined";
    }
    html += "<tr id=\"cam-" + Escape(name) + "\"><td>" + Escape(name) + "</td><td>" + rotation +
            "</td><td>" + centre + "</td><td>" + Number(s.value("rotation_deg", json())) +
            "</td><td>" + Number(s.value("centre", json())) + "</td><td>" + Escape(flag_text) +
            "</td></tr>";
  }
  return html + "</table></section>";
}

std::string MetricsSection(const json& run) {
  const json metrics = run.value("metrics", json::object());
  std::string rows;
  for (const auto& [pose_set, by_alignment] : metrics.items()) {
    if (!by_alignment.is_object()) continue;
    for (const auto& [alignment, errors] : by_alignment.items()) {
      if (!errors.is_object() || !errors.contains("mean_rotation_deg")) continue;
      rows += "<tr><td>" + Escape(pose_set) + "</td><td>" + Escape(alignment) + "</td><td>" +
              Number(errors["mean_rotation_deg"]) + "</td><td>" +
              Number(errors.value("mean_centre_m", json())) + "</td><td>" +
              Number(errors.value("num_frames", json()), 6) + "</td></tr>";
    }
  }
  if (rows.empty()) return "";
  return "<section id=\"metrics\"><h2>Against the ground truth</h2><table><tr><th>pose set</th>"
         "<th>alignment</th><th>mean rotation error (°)</th><th>mean centre error</th>"
         "<th>frames</th></tr>" +
         rows + "</table></section>";
}

}  // namespace

std::string WriteRunReport(const std::string& workdir) {
  const std::string summary_path = (fs::path(workdir) / "summary.json").string();
  if (!fs::exists(summary_path)) {
    ThrowInput(summary_path, 0,
               "no such file: not a raytime work directory (raytime run writes it)");
  }
  const json run = json::parse(ReadTextFile(summary_path), nullptr, false);
  if (run.is_discarded() || !run.is_object()) ThrowInput(summary_path, 0, "not a run summary");
  const RefinedRun refined = FindRefinedRun(workdir, run);
  const std::string title = "raytime run " + Text(run, "name") + " (" + Text(run, "status") + ")";
  std::string html =
      "<!DOCTYPE html><html lang=\"en\"><head><meta charset=\"utf-8\"><title>" + Escape(title) +
      "</title><style>body{font-family:sans-serif;margin:2em;max-width:72em}"
      "table{border-collapse:collapse}td,th{border:1px solid #ccc;padding:2px 6px;"
      "text-align:right}td:first-child{text-align:left}.status.ok{color:#070}"
      ".status.ok_with_warnings{color:#a60}.status.failed,.status.interrupted,.error{color:#b00}"
      "tr:target{background:#ffd}svg{border:1px solid #ddd}</style></head><body><h1>" +
      Escape(title) + "</h1><p>Work directory <code>" + Escape(workdir) +
      "</code>, pipeline <code>" + Escape(Text(run, "pipeline")) + "</code>, raytime " +
      Escape(Text(run, "raytime_version")) + "</p>" + VerdictSection(run, refined) +
      CamerasSection(refined, run) + MetricsSection(run) + StagesSection(run) + "</body></html>\n";
  const std::string path = (fs::path(workdir) / "report.html").string();
  WriteTextFileAtomically(path, html);
  return path;
}

}  // namespace raytime
