// Writes a downsampled copy of a dataset in the Strecha layout (images + .camera files), with
// intrinsics rescaled in the OpenCV pixel convention. Used to make the repository's sample scene.
#pragma once

#include <string>

#include "formats/dataset.h"

namespace raytime {

struct ResizeSceneOptions {
  int width = 768;        // output width in pixels; height keeps the aspect ratio
  int jpeg_quality = 90;  // 0-100
};

// Returns the number of images written. The output folder is written atomically.
int ResizeScene(const DatasetOptions& input, const std::string& output_root,
                const ResizeSceneOptions& options);

}  // namespace raytime
