#include "tests/capture_fixtures.h"

#include <cmath>
#include <cstdint>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/videoio.hpp>
#include <stdexcept>
#include <utility>
#include <vector>

#include "core/types.h"
#include "formats/strecha.h"

namespace fs = std::filesystem;
using nlohmann::json;

namespace raytime::fixtures {

namespace {

// ARKit camera axes from OpenCV's: diag(1, -1, -1), written out here rather than taken from the
// library, so the fixtures follow the documented convention independently.
Eigen::Matrix3d Flip() { return Eigen::Vector3d(1, -1, -1).asDiagonal(); }

// ARKit's intrinsics measure the principal point from the image's corner: OpenCV's + 0.5.
Eigen::Matrix3d ArkitK(const Eigen::Matrix3d& K) {
  Eigen::Matrix3d arkit = K;
  arkit(0, 2) += 0.5;
  arkit(1, 2) += 0.5;
  return arkit;
}

Eigen::Matrix3d WorldFromArkit(const Rigid3& pose) {
  return pose.rotation.normalized().toRotationMatrix() * Flip();
}

void WriteText(const std::string& path, const std::string& text) {
  fs::create_directories(fs::path(path).parent_path());
  std::ofstream out(path);
  out << text;
  if (!out) throw std::runtime_error("cannot write " + path);
}

void Copy(const std::string& from, const std::string& to) {
  fs::create_directories(fs::path(to).parent_path());
  fs::copy_file(from, to, fs::copy_options::overwrite_existing);
}

std::string Number(double value) {
  char buffer[40];
  std::snprintf(buffer, sizeof(buffer), "%.17g", value);
  return buffer;
}

// The geodesic from a to b (rotation exp/log, centre linear).
Rigid3 Between(const Rigid3& a, const Rigid3& b, double fraction) {
  const Eigen::Matrix3d ra = a.RotationMatrix(), rb = b.RotationMatrix();
  const Eigen::AngleAxisd relative(ra.transpose() * rb);
  const Eigen::Matrix3d r =
      ra * Eigen::AngleAxisd(fraction * relative.angle(), relative.axis()).toRotationMatrix();
  return Rigid3(Eigen::Quaterniond(r), a.translation + fraction * (b.translation - a.translation));
}

std::string Microseconds(double time_s) {
  return std::to_string(static_cast<long long>(std::llround(time_s * 1e6)));
}

}  // namespace

Rigid3 Perturb(const Rigid3& world_from_cam, int index) {
  const Eigen::Vector3d axis =
      Eigen::Vector3d(std::sin(index + 1.0), std::cos(index + 1.0), 0.5).normalized();
  const double angle = 2.0 * M_PI / 180.0;
  Rigid3 out;
  out.rotation = Eigen::Quaterniond(world_from_cam.RotationMatrix() *
                                    Eigen::AngleAxisd(angle, axis).toRotationMatrix());
  out.translation = world_from_cam.translation +
                    0.05 * Eigen::Vector3d(std::cos(index), std::sin(index), 0.5).normalized();
  return out;
}

Capture SampleCapture() {
  const std::string root = std::string(RAYTIME_SOURCE_DIR) + "/data/sample/fountain-P11";
  ImageSet images;
  PoseSet ground_truth;
  ReadStrechaScene(root, &images, &ground_truth);
  Capture capture;
  capture.width = images.images.front().width;
  capture.height = images.images.front().height;
  for (size_t i = 0; i < images.images.size(); ++i) {
    const ImageInfo& image = images.images[i];
    const CameraIntrinsics& camera = images.cameras[image.camera_index];
    Frame frame;
    frame.image = (fs::path(images.image_root) / image.name).string();
    frame.world_from_cam = Perturb(ground_truth.world_from_cam.at(image.name), static_cast<int>(i));
    frame.K << camera.fx() + 0.25 * i, 0, camera.cx(), 0, camera.fy(), camera.cy() - 0.125 * i, 0,
        0, 1;
    frame.time_s = 100.0 + 0.1 * i;
    capture.frames.push_back(frame);
  }
  return capture;
}

void WriteRecord3d(const Capture& capture, const std::string& root, double scale) {
  json metadata;
  metadata["w"] = static_cast<int>(std::lround(capture.width * scale));
  metadata["h"] = static_cast<int>(std::lround(capture.height * scale));
  // ARKit's K of the metadata size, column-major: measured from the image corner, a rescale
  // multiplies it.
  const auto scaled = [&](const Eigen::Matrix3d& K) {
    const Eigen::Matrix3d arkit = ArkitK(K);
    return std::vector<double>{arkit(0, 0) * scale, arkit(1, 1) * scale, arkit(0, 2) * scale,
                               arkit(1, 2) * scale};
  };
  const std::vector<double> k0 = scaled(capture.frames.front().K);
  metadata["K"] = {k0[0], 0.0, 0.0, 0.0, k0[1], 0.0, k0[2], k0[3], 1.0};
  json poses = json::array(), coefficients = json::array(), times = json::array();
  for (size_t i = 0; i < capture.frames.size(); ++i) {
    const Frame& frame = capture.frames[i];
    Copy(frame.image, root + "/rgb/" + std::to_string(i) + ".jpg");
    const Eigen::Quaterniond q(WorldFromArkit(frame.world_from_cam));
    const Eigen::Vector3d& t = frame.world_from_cam.translation;
    poses.push_back({q.x(), q.y(), q.z(), q.w(), t.x(), t.y(), t.z()});
    coefficients.push_back(scaled(frame.K));
    times.push_back(frame.time_s);
  }
  metadata["poses"] = poses;
  metadata["perFrameIntrinsicCoeffs"] = coefficients;
  metadata["frameTimestamps"] = times;
  metadata["fps"] = 10;
  metadata["initPose"] = {0, 0, 0, 1, 0, 0, 0};
  WriteText(root + "/metadata.json", metadata.dump());
}

void WritePolycam(const Capture& capture, const std::string& root) {
  for (const bool corrected : {true, false}) {
    const std::string images =
        root + (corrected ? "/keyframes/corrected_images/" : "/keyframes/images/");
    const std::string cameras =
        root + (corrected ? "/keyframes/corrected_cameras/" : "/keyframes/cameras/");
    for (const Frame& frame : capture.frames) {
      const std::string stem = Microseconds(frame.time_s);
      Copy(frame.image, images + stem + ".jpg");
      const Eigen::Matrix3d rotation = WorldFromArkit(frame.world_from_cam);
      const Eigen::Vector3d centre =
          frame.world_from_cam.translation +
          (corrected ? Eigen::Vector3d::Zero() : Eigen::Vector3d(1, 0, 0));
      const Eigen::Matrix3d K = ArkitK(frame.K);
      json camera = {{"fx", K(0, 0)},          {"fy", K(1, 1)},
                     {"cx", K(0, 2)},          {"cy", K(1, 2)},
                     {"width", capture.width}, {"height", capture.height},
                     {"blur_score", 200.0},    {"timestamp", std::llround(frame.time_s * 1e6)}};
      for (int r = 0; r < 3; ++r) {
        for (int c = 0; c < 4; ++c) {
          camera["t_" + std::to_string(r) + std::to_string(c)] = c < 3 ? rotation(r, c) : centre[r];
        }
      }
      WriteText(cameras + stem + ".json", camera.dump(2));
    }
  }
}

std::string Scanner3dName(int index) {
  char name[32];
  std::snprintf(name, sizeof(name), "frame_%05d.jpg", 3 * index);
  return name;
}

void WriteScanner3d(const Capture& capture, const std::string& root) {
  const int n = static_cast<int>(capture.frames.size());
  for (int i = 0; i < n; ++i) {
    for (int sub = 0; sub < (i + 1 < n ? 3 : 1); ++sub) {
      const Frame& frame = capture.frames[i];
      const Rigid3 pose =
          sub == 0 ? frame.world_from_cam
                   : Between(frame.world_from_cam, capture.frames[i + 1].world_from_cam, sub / 3.0);
      Eigen::Matrix4d m = Eigen::Matrix4d::Identity();
      m.topLeftCorner<3, 3>() = WorldFromArkit(pose);
      m.topRightCorner<3, 1>() = pose.translation;
      json frame_json;
      frame_json["cameraPoseARFrame"] = json::array();
      for (int r = 0; r < 4; ++r) {
        for (int c = 0; c < 4; ++c) frame_json["cameraPoseARFrame"].push_back(m(r, c));
      }
      frame_json["intrinsics"] = json::array();
      for (int r = 0; r < 3; ++r) {
        for (int c = 0; c < 3; ++c) frame_json["intrinsics"].push_back(ArkitK(frame.K)(r, c));
      }
      frame_json["time"] = frame.time_s + sub * 0.1 / 3.0;
      frame_json["frame_index"] = 3 * i + sub;
      frame_json["motionQuality"] = 1.0;
      char stem[32];
      std::snprintf(stem, sizeof(stem), "frame_%05d", 3 * i + sub);
      WriteText(root + "/" + stem + ".json", frame_json.dump(2));
      if (sub == 0) Copy(frame.image, root + "/" + stem + ".jpg");
    }
  }
}

void WriteNerfCapture(const Capture& capture, const std::string& root) {
  json top = {{"w", capture.width},
              {"h", capture.height},
              {"fl_x", capture.frames.front().K(0, 0)},
              {"fl_y", capture.frames.front().K(1, 1)},
              {"cx", ArkitK(capture.frames.front().K)(0, 2)},
              {"cy", ArkitK(capture.frames.front().K)(1, 2)},
              {"depth_integer_scale", 1.0}};
  json frames = json::array();
  for (size_t i = 0; i < capture.frames.size(); ++i) {
    const Frame& frame = capture.frames[i];
    Copy(frame.image, root + "/images/" + std::to_string(i) + ".jpg");
    const Eigen::Matrix3d rotation = WorldFromArkit(frame.world_from_cam);
    json matrix = json::array();
    for (int r = 0; r < 3; ++r) {
      matrix.push_back(
          {rotation(r, 0), rotation(r, 1), rotation(r, 2), frame.world_from_cam.translation[r]});
    }
    matrix.push_back({0.0, 0.0, 0.0, 1.0});
    frames.push_back({{"file_path", "images/" + std::to_string(i)},
                      {"transform_matrix", matrix},
                      {"timestamp", frame.time_s},
                      {"fl_x", frame.K(0, 0)},
                      {"fl_y", frame.K(1, 1)},
                      {"cx", ArkitK(frame.K)(0, 2)},
                      {"cy", ArkitK(frame.K)(1, 2)},
                      {"w", capture.width},
                      {"h", capture.height}});
  }
  top["frames"] = frames;
  WriteText(root + "/transforms.json", top.dump(2));
}

std::string NerfstudioName(int index) {
  char name[32];
  std::snprintf(name, sizeof(name), "frame_%05d.jpg", index + 1);
  return name;
}

void WriteNerfstudio(const Capture& capture, const std::string& root,
                     const Rigid3& applied_from_world) {
  const Eigen::Matrix3d applied = applied_from_world.rotation.toRotationMatrix();
  json applied_transform = json::array();
  for (int r = 0; r < 3; ++r) {
    applied_transform.push_back(
        {applied(r, 0), applied(r, 1), applied(r, 2), applied_from_world.translation[r]});
  }
  json frames = json::array();
  for (size_t i = 0; i < capture.frames.size(); ++i) {
    const Frame& frame = capture.frames[i];
    const std::string name = NerfstudioName(static_cast<int>(i));
    const std::string stem = name.substr(0, name.size() - 4);
    Copy(frame.image, root + "/images/" + name);
    Copy(frame.image, root + "/images_2/" + name);
    WriteText(root + "/depths/" + stem + ".png", "depth " + stem);
    WriteText(root + "/masks/" + stem + ".png", "mask " + stem);
    const Eigen::Matrix3d rotation = applied * WorldFromArkit(frame.world_from_cam);
    const Eigen::Vector3d centre =
        applied * frame.world_from_cam.translation + applied_from_world.translation;
    json matrix = json::array();
    for (int r = 0; r < 3; ++r) {
      matrix.push_back({rotation(r, 0), rotation(r, 1), rotation(r, 2), centre[r]});
    }
    matrix.push_back({0.0, 0.0, 0.0, 1.0});
    frames.push_back({{"file_path", "images/" + name},
                      {"transform_matrix", matrix},
                      {"colmap_im_id", i + 1},
                      {"fl_x", frame.K(0, 0)},
                      {"fl_y", frame.K(1, 1)},
                      {"cx", ArkitK(frame.K)(0, 2)},
                      {"cy", ArkitK(frame.K)(1, 2)},
                      {"w", capture.width},
                      {"h", capture.height},
                      {"depth_file_path", "depths/" + stem + ".png"},
                      {"mask_path", "masks/" + stem + ".png"},
                      {"my_tag", "frame " + std::to_string(i)}});
  }
  WriteText(root + "/sparse_pc.ply", "ply\nformat ascii 1.0\nelement vertex 0\nend_header\n");
  const json top = {{"camera_model", "OPENCV"},
                    {"frames", frames},
                    {"applied_transform", applied_transform},
                    {"ply_file_path", "sparse_pc.ply"},
                    {"my_note", "written by capture_fixtures"}};
  WriteText(root + "/transforms.json", top.dump(4));
}

// A ZIP archive of stored (uncompressed) entries, as np.savez writes .npz files.
std::string Crc32Zip(const std::vector<std::pair<std::string, std::string>>& entries) {
  const auto crc32 = [](const std::string& data) {
    uint32_t crc = 0xFFFFFFFFu;
    for (unsigned char byte : data) {
      crc ^= byte;
      for (int k = 0; k < 8; ++k) crc = (crc >> 1) ^ (0xEDB88320u & (0u - (crc & 1u)));
    }
    return ~crc;
  };
  const auto le = [](uint32_t value, int n) {
    std::string out;
    for (int i = 0; i < n; ++i) out += static_cast<char>((value >> (8 * i)) & 0xFF);
    return out;
  };
  std::string zip, directory;
  for (const auto& [name, data] : entries) {
    const uint32_t offset = static_cast<uint32_t>(zip.size());
    const uint32_t crc = crc32(data), size = static_cast<uint32_t>(data.size());
    zip += le(0x04034b50, 4) + le(20, 2) + le(0, 2) + le(0, 2) + le(0, 2) + le(0, 2) + le(crc, 4) +
           le(size, 4) + le(size, 4) + le(static_cast<uint32_t>(name.size()), 2) + le(0, 2) + name +
           data;
    directory += le(0x02014b50, 4) + le(20, 2) + le(20, 2) + le(0, 2) + le(0, 2) + le(0, 2) +
                 le(0, 2) + le(crc, 4) + le(size, 4) + le(size, 4) +
                 le(static_cast<uint32_t>(name.size()), 2) + le(0, 2) + le(0, 2) + le(0, 2) +
                 le(0, 2) + le(0, 4) + le(offset, 4) + name;
  }
  const uint32_t directory_offset = static_cast<uint32_t>(zip.size());
  zip += directory + le(0x06054b50, 4) + le(0, 2) + le(0, 2) +
         le(static_cast<uint32_t>(entries.size()), 2) +
         le(static_cast<uint32_t>(entries.size()), 2) +
         le(static_cast<uint32_t>(directory.size()), 4) + le(directory_offset, 4) + le(0, 2);
  return zip;
}

// A 4x4 float64 array in .npy format 1.0 (C order).
std::string Npy4x4(const Eigen::Matrix4d& m) {
  std::string header = "{'descr': '<f8', 'fortran_order': False, 'shape': (4, 4), }";
  while ((10 + header.size() + 1) % 64 != 0) header += ' ';
  header += '\n';
  std::string out = std::string("\x93NUMPY\x01\x00", 8);
  out += static_cast<char>(header.size() & 0xFF);
  out += static_cast<char>(header.size() >> 8);
  out += header;
  for (int r = 0; r < 4; ++r) {
    for (int c = 0; c < 4; ++c) {
      const double value = m(r, c);
      out.append(reinterpret_cast<const char*>(&value), 8);
    }
  }
  return out;
}

void WriteMobileBrick(const Capture& capture, const std::string& root,
                      const Rigid3* arkit_from_world) {
  std::vector<std::pair<std::string, std::string>> npz;
  for (size_t i = 0; i < capture.frames.size(); ++i) {
    const Frame& frame = capture.frames[i];
    char stem[32];
    std::snprintf(stem, sizeof(stem), "%06zu", i);
    Copy(frame.image, root + "/image/" + stem + ".jpg");
    std::string k, pose;
    for (int r = 0; r < 3; ++r) {
      k += Number(frame.K(r, 0)) + " " + Number(frame.K(r, 1)) + " " + Number(frame.K(r, 2)) + "\n";
    }
    const Eigen::Matrix3d rotation = frame.world_from_cam.RotationMatrix();
    for (int r = 0; r < 3; ++r) {
      pose += Number(rotation(r, 0)) + " " + Number(rotation(r, 1)) + " " + Number(rotation(r, 2)) +
              " " + Number(frame.world_from_cam.translation[r]) + "\n";
    }
    pose += "0 0 0 1\n";
    WriteText(root + "/intrinsic/" + stem + ".txt", k);
    WriteText(root + "/pose/" + stem + ".txt", pose);
    if (arkit_from_world) {
      const Rigid3 arkit = *arkit_from_world * frame.world_from_cam;
      Eigen::Matrix4d world_from_cam = Eigen::Matrix4d::Identity();
      world_from_cam.topLeftCorner<3, 3>() = arkit.RotationMatrix();
      world_from_cam.topRightCorner<3, 1>() = arkit.translation;
      Eigen::Matrix4d K4 = Eigen::Matrix4d::Identity();
      K4.topLeftCorner<3, 3>() = frame.K;
      npz.push_back({"scale_mat_" + std::to_string(i) + ".npy",
                     Npy4x4(Eigen::Vector4d(2, 2, 2, 1).asDiagonal())});
      npz.push_back(
          {"world_mat_" + std::to_string(i) + ".npy", Npy4x4(K4 * world_from_cam.inverse())});
    }
  }
  if (arkit_from_world) {
    std::ofstream(root + "/cameras_arkit.npz", std::ios::binary) << Crc32Zip(npz);
  }
}

void WriteScanNetPP(const Capture& capture, const std::string& root, const Rigid3& arkit_from_world,
                    bool arkit_axes) {
  const auto matrix = [](const Eigen::Matrix3d& rotation, const Eigen::Vector3d& centre) {
    json rows = json::array();
    for (int r = 0; r < 3; ++r) {
      rows.push_back({rotation(r, 0), rotation(r, 1), rotation(r, 2), centre[r]});
    }
    rows.push_back({0.0, 0.0, 0.0, 1.0});
    return rows;
  };
  json top = json::object();
  for (size_t i = 0; i < capture.frames.size(); ++i) {
    const Frame& frame = capture.frames[i];
    char key[32];
    std::snprintf(key, sizeof(key), "frame_%06zu", i);
    Copy(frame.image, root + "/iphone/rgb/" + key + ".jpg");
    const Rigid3 arkit = arkit_from_world * frame.world_from_cam;
    json intrinsic = json::array();
    const Eigen::Matrix3d K = ArkitK(frame.K);
    for (int r = 0; r < 3; ++r) intrinsic.push_back({K(r, 0), K(r, 1), K(r, 2)});
    top[key] = {{"timestamp", frame.time_s},
                {"intrinsic", intrinsic},
                {"pose", matrix(arkit.RotationMatrix() *
                                    (arkit_axes ? Flip() : Eigen::Matrix3d::Identity()),
                                arkit.translation)},
                {"aligned_pose",
                 matrix(frame.world_from_cam.RotationMatrix(), frame.world_from_cam.translation)},
                {"imu", {{"gravity", {0.0, -9.81, 0.0}}}}};
  }
  // A frame whose video frame was not extracted: not a frame of the dataset.
  top["frame_009999"] = top["frame_000000"];
  WriteText(root + "/iphone/pose_intrinsic_imu.json", top.dump());
}

std::string ArkitScenesName(const std::string& video, double time_s) {
  char name[64];
  std::snprintf(name, sizeof(name), "%s_%.3f", video.c_str(), time_s);
  return name;
}

void WriteArkitScenes(const Capture& capture, const std::string& root, const std::string& video) {
  std::string traj;
  const auto row = [&](double time_s, const Rigid3& world_from_cam) {
    const Rigid3 cam_from_world = world_from_cam.Inverse();
    const Eigen::AngleAxisd axis_angle(cam_from_world.rotation.normalized());
    const Eigen::Vector3d w = axis_angle.angle() * axis_angle.axis();
    traj += Number(time_s) + " " + Number(w.x()) + " " + Number(w.y()) + " " + Number(w.z()) + " " +
            Number(cam_from_world.translation.x()) + " " + Number(cam_from_world.translation.y()) +
            " " + Number(cam_from_world.translation.z()) + "\n";
  };
  for (size_t i = 0; i < capture.frames.size(); ++i) {
    const Frame& frame = capture.frames[i];
    const std::string name = ArkitScenesName(video, frame.time_s);
    Copy(frame.image, root + "/lowres_wide/" + name + ".png");
    WriteText(root + "/lowres_wide_intrinsics/" + name + ".pincam",
              std::to_string(capture.width) + " " + std::to_string(capture.height) + " " +
                  Number(frame.K(0, 0)) + " " + Number(frame.K(1, 1)) + " " +
                  Number(frame.K(0, 2)) + " " + Number(frame.K(1, 2)) + "\n");
    row(frame.time_s, frame.world_from_cam);
    if (i + 1 < capture.frames.size()) {
      row(0.5 * (frame.time_s + capture.frames[i + 1].time_s),
          Between(frame.world_from_cam, capture.frames[i + 1].world_from_cam, 0.5));
    }
  }
  WriteText(root + "/lowres_wide.traj", traj);
}

std::string LamarName(double time_s) { return "cam0/" + Microseconds(time_s) + ".jpg"; }

void WriteLamar(const Capture& capture, const std::string& root, const Rigid3& arkit_from_world,
                const Rigid3& rig_from_cam) {
  const auto pose = [](const Rigid3& p) {
    const Eigen::Quaterniond q = p.rotation.normalized();
    return Number(q.w()) + ", " + Number(q.x()) + ", " + Number(q.y()) + ", " + Number(q.z()) +
           ", " + Number(p.translation.x()) + ", " + Number(p.translation.y()) + ", " +
           Number(p.translation.z());
  };
  const Eigen::Matrix3d& K = capture.frames.front().K;
  WriteText(root + "/sensors.txt",
            "# sensor_id, name, sensor_type, [sensor_params]+\n"
            "cam0, phone camera, camera, PINHOLE, " +
                std::to_string(capture.width) + ", " + std::to_string(capture.height) + ", " +
                Number(K(0, 0)) + ", " + Number(K(1, 1)) + ", " + Number(K(0, 2) + 0.5) + ", " +
                Number(K(1, 2) + 0.5) + "\n");
  WriteText(root + "/rigs.txt", "# rig_id, sensor_id, qw, qx, qy, qz, tx, ty, tz\nrig0, cam0, " +
                                    pose(rig_from_cam) + "\n");
  std::string images = "# timestamp, sensor_id, image_path\n";
  std::string trajectories = "# timestamp, device_id, qw, qx, qy, qz, tx, ty, tz\n";
  std::string aligned = trajectories;
  for (const Frame& frame : capture.frames) {
    const std::string us = Microseconds(frame.time_s);
    Copy(frame.image, root + "/raw_data/" + LamarName(frame.time_s));
    images += us + ", cam0, " + LamarName(frame.time_s) + "\n";
    trajectories += us + ", rig0, " +
                    pose(arkit_from_world * frame.world_from_cam * rig_from_cam.Inverse()) + "\n";
    aligned += us + ", cam0, " + pose(frame.world_from_cam) + "\n";
  }
  images += "999000000, cam0, cam0/999000000.jpg\n";  // no pose within reach: not a frame
  WriteText(root + "/images.txt", images);
  WriteText(root + "/trajectories.txt", trajectories);
  WriteText(root + "/proc/alignment_trajectories.txt", aligned);
}

bool WriteStray(const Capture& capture, const std::string& root, double fps, double odometry_hz,
                double capture_scale, std::vector<OdometryRow>* rows, const std::string& fourcc) {
  if (fourcc.size() != 4) throw std::invalid_argument("fourcc '" + fourcc + "': 4 characters");
  fs::create_directories(root);
  {
    cv::VideoWriter writer(root + "/rgb.mp4",
                           cv::VideoWriter::fourcc(fourcc[0], fourcc[1], fourcc[2], fourcc[3]), fps,
                           cv::Size(capture.width, capture.height));
    if (!writer.isOpened()) return false;
    for (const Frame& frame : capture.frames) {
      const cv::Mat image = cv::imread(frame.image);
      // VideoWriter drops frames of another size without a word.
      if (image.cols != capture.width || image.rows != capture.height) {
        throw std::runtime_error(frame.image + ": not " + std::to_string(capture.width) + "x" +
                                 std::to_string(capture.height));
      }
      writer.write(image);
    }
  }
  const Eigen::Matrix3d K = ArkitK(capture.frames.front().K);  // ARKit's: scales as is
  const double s = capture_scale;
  WriteText(root + "/camera_matrix.csv", Number(K(0, 0) * s) + ", 0.0, " + Number(K(0, 2) * s) +
                                             "\n0.0, " + Number(K(1, 1) * s) + ", " +
                                             Number(K(1, 2) * s) + "\n0.0, 0.0, 1.0\n");
  const double start = capture.frames.front().time_s;
  const double duration = (capture.frames.size() - 1) / fps;
  std::string odometry = "timestamp, frame, x, y, z, qx, qy, qz, qw\n";
  rows->clear();
  for (int j = 0; j / odometry_hz <= duration + 1e-9; ++j) {
    const double tau = j / odometry_hz;  // on the video's clock
    const int a = std::min(static_cast<int>(std::floor(tau * fps + 1e-9)),
                           static_cast<int>(capture.frames.size()) - 2);
    const double fraction = std::max(0.0, tau * fps - a);
    const Rigid3 pose =
        Between(capture.frames[a].world_from_cam, capture.frames[a + 1].world_from_cam, fraction);
    const int nearest = static_cast<int>(std::lround(tau * fps));
    rows->push_back({start + tau, nearest, pose});
    const Eigen::Quaterniond q = pose.rotation.normalized();
    odometry += Number(start + tau) + ", " + std::to_string(nearest) + ", " +
                Number(pose.translation.x()) + ", " + Number(pose.translation.y()) + ", " +
                Number(pose.translation.z()) + ", " + Number(q.x()) + ", " + Number(q.y()) + ", " +
                Number(q.z()) + ", " + Number(q.w()) + "\n";
  }
  WriteText(root + "/odometry.csv", odometry);
  return true;
}

}  // namespace raytime::fixtures
