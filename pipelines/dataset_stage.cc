// The `dataset` stage: reads images, intrinsics and ground truth (when the dataset has it) into
// the work directory, so every later stage reads one HDF5 file instead of the user's layout.
#include <spdlog/spdlog.h>

#include "core/formats/dataset.h"
#include "core/hdf5_store.h"
#include "pipelines/stages.h"

namespace raytime {
namespace {

class DatasetStage : public StageWithOptions<DatasetOptions> {
 public:
  std::string type() const override { return "dataset"; }
  std::string description() const override {
    return "Read a dataset (images, intrinsics, ground truth) into the work directory";
  }
  std::vector<std::string> Inputs() const override { return {}; }
  std::vector<std::string> ExternalFiles() const override { return LoadDataset(options_).files; }

  nlohmann::json Run(const StageContext& context) override {
    const Dataset dataset = LoadDataset(options_);
    spdlog::info("dataset: {} images, {} camera(s), ground truth: {}", dataset.images.images.size(),
                 dataset.images.cameras.size(), dataset.ground_truth ? "yes" : "no");
    Hdf5Writer writer(context.output_path);
    writer.WriteImages(dataset.images);
    if (dataset.ground_truth) {
      writer.WritePoseSet("ground_truth", *dataset.ground_truth, PoseRole::kGroundTruth,
                          MakeProvenance(*this));
    }
    writer.Commit();
    return {{"num_images", dataset.images.images.size()},
            {"num_cameras", dataset.images.cameras.size()},
            {"has_ground_truth", dataset.ground_truth.has_value()},
            {"warnings", WarningsToJson(dataset.warnings)}};
  }
};

}  // namespace

std::unique_ptr<Stage> CreateDatasetStage() { return std::make_unique<DatasetStage>(); }

}  // namespace raytime
