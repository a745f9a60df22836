// _raytime.read_poses / write_poses: the pose files formats/ reads (those of `raytime evaluate
// --est-format`, a raytime HDF5 file's pose set too) and writes (a COLMAP model, nerfstudio's
// transforms.json, a TUM trajectory), as names and (N, 4, 4) camera-to-world arrays.

#include <algorithm>
#include <string>
#include <vector>

#include "core/error.h"
#include "core/options.h"
#include "formats/colmap_model.h"
#include "formats/dataset.h"
#include "formats/nerfstudio.h"
#include "formats/tum.h"
#include "python/arrays.h"
#include "python/bindings.h"

namespace py = pybind11;

namespace raytime::python {
namespace {

const std::vector<std::string> kWritableFormats = {"colmap", "colmap_binary", "nerfstudio", "tum"};

py::tuple ReadPoses(const std::string& path, const std::string& format,
                    const std::string& pose_set) {
  const PoseSet poses = ReadPoseFileOrSet(format, path, pose_set, "(pose_set=)");
  std::vector<std::string> names;
  std::vector<Rigid3> world_from_cam;
  for (const auto& [name, pose] : poses.world_from_cam) {
    names.push_back(name);
    world_from_cam.push_back(pose);
  }
  return py::make_tuple(names, PosesToArray(world_from_cam));
}

// The images of `names` with their cameras (one per distinct camera dict), for the writers that
// write intrinsics.
ImageSet ImagesOf(const std::vector<std::string>& names, const std::vector<py::dict>& cameras,
                  PixelConvention convention) {
  ImageSet images;
  for (size_t i = 0; i < names.size(); ++i) {
    const CameraIntrinsics camera =
        CameraFromDict(cameras.at(i), convention, "cameras['" + names[i] + "']");
    auto same = std::find(images.cameras.begin(), images.cameras.end(), camera);
    const int index = static_cast<int>(same - images.cameras.begin());
    if (same == images.cameras.end()) images.cameras.push_back(camera);
    images.images.push_back({names[i], camera.width, camera.height, index});
  }
  std::sort(images.images.begin(), images.images.end(),
            [](const ImageInfo& a, const ImageInfo& b) { return a.name < b.name; });
  return images;
}

void WritePoses(const std::string& path, const std::vector<std::string>& names,
                const PoseArray& poses, const std::string& format,
                const std::vector<py::dict>& cameras, const std::string& pixel_convention) {
  if (std::find(kWritableFormats.begin(), kWritableFormats.end(), format) ==
      kWritableFormats.end()) {
    throw InputError(UnknownKeyMessage("raytime.write_poses", format, kWritableFormats, "format"));
  }
  const std::vector<Rigid3> world_from_cam = PosesFromArray(poses, "poses");
  PoseSet pose_set;
  for (size_t i = 0; i < names.size(); ++i) {
    if (!pose_set.world_from_cam.emplace(names.at(i), world_from_cam.at(i)).second) {
      throw InputError("raytime.write_poses: '" + names[i] + "' is given twice");
    }
  }
  if (format == "tum") return WriteTumTrajectory(path, pose_set);
  if (cameras.size() != names.size()) {
    throw InputError("raytime.write_poses: format " + format +
                     " writes intrinsics: give cameras (one dict, or one per pose)");
  }
  const ImageSet images = ImagesOf(names, cameras, PixelConventionFromName(pixel_convention));
  if (format == "nerfstudio") return WriteTransformsJson(path, images, pose_set);
  const ColmapModel model = ToColmapModel(images, pose_set);
  if (format == "colmap_binary") return WriteColmapModelBinary(model, path);
  WriteColmapModelText(model, path);
}

}  // namespace

void BindPoseFiles(py::module_& m) {
  m.def("read_poses", &ReadPoses, py::arg("path"), py::arg("format"), py::arg("pose_set"),
        "(names, (N, 4, 4) camera-to-world poses) of a pose file (raytime.read_poses wraps it)");
  m.def("write_poses", &WritePoses, py::arg("path"), py::arg("names"), py::arg("poses"),
        py::arg("format"), py::arg("cameras"), py::arg("pixel_convention"),
        "Writes poses in a format of writable_formats (raytime.write_poses wraps it)");
  std::vector<std::string> readable = kPoseFileFormats;
  readable.push_back("hdf5");
  m.attr("readable_formats") = readable;
  m.attr("writable_formats") = kWritableFormats;
}

}  // namespace raytime::python
