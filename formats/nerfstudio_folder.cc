#include "formats/nerfstudio_folder.h"

#include <algorithm>
#include <filesystem>
#include <regex>

#include "core/atomic_file.h"
#include "core/error.h"
#include "formats/nerfstudio.h"

namespace fs = std::filesystem;
using nlohmann::json;
using nlohmann::ordered_json;

namespace raytime {
namespace {

// The split lists nerfstudio reads (nerfstudio_dataparser.py): paths, resolved like file_path.
const char* const kSplitLists[] = {"train_filenames", "val_filenames", "test_filenames"};

bool IsPathKey(const std::string& key) {
  return key.size() > 5 && key.compare(key.size() - 5, 5, "_path") == 0;
}

std::string WithoutDotSlash(std::string path) {
  while (path.compare(0, 2, "./") == 0) path.erase(0, 2);
  return path;
}

// Calls `visit` on every path string of the document: keys ending in _path at the top level and in
// frames (file_path, depth_file_path, mask_path, ply_file_path, ...) and the split lists' entries.
template <class Visit>
void ForEachPath(ordered_json& document, Visit&& visit) {
  const auto visit_object = [&](ordered_json& object) {
    for (auto& [key, value] : object.items()) {
      if (IsPathKey(key) && value.is_string()) visit(value);
    }
  };
  visit_object(document);
  for (const char* list : kSplitLists) {
    if (!document.contains(list) || !document[list].is_array()) continue;
    for (ordered_json& value : document[list]) {
      if (value.is_string()) visit(value);
    }
  }
  for (const char* frames : {"frames", "raytime_left_out_frames"}) {
    if (!document.contains(frames)) continue;
    for (ordered_json& frame : document[frames]) {
      if (frame.is_object()) visit_object(frame);
    }
  }
}

// The first entry of a relative path ("images" for "./images/a.jpg"); "" for an absolute path.
std::string FirstEntry(const std::string& path) {
  const fs::path normal = fs::path(WithoutDotSlash(path)).lexically_normal();
  if (normal.empty() || normal.is_absolute()) return "";
  return normal.begin()->string();
}

bool SameFile(const fs::path& a, const fs::path& b) {
  std::error_code error;
  return fs::equivalent(a, b, error);
}

// Links input_dir/entry as output_dir/entry; false when it cannot (the name is taken by something
// else, is reserved, lies above the folder, or holds the output folder itself).
bool LinkEntry(const fs::path& input_dir, const fs::path& output_dir, const std::string& entry,
               const std::set<std::string>& reserved) {
  if (entry.empty() || entry == "." || entry == ".." || reserved.count(entry) > 0) return false;
  const fs::path target = fs::weakly_canonical(input_dir / entry);
  const fs::path output = fs::weakly_canonical(output_dir);
  const auto [end, unused] =
      std::mismatch(target.begin(), target.end(), output.begin(), output.end());
  if (end == target.end()) return false;  // the output folder lies inside it: a loop
  const fs::path link = output_dir / entry;
  std::error_code error;
  const fs::file_status status = fs::symlink_status(link, error);
  if (fs::is_symlink(status) && SameFile(link, target)) return true;
  // A link holds nothing of anyone's: one to another folder (an earlier dataset's) is replaced.
  if (fs::is_symlink(status)) fs::remove(link);
  if (fs::exists(status) && !fs::is_symlink(status)) return false;
  if (fs::is_directory(target)) {
    fs::create_directory_symlink(target, link);
  } else {
    fs::create_symlink(target, link);
  }
  return true;
}

// 3. Links what the paths start with, and nerfstudio's downscaled siblings of those folders
// (images_2, depths_4, masks_8, ...); paths whose first entry cannot be linked become absolute.
void LinkPaths(ordered_json& document, const fs::path& input_dir, const fs::path& output_dir,
               const std::set<std::string>& reserved, NerfstudioWriteSummary* summary) {
  std::set<std::string> entries;
  ForEachPath(document, [&](ordered_json& value) {
    const std::string entry = FirstEntry(value.get<std::string>());
    if (!entry.empty()) entries.insert(entry);
  });
  std::set<std::string> prefixes = {"images", "depths", "masks"};
  for (const std::string& entry : entries) prefixes.insert(entry);
  std::error_code error;
  for (const auto& item : fs::directory_iterator(input_dir, error)) {
    const std::string name = item.path().filename().string();
    const size_t underscore = name.rfind('_');
    if (underscore == std::string::npos || prefixes.count(name.substr(0, underscore)) == 0)
      continue;
    if (std::regex_match(name.substr(underscore + 1), std::regex("[0-9]+"))) entries.insert(name);
  }
  std::set<std::string> unlinked;
  for (const std::string& entry : entries) {
    if (!fs::exists(input_dir / entry)) continue;  // it resolved to nothing before either
    if (LinkEntry(input_dir, output_dir, entry, reserved)) {
      summary->links.push_back(entry);
    } else {
      unlinked.insert(entry);
      summary->absolute.push_back(entry);
    }
  }
  ForEachPath(document, [&](ordered_json& value) {
    const std::string path = value.get<std::string>();
    if (unlinked.count(FirstEntry(path)) > 0) {
      value = (fs::absolute(input_dir) / WithoutDotSlash(path)).lexically_normal().string();
    }
  });
}

// 1. Each frame's new transform_matrix and raytime_ keys; a frame without a new pose moves to
// raytime_left_out_frames, and out of the split lists, so that no trainer reads it.
void UpdateFrames(ordered_json& document, const TransformsFrames& parsed,
                  const NerfstudioUpdate& update, NerfstudioWriteSummary* summary) {
  ordered_json kept = ordered_json::array();
  ordered_json left_out = ordered_json::array();
  std::set<std::string> left_out_paths;
  for (size_t i = 0; i < parsed.frames.size(); ++i) {
    ordered_json frame = document["frames"][i];
    const std::string& name = parsed.frames[i].name;
    const auto fields = update.frame_fields.find(name);
    if (fields != update.frame_fields.end()) {
      for (const auto& [key, value] : fields->items()) frame[key] = value;
    }
    const auto pose = update.poses.world_from_cam.find(name);
    if (pose == update.poses.world_from_cam.end()) {
      left_out_paths.insert(WithoutDotSlash(frame["file_path"].get<std::string>()));
      left_out.push_back(std::move(frame));
      summary->left_out.push_back(name);
      continue;
    }
    frame["transform_matrix"] = ordered_json::parse(TransformMatrixJson(pose->second).dump());
    kept.push_back(std::move(frame));
    ++summary->frames_updated;
  }
  document["frames"] = std::move(kept);
  if (left_out.empty()) return;
  document["raytime_left_out_frames"] = std::move(left_out);
  for (const char* list : kSplitLists) {
    if (!document.contains(list) || !document[list].is_array()) continue;
    ordered_json& names = document[list];
    names.erase(std::remove_if(names.begin(), names.end(),
                               [&](const ordered_json& value) {
                                 return value.is_string() && left_out_paths.count(WithoutDotSlash(
                                                                 value.get<std::string>())) > 0;
                               }),
                names.end());
  }
}

// Whether `object` states the distortion group (nerfstudio reads all of it from one place).
bool StatesDistortion(const ordered_json& object) {
  for (const char* key : {"k1", "k2", "k3", "k4", "p1", "p2", "distortion_params"}) {
    if (object.contains(key)) return true;
  }
  return false;
}

// Sets `key` of `object`'s intrinsics, into distortion_params where the object gives distortion
// that way ([k1, k2, k3, k4, p1, p2]).
void SetIntrinsic(ordered_json& object, const std::string& key, const json& value) {
  static const std::map<std::string, int> kDistortionIndex = {
      {"k1", 0}, {"k2", 1}, {"p1", 4}, {"p2", 5}};
  const auto index = kDistortionIndex.find(key);
  if (index != kDistortionIndex.end() && object.contains("distortion_params")) {
    object["distortion_params"][index->second] = value.get<double>();
  } else {
    object[key] = value.get<double>();
  }
}

// 2. Self-calibration's cameras, where nerfstudio reads each value from: the top level keeps a key
// it states when every kept frame has the same new value; otherwise the key (for distortion, the
// group) leaves the top level and every frame states its own.
void UpdateIntrinsics(ordered_json& document, const TransformsFrames& parsed,
                      const NerfstudioUpdate& update, NerfstudioWriteSummary* summary) {
  std::vector<std::pair<ordered_json*, json>> frames;  // kept frame, its camera's keys
  bool changed = false;
  for (size_t i = 0; i < parsed.frames.size(); ++i) {
    const TransformsFrame& frame = parsed.frames[i];
    if (!update.poses.Has(frame.name)) continue;
    const auto camera = update.cameras.find(frame.name);
    changed = changed || (camera != update.cameras.end() && !(camera->second == frame.camera));
    frames.emplace_back(
        &document["frames"][i],
        TransformsIntrinsicsJson(camera != update.cameras.end() ? camera->second : frame.camera));
  }
  if (!changed) return;
  summary->intrinsics_updated = true;
  const auto shared = [&](const char* key) {
    return std::all_of(frames.begin(), frames.end(), [&](const auto& frame) {
      return frame.second[key] == frames.front().second[key];
    });
  };
  const bool top_distortion = StatesDistortion(document);
  const bool distortion_shared = shared("k1") && shared("k2") && shared("p1") && shared("p2");
  if (top_distortion && !distortion_shared) {
    for (const char* key : {"k1", "k2", "k3", "k4", "p1", "p2", "distortion_params"}) {
      document.erase(key);
    }
  }
  for (const char* key : {"fl_x", "fl_y", "cx", "cy", "k1", "k2", "p1", "p2"}) {
    const bool distortion = key[0] == 'k' || key[0] == 'p';
    const bool at_top = distortion ? top_distortion && distortion_shared : document.contains(key);
    if (at_top && shared(key)) {
      SetIntrinsic(document, key, frames.front().second[key]);
      continue;
    }
    if (at_top) document.erase(key);
    for (auto& [frame, values] : frames) {
      // A frame stating no distortion keeps none where it has none.
      if (distortion && values[key] == 0.0 && !StatesDistortion(*frame)) continue;
      SetIntrinsic(*frame, key, values[key]);
    }
  }
  const bool any_distortion = std::any_of(frames.begin(), frames.end(), [](const auto& frame) {
    return frame.second["k1"] != 0.0 || frame.second["k2"] != 0.0 || frame.second["p1"] != 0.0 ||
           frame.second["p2"] != 0.0;
  });
  if (any_distortion && document.contains("camera_model") && document["camera_model"] != "OPENCV") {
    document["camera_model"] = "OPENCV";  // PINHOLE models no distortion
  }
}

}  // namespace

NerfstudioWriteSummary WriteNerfstudioFolder(const std::string& input_path, const std::string& text,
                                             const std::string& output_dir,
                                             const NerfstudioUpdate& update,
                                             const std::set<std::string>& reserved) {
  NerfstudioWriteSummary summary;
  summary.path = (fs::path(output_dir) / "transforms.json").string();
  if (SameFile(summary.path, input_path)) {
    ThrowInput(input_path, 0,
               "raytime would write its transforms.json over this file (the work directory is the "
               "dataset's folder); choose another --workdir");
  }
  const TransformsFrames parsed =
      ReadTransformsFrames(input_path, ParseTransformsJson(input_path, text));
  ordered_json document = ordered_json::parse(text);
  UpdateIntrinsics(document, parsed, update, &summary);
  UpdateFrames(document, parsed, update, &summary);
  fs::create_directories(output_dir);
  LinkPaths(document, fs::path(input_path).parent_path(), output_dir, reserved, &summary);
  WriteTextFileAtomically(summary.path, document.dump(4) + "\n");
  return summary;
}

}  // namespace raytime
