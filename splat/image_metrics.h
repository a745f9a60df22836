// raytime's own image metrics for held-out renders (SPEC §7; paper §4.5, Table 4): PSNR and SSIM
// computed the same way whichever trainer rendered the views, so pose sources trained by
// different trainers (or trainer versions) are scored on one scale. LPIPS needs a learned network
// and is taken from the trainer only.
//
// Conventions, those of the 3DGS trainers' own metrics: values on [0, 1] (8-bit / 255, 16-bit /
// 65535), alpha dropped; per image, PSNR = 10 log10(1 / MSE) with the MSE over all pixels and
// channels; SSIM (Wang et al. 2004) with an 11x11 Gaussian window, sigma 1.5, C1 = 0.01^2,
// C2 = 0.03^2, per channel and averaged over the map and the channels; a folder's value is the
// mean over its images. Borders: the window is reflected (OpenCV's default, BORDER_REFLECT_101)
// where the Inria code zero-pads, so SSIM may differ from a trainer's own in the third decimal;
// PSNR agrees exactly.
#pragma once

#include <opencv2/core.hpp>
#include <string>
#include <vector>

namespace raytime {

// PSNR in dB of `render` against `reference`: same size and channels, any depth (converted to
// [0, 1] as above). +infinity for identical images. InputError on a size or channel mismatch.
double Psnr(const cv::Mat& render, const cv::Mat& reference);

// Mean SSIM over the map and the channels, in [-1, 1]; 1 for identical images.
double Ssim(const cv::Mat& render, const cv::Mat& reference);

// One held-out view: a render and its ground truth, as two files or as one side-by-side file with
// the ground truth in the left half and the render in the right (how gsplat and nerfstudio save
// their evaluation images).
struct HeldOutView {
  std::string render_path;
  std::string reference_path;  // "" for a side-by-side file in render_path
};

struct HeldOutScore {
  int num_images = 0;
  double psnr = 0.0;  // mean over images, dB (+infinity when a render equals its ground truth)
  double ssim = 0.0;  // mean over images
};

// Scores every view; InputError naming the file that cannot be read, or a pair whose sizes differ.
HeldOutScore ScoreHeldOutViews(const std::vector<HeldOutView>& views);

// The views of a `renders/` + `gt/` folder pair (the Inria layout, `MODEL/test/ours_<it>/`):
// every image file of `renders_dir` with the file of the same name in `gt_dir`, by sorted name.
// InputError when a render has no ground truth or the folder holds no image.
std::vector<HeldOutView> ViewsOfFolderPair(const std::string& renders_dir,
                                           const std::string& gt_dir);

}  // namespace raytime
