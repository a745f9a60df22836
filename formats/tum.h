// TUM RGB-D trajectory files: one pose per line, `timestamp tx ty tz qx qy qz qw`, camera-to-world
// (translation = camera centre), '#' comments. The timestamp token, exactly as written, is the
// pose's name unless a names list maps row k to image name k.
#pragma once

#include <string>
#include <vector>

#include "core/types.h"

namespace raytime {

// `names`: optional image names in row order (must have as many entries as pose rows).
PoseSet ReadTumTrajectory(const std::string& path, const std::vector<std::string>& names = {});
// Writes the poses in name order; the name is the first column when `timestamps` is empty,
// otherwise timestamps[k] is written for the k-th pose in name order. Atomic.
void WriteTumTrajectory(const std::string& path, const PoseSet& poses,
                        const std::vector<std::string>& timestamps = {});

}  // namespace raytime
