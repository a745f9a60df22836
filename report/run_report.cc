#include "report/run_report.h"

#include <spdlog/spdlog.h>
#include <tbb/parallel_for.h>

#include <Eigen/Eigenvalues>
#include <algorithm>
#include <cmath>
#include <filesystem>
#include <map>
#include <nlohmann/json.hpp>
#include <set>
#include <stdexcept>
#include <vector>

#include "core/artifacts.h"
#include "core/atomic_file.h"
#include "core/error.h"
#include "core/geometry.h"
#include "core/hdf5_store.h"
#include "core/timing.h"
#include "core/types.h"
#include "report/html.h"
#include "run_report_orbit_js.h"  // generated from report/run_report_orbit.js

namespace fs = std::filesystem;

namespace raytime {
namespace {

using nlohmann::json;

// Thumbnails: 160 px wide, JPEG quality 65: about 5 kB each (the 457-frame desk: 3 MB of page).
constexpr int kThumbnailWidth = 160;
// A warning naming many images shows this many of them as thumbnails (all of them as links).
constexpr size_t kThumbnailsPerWarning = 12;
// A camera's panel lists its worst pairs, this many (all of them are in the matrix).
constexpr size_t kPairsPerPanel = 12;

// The frame the views share: the refined centres' mean and principal directions (columns,
// ascending spread), and each camera's centre correction with the largest of them.
struct CentreFrame {
  Eigen::Vector3d mean = Eigen::Vector3d::Zero();
  Eigen::Matrix3d axes = Eigen::Matrix3d::Identity();
  std::map<std::string, double> correction;  // refined cameras with a prior pose
  double largest = 0.0;

  double Share(const std::string& name) const {
    const auto it = correction.find(name);
    return it == correction.end() || largest <= 0 ? 0.0 : it->second / largest;
  }
};

// What the page is made of: the run's summary, the refine stage the page is about (the last one
// that ran) with its prior, refined and (aligned onto the refined) reference pose sets, its fit per
// image and pair, and the images.
struct RunPage {
  std::string workdir;
  json run;
  std::string stage_id;
  json summary = json::object();  // the refine stage's
  std::string prior_set, refined_set, truth_set;
  PoseSet prior, refined;
  PoseSet truth;  // Sim(3)-aligned onto the refined centres; empty when there is none
  json diagnostics = json::object();  // kSolveDiagnosticsJson
  ImageSet images;
  std::vector<std::string> names;  // prior ∪ refined, in capture order
  std::map<std::string, std::set<std::string>> flags;
  std::map<std::string, std::string> thumbnails;  // data URIs
  CentreFrame frame;
};

fs::path StageFileOf(const RunPage& page, const std::string& pose_set) {
  const auto& sets = JsonObject(page.run, "pose_sets");
  const auto it = sets.find(pose_set);
  if (it == sets.end() || !it->is_string()) return fs::path();
  const fs::path file = fs::path(page.workdir) / (it->get<std::string>() + ".h5");
  return fs::exists(file) ? file : fs::path();
}

PoseSet ReadPoseSetOfRun(const RunPage& page, const std::string& name) {
  const fs::path file = StageFileOf(page, name);
  return file.empty() ? PoseSet() : Hdf5Reader(file.string()).ReadPoseSet(name);
}

// The reference pose set moved onto the refined centres (Sim(3) on the common names): drawn
// beside them, not measured (the metrics section has the errors).
PoseSet AlignedTruth(const PoseSet& truth, const PoseSet& refined) {
  std::vector<Eigen::Vector3d> source, target;
  for (const auto& [name, pose] : truth.world_from_cam) {
    const auto it = refined.world_from_cam.find(name);
    if (it == refined.world_from_cam.end()) continue;
    source.push_back(pose.translation);
    target.push_back(it->second.translation);
  }
  PoseSet aligned;
  if (source.size() < 3) return aligned;
  try {
    const Sim3 refined_from_truth = FitAlignment(source, target, AlignmentKind::kSim3);
    for (const auto& [name, pose] : truth.world_from_cam) {
      aligned.world_from_cam[name] = refined_from_truth.TransformPose(pose);
    }
  } catch (const std::invalid_argument&) {
    // Collinear centres: no alignment, nothing drawn.
  }
  return aligned;
}

CentreFrame CentreFrameOf(const PoseSet& prior, const PoseSet& refined) {
  CentreFrame frame;
  const auto& solved = refined.world_from_cam;
  for (const auto& [name, pose] : solved) frame.mean += pose.translation;
  frame.mean /= static_cast<double>(std::max<size_t>(solved.size(), 1));
  Eigen::Matrix3d scatter = Eigen::Matrix3d::Zero();
  for (const auto& [name, pose] : solved) {
    const Eigen::Vector3d d = pose.translation - frame.mean;
    scatter += d * d.transpose();
    const auto it = prior.world_from_cam.find(name);
    if (it == prior.world_from_cam.end()) continue;
    const double correction = (it->second.translation - pose.translation).norm();
    frame.correction[name] = correction;
    frame.largest = std::max(frame.largest, correction);
  }
  frame.axes = Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d>(scatter).eigenvectors();
  // A right-handed frame, so the orbit view is not a mirror image.
  if (frame.axes.determinant() < 0) frame.axes.col(0) *= -1.0;
  return frame;
}

std::map<std::string, std::set<std::string>> FlagsByImage(const json& run) {
  std::map<std::string, std::set<std::string>> flags;
  for (const json& warning : JsonArray(run, "warnings")) {
    for (const json& image : JsonArray(warning, "images")) {
      if (image.is_string()) flags[image.get<std::string>()].insert(JsonText(warning, "code"));
    }
  }
  return flags;
}

// The dataset's images (their folder and cameras), from the first stage file that holds them.
ImageSet ImagesOfRun(const RunPage& page) {
  for (const json& stage : JsonArray(page.run, "stages")) {
    const fs::path file = fs::path(page.workdir) / (JsonText(stage, "id") + ".h5");
    if (JsonText(stage, "id").empty() || !fs::exists(file)) continue;
    const Hdf5Reader reader(file.string());
    if (reader.HasImages()) return reader.ReadImages();
  }
  return ImageSet();
}

void ReadRefineStage(RunPage* page) {
  for (const json& stage : JsonArray(page->run, "stages")) {
    if (JsonText(stage, "type") == "refine" && !JsonObject(stage, "summary").empty()) {
      page->stage_id = JsonText(stage, "id");
      page->summary = JsonObject(stage, "summary");
      page->refined_set = JsonText(page->summary, "pose_set");
      page->prior_set = JsonText(JsonObject(stage, "options"), "prior", "prior");
    }
    if (JsonText(stage, "type") == "evaluate") {
      page->truth_set = JsonText(JsonObject(stage, "options"), "reference", "ground_truth");
    }
  }
  if (page->stage_id.empty()) return;
  page->prior = ReadPoseSetOfRun(*page, page->prior_set);
  page->refined = ReadPoseSetOfRun(*page, page->refined_set);
  if (!page->truth_set.empty()) {
    page->truth = AlignedTruth(ReadPoseSetOfRun(*page, page->truth_set), page->refined);
  }
  const fs::path file = StageFileOf(*page, page->refined_set);
  if (!file.empty()) {
    const Hdf5Reader reader(file.string());
    if (reader.HasJson(kSolveDiagnosticsJson))
      page->diagnostics = reader.ReadJson(kSolveDiagnosticsJson);
  }
  page->frame = CentreFrameOf(page->prior, page->refined);
}

RunPage ReadRunPage(const std::string& workdir, const json& run) {
  RunPage page;
  page.workdir = workdir;
  page.run = run;
  ReadRefineStage(&page);
  page.images = ImagesOfRun(page);
  page.flags = FlagsByImage(run);
  std::set<std::string> unique;
  for (const auto& [name, pose] : page.prior.world_from_cam) unique.insert(name);
  for (const auto& [name, pose] : page.refined.world_from_cam) unique.insert(name);
  // Capture order: a video's "2.jpg" before "10.jpg".
  page.names.assign(unique.begin(), unique.end());
  std::sort(page.names.begin(), page.names.end(), NaturalNameLess);
  if (!page.images.image_root.empty()) {
    // Decoding is most of a page's time (a rerun with nothing to do: 0.6 of its 1.1 s on the
    // 193-frame desk), one image per task.
    std::vector<std::string> uris(page.names.size());
    tbb::parallel_for(size_t{0}, page.names.size(), [&](size_t i) {
      uris[i] = ThumbnailDataUri((fs::path(page.images.image_root) / page.names[i]).string(),
                                 kThumbnailWidth);
    });
    for (size_t i = 0; i < page.names.size(); ++i) page.thumbnails[page.names[i]] = uris[i];
  }
  return page;
}

std::string CameraLink(const std::string& name) {
  return "<a href=\"#cam-" + HtmlEscape(name) + "\">" + HtmlEscape(name) + "</a>";
}

std::string Thumbnail(const RunPage& page, const std::string& name, int display_width) {
  const auto it = page.thumbnails.find(name);
  if (it == page.thumbnails.end() || it->second.empty()) return "";
  return "<a href=\"#cam-" + HtmlEscape(name) + "\"><img class=\"thumb\" src=\"" + it->second +
         "\" width=\"" + std::to_string(display_width) + "\" alt=\"" + HtmlEscape(name) +
         "\" title=\"" + HtmlEscape(name) + "\"></a>";
}

std::string VerdictSection(const RunPage& page) {
  const json& run = page.run;
  const std::string status = JsonText(run, "status");
  std::string html = "<section id=\"verdict\"><h2>Verdict</h2><p class=\"status " +
                     HtmlEscape(status) + "\">Status: <b>" + HtmlEscape(status) + "</b>";
  if (run.contains("seconds")) html += " in " + HtmlNumber(run["seconds"]) + " s";
  html += "</p>";
  if (!JsonText(run, "error").empty())
    html += "<p class=\"error\">" + HtmlEscape(JsonText(run, "error")) + "</p>";
  if (!page.stage_id.empty()) {
    const json& s = page.summary;
    html += "<p>" + HtmlEscape(page.stage_id) + ": decision <b>" +
            HtmlEscape(JsonText(s, "decision")) + "</b>";
    const json fired = JsonArray(JsonObject(s, "guardrails"), "fired");
    html +=
        fired.empty() ? ", no guardrail fired" : ", guardrails fired: " + HtmlEscape(fired.dump());
    std::map<std::string, int> verdicts;
    const json frames = JsonObject(s, "frame_verdicts");
    for (const auto& [name, verdict] : frames.items()) ++verdicts[JsonText(verdict, "verdict")];
    if (!verdicts.empty()) {
      html += "; frames: " + std::to_string(verdicts["held"]) + " held by their matches, " +
              std::to_string(verdicts["held_by_prior"]) + " placed by the trusted prior, " +
              std::to_string(verdicts["doubted"]) + " doubted";
    }
    const json u = JsonObject(s, "uncertainty");
    if (JsonAt(u, "computed") == true) {
      html += "; keypoint noise " + HtmlNumber(u["sigma_px"]) + " px, median σ " +
              HtmlNumber(u["median_rotation_deg"]) + "° rotation, " +
              HtmlNumber(u["median_centre"]) + " centre";
    }
    html += "</p>";
  }
  const json warnings = JsonArray(run, "warnings");
  html += "<h3>Warnings (" + std::to_string(warnings.size()) + ")</h3>";
  if (warnings.empty()) html += "<p>None.</p>";
  html += "<ul>";
  for (const json& warning : warnings) {
    html += "<li><code>" + HtmlEscape(JsonText(warning, "code")) + "</code> " +
            HtmlEscape(JsonText(warning, "message"));
    const json images = JsonArray(warning, "images");
    if (!images.empty()) {
      html += "<br>Images:";
      std::string thumbs;
      size_t shown = 0;
      for (const json& image : images) {
        if (!image.is_string()) continue;
        html += " " + CameraLink(image.get<std::string>());
        if (shown++ < kThumbnailsPerWarning)
          thumbs += Thumbnail(page, image.get<std::string>(), 96);
      }
      if (!thumbs.empty()) html += "<br>" + thumbs;
    }
    html += "</li>";
  }
  return html + "</ul></section>";
}

std::string StagesSection(const json& run) {
  std::string html = "<section id=\"stages\"><h2>Stages</h2><table>" +
                     HtmlRow({"stage", "type", "status", "seconds"}, "th");
  for (const json& stage : JsonArray(run, "stages")) {
    html +=
        HtmlRow({HtmlEscape(JsonText(stage, "id")), HtmlEscape(JsonText(stage, "type")),
                 HtmlEscape(JsonText(stage, "status")), HtmlNumber(JsonAt(stage, "seconds"), 3)});
  }
  return html + "</table></section>";
}

// A colour from green (share 0) to red (share 1).
std::string ShareColour(double share) {
  const double s = std::isfinite(share) ? std::clamp(share, 0.0, 1.0) : 1.0;
  const int red = static_cast<int>(std::lround(40 + 200 * s));
  const int green = static_cast<int>(std::lround(170 - 130 * s));
  return "rgb(" + std::to_string(red) + "," + std::to_string(green) + ",60)";
}

// One view of the centres: across, the main direction; up, the principal direction
// `vertical_axis` (1: the second, a top view; 0: the least, a side view), at one scale, the height
// following the spread. Prior grey, reference blue, refined coloured by its centre correction with
// the correction drawn; each refined camera opens its panel.
std::string CamerasSvg(const RunPage& page, const std::string& view, int vertical_axis) {
  const CentreFrame& frame = page.frame;
  const auto& solved = page.refined.world_from_cam;
  const Eigen::Vector3d u = frame.axes.col(2);
  const Eigen::Vector3d v = frame.axes.col(vertical_axis);
  const auto project = [&](const Eigen::Vector3d& x) {
    return Eigen::Vector2d((x - frame.mean).dot(u), (x - frame.mean).dot(v));
  };
  std::vector<Eigen::Vector2d> points;
  for (const auto& [name, pose] : solved) {
    points.push_back(project(pose.translation));
    for (const PoseSet* other : {&page.prior, &page.truth}) {
      const auto it = other->world_from_cam.find(name);
      if (it != other->world_from_cam.end()) points.push_back(project(it->second.translation));
    }
  }
  Eigen::Vector2d lo = points.front(), hi = points.front();
  for (const auto& p : points) {
    lo = lo.cwiseMin(p);
    hi = hi.cwiseMax(p);
  }
  const double width = 560.0, margin = 20.0;
  const double extent = std::max(hi.x() - lo.x(), 1e-12);
  const double scale = (width - 2 * margin) / extent;
  const double height = std::max(160.0, (hi.y() - lo.y()) * scale + 2 * margin);
  // A centre's screen position as two attributes: a circle's cx, cy or a line end's x1, y1.
  const auto at = [&](const Eigen::Vector3d& x, const char* x_name = "cx",
                      const char* y_name = "cy") {
    const Eigen::Vector2d p = project(x);
    const Eigen::Vector2d s(margin + (p.x() - lo.x()) * scale,
                            height - margin - (p.y() - lo.y()) * scale);
    return std::string(x_name) + "=\"" + HtmlNumber(s.x(), 6) + "\" " + y_name + "=\"" +
           HtmlNumber(s.y(), 6) + "\"";
  };
  const auto line = [&](const Eigen::Vector3d& a, const Eigen::Vector3d& b) {
    return "<line " + at(a, "x1", "y1") + " " + at(b, "x2", "y2");
  };
  std::string svg = "<svg id=\"cameras-" + view +
                    "\" xmlns=\"http://www.w3.org/2000/svg\" width=\"" + HtmlNumber(width, 4) +
                    "\" height=\"" + HtmlNumber(height, 4) +
                    "\" role=\"img\"><title>Camera centres, " + view +
                    " view: prior grey, reference blue, refined coloured by correction</title>";
  for (const auto& [name, pose] : solved) {
    const auto truth = page.truth.world_from_cam.find(name);
    if (truth != page.truth.world_from_cam.end()) {
      svg += "<circle " + at(truth->second.translation) + " r=\"2.5\" fill=\"#36c\"/>";
    }
    const auto prior = page.prior.world_from_cam.find(name);
    const std::string colour = ShareColour(frame.Share(name));
    if (prior != page.prior.world_from_cam.end()) {
      svg += line(prior->second.translation, pose.translation) + " stroke=\"" + colour +
             "\"/><circle " + at(prior->second.translation) + " r=\"3\" fill=\"#999\"/>";
    }
    svg += "<a href=\"#cam-" + HtmlEscape(name) + "\"><circle class=\"camera\" data-name=\"" +
           HtmlEscape(name) + "\" " + at(pose.translation) + " r=\"5\" fill=\"" + colour +
           "\"><title>" + HtmlEscape(name) + "</title></circle></a>";
  }
  return svg + "</svg>";
}

std::string JsonVector(const Eigen::Vector3d& x) {
  return "[" + HtmlNumber(x.x(), 7) + "," + HtmlNumber(x.y(), 7) + "," + HtmlNumber(x.z(), 7) + "]";
}

std::string JsonMatrix(const Eigen::Matrix3d& m) {
  std::string out = "[";
  for (int r = 0; r < 3; ++r) {
    for (int c = 0; c < 3; ++c) out += (r + c == 0 ? "" : ",") + HtmlNumber(m(r, c), 6);
  }
  return out + "]";
}

// The orbit view's data: per camera its refined, prior and reference centre and orientation in the
// centres' principal frame (rotated so that the least direction is up), and its frustum's half
// extents (w / 2f, h / 2f).
std::string OrbitData(const RunPage& page) {
  const CentreFrame& frame = page.frame;
  Eigen::Matrix3d to_frame;  // rows: main, second, least direction
  to_frame.row(0) = frame.axes.col(2).transpose();
  to_frame.row(1) = frame.axes.col(1).transpose();
  to_frame.row(2) = frame.axes.col(0).transpose();
  if (to_frame.determinant() < 0) to_frame.row(1) *= -1.0;
  const auto centre = [&](const Rigid3& pose) {
    return JsonVector(to_frame * (pose.translation - frame.mean));
  };
  const auto rotation = [&](const Rigid3& pose) {
    return JsonMatrix(to_frame * pose.rotation.toRotationMatrix());
  };
  std::string out = "{\"cameras\":[";
  bool first = true;
  for (const auto& [name, pose] : page.refined.world_from_cam) {
    Eigen::Vector2d half(0.5, 0.375);
    const int index = page.images.Find(name);
    if (index >= 0) {
      const ImageInfo& info = page.images.images[index];
      const CameraIntrinsics& camera = page.images.cameras.at(info.camera_index);
      if (camera.fx() > 0 && camera.fy() > 0) {
        half = Eigen::Vector2d(camera.width / (2 * camera.fx()), camera.height / (2 * camera.fy()));
      }
    }
    out += std::string(first ? "" : ",") + "{\"n\":" + json(name).dump() +
           ",\"c\":" + centre(pose) + ",\"r\":" + rotation(pose) + ",\"k\":[" +
           HtmlNumber(half.x(), 4) + "," + HtmlNumber(half.y(), 4) + "],\"colour\":\"" +
           ShareColour(frame.Share(name)) + "\"";
    const auto prior = page.prior.world_from_cam.find(name);
    if (prior != page.prior.world_from_cam.end()) {
      out += ",\"p\":" + centre(prior->second) + ",\"pr\":" + rotation(prior->second);
    }
    const auto truth = page.truth.world_from_cam.find(name);
    if (truth != page.truth.world_from_cam.end()) {
      out += ",\"g\":" + centre(truth->second) + ",\"gr\":" + rotation(truth->second);
    }
    out += "}";
    first = false;
  }
  return out + "]}";
}

std::string OrbitView(const RunPage& page) {
  std::string html =
      "<h3>Orbit view</h3><p>The cameras as frusta: refined coloured by correction, prior grey, "
      "reference blue. Drag to turn, wheel to zoom, click a camera to open it. <label><input "
      "type=\"checkbox\" id=\"orbit-prior\" checked> prior</label>";
  if (!page.truth.world_from_cam.empty()) {
    html += " <label><input type=\"checkbox\" id=\"orbit-truth\" checked> reference (" +
            HtmlEscape(page.truth_set) + ", Sim(3)-aligned)</label>";
  }
  // "</" cannot occur in the data: names are JSON-escaped and "</script" would need a slash
  // after "<", which json.dump() writes as is, so it is escaped here.
  std::string data = OrbitData(page);
  for (size_t at = data.find("</"); at != std::string::npos; at = data.find("</", at + 3)) {
    data.replace(at, 2, "<\\/");
  }
  return html +
         "</p><canvas id=\"orbit\" width=\"720\" height=\"480\"></canvas>"
         "<script id=\"orbit-data\" type=\"application/json\">" +
         data + "</script><script>" + kRunReportOrbitJs + "</script>";
}

std::string CamerasSection(const RunPage& page) {
  if (page.stage_id.empty())
    return "<section id=\"cameras\"><h2>Cameras</h2><p>No refine stage ran.</p></section>";
  std::string html = "<section id=\"cameras\"><h2>Cameras: " + HtmlEscape(page.prior_set) + " → " +
                     HtmlEscape(page.refined_set) + "</h2>";
  if (page.refined.world_from_cam.size() < 2) {
    return html + "<p>Fewer than two refined cameras: no view.</p></section>";
  }
  return html +
         "<p>Top view (the centres' two main directions) and side view (the main and the least "
         "direction): prior grey, refined coloured green to red by the size of its correction, "
         "the correction drawn" +
         (page.truth.world_from_cam.empty() ? std::string()
                                            : ", the reference blue (Sim(3)-aligned)") +
         "; click a camera to open it.</p>" + CamerasSvg(page, "top", 1) + " " +
         CamerasSvg(page, "side", 0) + OrbitView(page) + "</section>";
}

// A camera's numbers, as table cells: rotation and centre correction, σ, residual median, pairs,
// matches, flags.
struct CameraNumbers {
  std::string rotation = "–", centre = "–", sigma_rotation, sigma_centre, residual, pairs, matches;
  std::string flags;
  // The refine stage's frame verdict (held, held_by_prior, doubted), its reason and the sentence
  // that says why; empty for an image without one.
  std::string verdict, reason, detail;
};

// The verdict as a table cell: the word, the reason beside it, the sentence on hover.
std::string VerdictCell(const CameraNumbers& n) {
  if (n.verdict.empty()) return "–";
  return "<span class=\"verdict " + HtmlEscape(n.verdict) + "\" title=\"" + HtmlEscape(n.detail) +
         "\">" + HtmlEscape(n.verdict) +
         (n.reason.empty() ? "" : " (" + HtmlEscape(n.reason) + ")") + "</span>";
}

CameraNumbers NumbersOf(const RunPage& page, const std::string& name) {
  CameraNumbers n;
  const auto prior = page.prior.world_from_cam.find(name);
  const auto solved = page.refined.world_from_cam.find(name);
  if (prior != page.prior.world_from_cam.end() && solved != page.refined.world_from_cam.end()) {
    n.rotation = HtmlNumber(
        DegreesFromRadians(RotationDistance(prior->second.rotation, solved->second.rotation)));
    n.centre = HtmlNumber((prior->second.translation - solved->second.translation).norm());
  }
  const json verdict = JsonObject(JsonObject(page.summary, "frame_verdicts"), name.c_str());
  n.verdict = JsonText(verdict, "verdict");
  n.reason = JsonText(verdict, "reason");
  n.detail = JsonText(verdict, "detail");
  const json sigma = JsonObject(JsonObject(page.summary, "uncertainty"), "cameras");
  const json s = JsonObject(sigma, name.c_str());
  n.sigma_rotation = HtmlNumber(JsonAt(s, "rotation_deg"));
  n.sigma_centre = HtmlNumber(JsonAt(s, "centre"));
  const json images = JsonObject(page.diagnostics, "images");
  const json d = JsonObject(images, name.c_str());
  n.residual = HtmlNumber(JsonAt(d, "residual_median_px"));
  n.pairs = HtmlNumber(JsonAt(d, "num_pairs"), 9);
  n.matches = HtmlNumber(JsonAt(d, "num_matches"), 9);
  const auto it = page.flags.find(name);
  if (it != page.flags.end()) {
    for (const auto& code : it->second) n.flags += (n.flags.empty() ? "" : ", ") + code;
  }
  if (solved == page.refined.world_from_cam.end()) {
    n.flags += std::string(n.flags.empty() ? "" : ", ") + "not refined";
  }
  return n;
}

std::string CameraTable(const RunPage& page) {
  if (page.stage_id.empty()) return "";
  std::string html =
      "<section id=\"camera-section\"><h2>Per camera</h2><table id=\"camera-table\">" +
      HtmlRow({"image", "verdict", "rotation correction (°)", "centre correction", "σ rotation (°)",
               "σ centre", "residual median (px)", "pairs", "matches", "flags"},
              "th");
  for (const std::string& name : page.names) {
    const CameraNumbers n = NumbersOf(page, name);
    html += HtmlRow({CameraLink(name), VerdictCell(n), n.rotation, n.centre, n.sigma_rotation,
                     n.sigma_centre, n.residual, n.pairs, n.matches, HtmlEscape(n.flags)},
                    "td", "row-" + name);
  }
  return html + "</table></section>";
}

// One GNC stage's residual histogram: a bar per bin of the summary's edges, heights as the share
// of the stage's residuals.
std::string HistogramSvg(const json& stage, const std::vector<double>& edges,
                         const std::string& label) {
  std::vector<int> counts;
  for (const json& count : JsonArray(stage, "residual_histogram")) {
    counts.push_back(count.is_number_integer() ? count.get<int>() : 0);
  }
  if (counts.size() != edges.size() + 1) return "";
  double total = 0.0;
  for (const int count : counts) total += count;
  if (total <= 0) return "";
  const double bar = 14.0, height = 90.0, top = 18.0, width = bar * counts.size() + 24;
  std::string svg = "<svg class=\"histogram\" xmlns=\"http://www.w3.org/2000/svg\" width=\"" +
                    HtmlNumber(width, 4) + "\" height=\"" + HtmlNumber(top + height + 16, 4) +
                    "\"><text x=\"4\" y=\"13\" font-size=\"11\">" + HtmlEscape(label) + "</text>";
  for (size_t b = 0; b < counts.size(); ++b) {
    const double h = height * counts[b] / total;
    const std::string range =
        (b == 0              ? "< " + HtmlNumber(edges[0])
         : b == edges.size() ? "≥ " + HtmlNumber(edges.back())
                             : HtmlNumber(edges[b - 1]) + "–" + HtmlNumber(edges[b])) +
        " px: " + std::to_string(counts[b]);
    svg += "<rect x=\"" + HtmlNumber(5 + bar * b, 5) + "\" y=\"" + HtmlNumber(top + height - h, 5) +
           "\" width=\"" + HtmlNumber(bar - 2, 3) + "\" height=\"" + HtmlNumber(h, 5) +
           "\" fill=\"#58a\"><title>" + range + "</title></rect>";
  }
  // Axis labels under the 0.1, 1, 10, 100 px edges (bin b starts at edge b − 1).
  for (size_t e = 0; e < edges.size(); ++e) {
    const double decade = std::log10(edges[e]);
    if (std::abs(decade - std::round(decade)) > 1e-9) continue;
    svg += "<text x=\"" + HtmlNumber(5 + bar * (e + 1) - 3, 5) + "\" y=\"" +
           HtmlNumber(top + height + 12, 5) + "\" font-size=\"9\">" + HtmlNumber(edges[e]) +
           "</text>";
  }
  return svg + "</svg>";
}

std::string ResidualsSection(const RunPage& page) {
  std::vector<double> edges;
  for (const json& edge : JsonArray(page.summary, "residual_histogram_edges_px")) {
    if (edge.is_number()) edges.push_back(edge.get<double>());
  }
  std::string charts;
  for (const json& pass : JsonArray(page.summary, "passes")) {
    for (const json& stage : JsonArray(pass, "stages")) {
      charts += HistogramSvg(
          stage, edges,
          JsonText(pass, "name") + ", a = " + HtmlNumber(JsonAt(stage, "loss_scale_px2")) + " px²");
    }
  }
  if (charts.empty()) return "";
  return "<section id=\"residuals\"><h2>Residuals per GNC stage</h2><p>Norms of the "
         "cross-projection residuals at the end of each stage (share of the residuals per bin, "
         "pixels on a log axis): the annealing should move the mass left and leave the "
         "outliers on the right.</p>" +
         charts + "</section>";
}

// The pair-consistency matrix: images × images in capture order, a cell per pair with used
// matches coloured by its median residual against the inconsistent-pair threshold, the pairs the
// solve left unexplained outlined, the pairs the removal took black.
std::string PairMatrixSection(const RunPage& page) {
  const json pairs = JsonArray(page.diagnostics, "pairs");
  if (pairs.empty() || page.names.size() < 2) return "";
  std::map<std::string, size_t> index;
  for (size_t i = 0; i < page.names.size(); ++i) index[page.names[i]] = i;
  const json verdict = JsonObject(JsonObject(page.summary, "guardrails"), "inconsistent_pairs");
  const json given = JsonAt(verdict, "pair_threshold_px");
  const double threshold = given.is_number() && given.get<double>() > 0 ? given.get<double>() : 4.0;
  const size_t n = page.names.size();
  const double cell = std::max(1.0, 560.0 / static_cast<double>(n));
  const double side = cell * static_cast<double>(n);
  std::string svg = "<svg id=\"pair-matrix\" xmlns=\"http://www.w3.org/2000/svg\" width=\"" +
                    HtmlNumber(side + 2, 6) + "\" height=\"" + HtmlNumber(side + 2, 6) +
                    "\"><rect x=\"1\" y=\"1\" width=\"" + HtmlNumber(side, 6) + "\" height=\"" +
                    HtmlNumber(side, 6) + "\" fill=\"#f4f4f4\"/>";
  const auto rect = [&](size_t row, size_t column, const std::string& fill,
                        const std::string& title) {
    return "<rect x=\"" + HtmlNumber(1 + cell * column, 6) + "\" y=\"" +
           HtmlNumber(1 + cell * row, 6) + "\" width=\"" + HtmlNumber(cell, 4) + "\" height=\"" +
           HtmlNumber(cell, 4) + "\" fill=\"" + fill + "\"><title>" + title + "</title></rect>";
  };
  const auto cells = [&](const std::string& a, const std::string& b, const std::string& fill,
                         const std::string& title) {
    const auto i = index.find(a), j = index.find(b);
    if (i == index.end() || j == index.end()) return std::string();
    return rect(i->second, j->second, fill, title) + rect(j->second, i->second, fill, title);
  };
  const auto name = [](const json& image) {
    return image.is_string() ? image.get<std::string>() : std::string();
  };
  int drawn = 0;
  for (const json& pair : pairs) {
    if (!pair.is_array() || pair.size() != 4) continue;
    const double median = pair[3].is_number() ? pair[3].get<double>() : NAN;
    // Log colour scale: 0.1 px and below green, the threshold and above red.
    const double share =
        std::log(std::max(median, 0.1) / 0.1) / std::log(std::max(threshold, 0.2) / 0.1);
    const std::string title = HtmlEscape(name(pair[0])) + " – " + HtmlEscape(name(pair[1])) +
                              ": median " + HtmlNumber(median) + " px, " + HtmlNumber(pair[2], 9) +
                              " matches" + (median > threshold ? " (unexplained)" : "");
    svg += cells(name(pair[0]), name(pair[1]), ShareColour(share), title);
    ++drawn;
  }
  int removed = 0;
  for (const json& pair : JsonArray(page.diagnostics, "removed")) {
    if (!pair.is_array() || pair.size() != 4) continue;
    svg += cells(name(pair[0]), name(pair[1]), "#000",
                 HtmlEscape(name(pair[0])) + " – " + HtmlEscape(name(pair[1])) +
                     ": removed by the pair removal (median " + HtmlNumber(pair[3]) + " px)");
    ++removed;
  }
  return "<section id=\"pairs\"><h2>Pair consistency</h2><p>Images × images in capture order; a "
         "cell per pair the solve used, coloured by the median of its matches' residuals at the "
         "solution from green (0.1 px and below) to red (the inconsistent-pair threshold, " +
         HtmlNumber(threshold) + " px, and above); black: removed by the wrong-pair removal. " +
         std::to_string(drawn) + " pairs, " + std::to_string(removed) +
         " removed. Hover a cell for its pair.</p>" + svg + "</svg></section>";
}

// A camera's panel, shown when it is the page's target (a click on it anywhere): its image, its
// numbers and its worst pairs.
std::string CameraPanels(const RunPage& page) {
  std::map<std::string, std::vector<std::pair<double, std::string>>> pairs_of;
  for (const json& pair : JsonArray(page.diagnostics, "pairs")) {
    if (!pair.is_array() || pair.size() != 4 || !pair[0].is_string() || !pair[1].is_string())
      continue;
    const double median = pair[3].is_number() ? pair[3].get<double>() : INFINITY;
    const std::string a = pair[0], b = pair[1];
    const std::string text = HtmlNumber(median) + " px, " + HtmlNumber(pair[2], 9) + " matches";
    pairs_of[a].emplace_back(median, CameraLink(b) + " " + text);
    pairs_of[b].emplace_back(median, CameraLink(a) + " " + text);
  }
  std::string html;
  for (const std::string& name : page.names) {
    const CameraNumbers n = NumbersOf(page, name);
    html += "<aside class=\"panel\" id=\"cam-" + HtmlEscape(name) +
            "\"><a class=\"close\" href=\"#camera-section\">close ✕</a><h3>" + HtmlEscape(name) +
            "</h3>";
    const auto thumbnail = page.thumbnails.find(name);
    html += thumbnail != page.thumbnails.end() && !thumbnail->second.empty()
                ? "<img src=\"" + thumbnail->second + "\" width=\"" +
                      std::to_string(kThumbnailWidth) + "\" alt=\"" + HtmlEscape(name) + "\">"
                : "<p>(image not found)</p>";
    const auto unit = [](const std::string& number, const char* unit_text) {
      return number == "–" ? number : number + unit_text;
    };
    html +=
        "<table>" +
        HtmlRow({"verdict", VerdictCell(n) +
                                (n.detail.empty() ? std::string() : ": " + HtmlEscape(n.detail))}) +
        HtmlRow({"rotation correction", unit(n.rotation, "°")}) +
        HtmlRow({"centre correction", n.centre}) +
        HtmlRow({"σ rotation", unit(n.sigma_rotation, "°")}) +
        HtmlRow({"σ centre", n.sigma_centre}) +
        HtmlRow({"residual median", unit(n.residual, " px")}) +
        HtmlRow({"pairs / matches", n.pairs + " / " + n.matches}) +
        HtmlRow({"flags", HtmlEscape(n.flags.empty() ? "none" : n.flags)}) +
        "</table><p><a href=\"#row-" + HtmlEscape(name) + "\">its row</a></p>";
    auto& list = pairs_of[name];
    std::sort(list.begin(), list.end(),
              [](const auto& a, const auto& b) { return a.first > b.first; });
    if (!list.empty()) {
      html += "<p>Worst pairs (median residual):</p><ol>";
      for (size_t k = 0; k < std::min(kPairsPerPanel, list.size()); ++k) {
        html += "<li>" + list[k].second + "</li>";
      }
      html += "</ol>";
      if (list.size() > kPairsPerPanel) {
        html += "<p>and " + std::to_string(list.size() - kPairsPerPanel) +
                " more (all in the pair matrix)</p>";
      }
    }
    html += "</aside>";
  }
  return html;
}

std::string MetricsSection(const json& run) {
  const json metrics = JsonObject(run, "metrics");
  std::string rows, splat_rows;
  // metrics.<pose set>.<alignment> from evaluate, metrics.<splat stage>.<pose set> from splat.
  for (const auto& [group, by_key] : metrics.items()) {
    if (!by_key.is_object()) continue;
    for (const auto& [key, entry] : by_key.items()) {
      if (!entry.is_object()) continue;
      if (entry.contains("mean_rotation_deg")) {
        rows += HtmlRow({HtmlEscape(group), HtmlEscape(key), HtmlNumber(entry["mean_rotation_deg"]),
                         HtmlNumber(JsonAt(entry, "mean_centre_m")),
                         HtmlNumber(JsonAt(entry, "num_frames"), 6)});
      } else if (entry.contains("psnr")) {
        splat_rows += HtmlRow(
            {HtmlEscape(key), HtmlEscape(group), HtmlEscape(JsonText(entry, "trainer")),
             HtmlEscape(JsonText(entry, "status")), HtmlNumber(JsonAt(entry, "psnr"), 4),
             HtmlNumber(JsonAt(entry, "ssim")), HtmlNumber(JsonAt(entry, "raytime_psnr"), 4),
             HtmlNumber(JsonAt(entry, "raytime_ssim")), HtmlNumber(JsonAt(entry, "seconds"))});
      }
    }
  }
  std::string html;
  if (!rows.empty()) {
    html +=
        "<section id=\"metrics\"><h2>Against the ground truth</h2><table>" +
        HtmlRow({"pose set", "alignment", "mean rotation error (°)", "mean centre error", "frames"},
                "th") +
        rows + "</table></section>";
  }
  if (!splat_rows.empty()) {
    html += "<section id=\"splat\"><h2>Splats (held-out views)</h2><table>" +
            HtmlRow({"pose set", "stage", "trainer", "status", "PSNR (dB)", "SSIM",
                     "raytime PSNR (dB)", "raytime SSIM", "seconds"},
                    "th") +
            splat_rows + "</table></section>";
  }
  return html;
}

// Each splat stage's held-out renders beside the photos they were scored against (RESULT/renders
// and RESULT/gt, written when raytime rendered the trainer's splats: trainer opensplat), one row
// per held-out view, one column per pose set.
std::string SplatRendersSection(const json& run) {
  std::string html;
  for (const json& stage : JsonArray(run, "stages")) {
    if (JsonText(stage, "type") != "splat") continue;
    std::vector<std::pair<std::string, fs::path>> sets;  // pose set, result folder
    std::set<std::string> views;
    for (const json& record : JsonArray(JsonObject(stage, "summary"), "pose_sets")) {
      const fs::path renders = fs::path(JsonText(record, "result_dir")) / "renders";
      if (JsonText(record, "status") != "ok" || !fs::is_directory(renders)) continue;
      sets.emplace_back(JsonText(record, "pose_set"), renders.parent_path());
      for (const auto& entry : fs::directory_iterator(renders)) {
        views.insert(entry.path().filename().string());
      }
    }
    if (sets.empty()) continue;
    html += "<section class=\"splat-renders\"><h2>" + HtmlEscape(JsonText(stage, "id")) +
            ": held-out views</h2><p>The photo, then each pose set's splats rendered by raytime at "
            "that camera (what its PSNR scores).</p><table><tr><th>view</th><th>photo</th>";
    for (const auto& [name, dir] : sets) html += "<th>" + HtmlEscape(name) + "</th>";
    html += "</tr>";
    for (const std::string& view : views) {
      html += "<tr><td>" + HtmlEscape(view) + "</td><td>";
      const std::string photo =
          ThumbnailDataUri((sets.front().second / "gt" / view).string(), kThumbnailWidth);
      if (!photo.empty()) html += "<img src=\"" + photo + "\" alt=\"photo\">";
      html += "</td>";
      for (const auto& [name, dir] : sets) {
        const std::string render =
            ThumbnailDataUri((dir / "renders" / view).string(), kThumbnailWidth);
        html += "<td>" +
                (render.empty() ? std::string("–")
                                : "<img src=\"" + render + "\" alt=\"" + HtmlEscape(name) + "\">") +
                "</td>";
      }
      html += "</tr>";
    }
    html += "</table></section>";
  }
  return html;
}

const char* RunPageStyle() {
  return ".panel{display:none;position:fixed;top:0;right:0;width:22em;max-height:100vh;"
         "overflow:auto;background:#fff;border-left:2px solid #888;padding:0.5em 1em;"
         "box-shadow:-4px 0 8px rgba(0,0,0,.2)}.panel:target{display:block}"
         ".panel .close{float:right}.panel table td{text-align:left}img.thumb{margin:2px}"
         "tr:target{background:#ffd}.histogram{margin:2px}.verdict.doubted{color:#b00;"
         "font-weight:bold}.verdict.held_by_prior{color:#a60}";
}

}  // namespace

std::string WriteRunReport(const std::string& workdir) {
  const auto start = std::chrono::steady_clock::now();
  const std::string summary_path = (fs::path(workdir) / "summary.json").string();
  if (!fs::exists(summary_path)) {
    ThrowInput(summary_path, 0,
               "no such file: not a raytime work directory (raytime run writes it)");
  }
  const json run = json::parse(ReadTextFile(summary_path), nullptr, false);
  if (run.is_discarded() || !run.is_object()) ThrowInput(summary_path, 0, "not a run summary");
  const RunPage page = ReadRunPage(workdir, run);
  const std::string title =
      "raytime run " + JsonText(run, "name") + " (" + JsonText(run, "status") + ")";
  const std::string html =
      "<!DOCTYPE html><html lang=\"en\"><head><meta charset=\"utf-8\"><title>" + HtmlEscape(title) +
      "</title><style>" + PageStyle() + RunPageStyle() + "</style></head><body><h1>" +
      HtmlEscape(title) + "</h1><p>Work directory <code>" + HtmlEscape(workdir) +
      "</code>, pipeline <code>" + HtmlEscape(JsonText(run, "pipeline")) + "</code>, raytime " +
      HtmlEscape(JsonText(run, "raytime_version")) + "</p>" + VerdictSection(page) +
      CamerasSection(page) + CameraTable(page) + ResidualsSection(page) + PairMatrixSection(page) +
      MetricsSection(run) + SplatRendersSection(run) + StagesSection(run) + CameraPanels(page) +
      "</body></html>\n";
  const std::string path = (fs::path(workdir) / "report.html").string();
  WriteTextFileAtomically(path, html);
  spdlog::debug(fmt::format("report: {} kB in {:.2f} s", html.size() / 1024, SecondsSince(start)));
  return path;
}

}  // namespace raytime
