// A nerfstudio folder's transforms.json written again with raytime's poses into another folder (a
// work directory), so that it takes the place of the user's file without touching it (issue 49).
//
// nerfstudio's dataparser (nerfstudio_dataparser.py) resolves every path from the folder holding
// transforms.json: file_path, depth_file_path, mask_path, ply_file_path and the train / val / test
// filename lists; with a downscale factor N it looks for images_N/, depths_N/ and masks_N/ beside
// them. So every key keeps its value, paths included, and the output folder gets a symbolic link
// per entry of the input folder those paths start with (and its images_N-style siblings): the same
// text resolves to the same files from either folder. A path whose first entry cannot be linked
// (the output folder already holds that name, or it lies above the folder) is written absolute.
#pragma once

#include <map>
#include <nlohmann/json.hpp>
#include <set>
#include <string>
#include <vector>

#include "core/types.h"

namespace raytime {

struct NerfstudioUpdate {
  // By image name (as ReadTransformsJson names them): the frame's new camera-to-world, in the
  // file's world. A frame without one is moved from "frames" to "raytime_left_out_frames" (and out
  // of the split lists), so that no trainer uses it, with its entry unchanged but for its raytime_
  // keys.
  PoseSet poses;
  // By image name: the frame's camera where it changed (self-calibration), written where nerfstudio
  // reads it from (the top level when every frame shares the value, else per frame).
  std::map<std::string, CameraIntrinsics> cameras;
  // By image name: keys added to the frame (raytime_verdict, raytime_rotation_sigma_deg, ...).
  nlohmann::json frame_fields = nlohmann::json::object();
};

struct NerfstudioWriteSummary {
  std::string path;                   // OUTPUT_DIR/transforms.json
  int frames_updated = 0;             // frames whose transform_matrix was replaced
  std::vector<std::string> left_out;  // image names of the frames moved out of "frames"
  std::vector<std::string> links;     // entries of the input folder linked into the output's
  std::vector<std::string> absolute;  // first path entries written as absolute paths instead
  bool intrinsics_updated = false;
};

// Writes OUTPUT_DIR/transforms.json: the document `text` read from `input_path` with only
// `update` applied (key order, every other key and value as they were; indent 4, as nerfstudio
// writes), and the links its paths need. `reserved` are names the output folder will hold for
// other reasons (never linked). Atomic. InputError when the output would replace the input file or
// a frame is malformed (ReadTransformsFrames).
NerfstudioWriteSummary WriteNerfstudioFolder(const std::string& input_path, const std::string& text,
                                             const std::string& output_dir,
                                             const NerfstudioUpdate& update,
                                             const std::set<std::string>& reserved);

}  // namespace raytime
