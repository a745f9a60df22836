// Held-out views of a trainer-ready export rendered by raytime itself and scored (issue 33): the
// same renderer (splat/splat_render.h) and the same metrics (splat/image_metrics.h) for every
// trainer and pose source, so Table 4's columns differ only by the poses. Also the train-only view
// of an export a trainer is given, so a held-out frame never reaches it.
#pragma once

#include <string>
#include <vector>

#include "splat/image_metrics.h"
#include "splat/splat_render.h"

namespace raytime {

// The export's held-out image names (DATA_DIR/test.txt, one per line).
std::vector<std::string> HeldOutNames(const std::string& data_dir);

// Writes VIEW_DIR/sparse/0/{cameras,images,points3D}.bin: the export's model (DATA_DIR/sparse/0)
// without its held-out images, so a trainer pointed at VIEW_DIR (with its images read from
// DATA_DIR/images) never sees one. `seed` other than 0 shuffles the images' order and the points'
// order (their ids, tracks renumbered alike): a trainer that visits cameras in file order and
// draws each Gaussian's initial state in file order from a fixed random state (OpenSplat seeds its
// generators with 42) then trains another way on the same frames and points, which is how two
// "seeds" of one pose set measure the training-noise floor. Returns the number of
// training images. `random_points` > 0 replaces the export's points by that many drawn uniformly in
// a ball around the training cameras (centre: their mean; radius: 3 × their largest distance from
// it, the extent of gsplat's random initialization) with random colours, from `seed`: the paper's
// initialization that favours no pose source (§4.5; the export's points are each pose set's own
// tracks). InputError naming the file when the export has no model or no test.txt, or holds no
// training image.
int WriteTrainOnlyView(const std::string& data_dir, const std::string& view_dir, int seed = 0,
                       int random_points = 0);

struct HeldOutRenderOptions {
  // The trainer's image downscale factor: views are rendered at the photos' size / downscale
  // (rounded down, as OpenSplat and the Inria code resize), intrinsics scaled alike, the photos
  // resized to the same size (area averaging) before scoring.
  double downscale = 1.0;
  SplatRenderOptions render;
};

// Renders every held-out camera of the export DATA_DIR (test.txt, sparse/0 poses and PINHOLE
// intrinsics, images/) from `splats` (ReadGaussianSplatPly), writes OUT_DIR/renders/<name>.png and
// the photo it is scored against OUT_DIR/gt/<name>.png, and returns their PSNR / SSIM. InputError
// naming the file for a missing or unreadable .ply, model, image or held-out camera.
HeldOutScore RenderAndScoreHeldOutViews(const GaussianSplats& splats, const std::string& data_dir,
                                        const std::string& out_dir,
                                        const HeldOutRenderOptions& options);

}  // namespace raytime
