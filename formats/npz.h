// NumPy .npz archives (a ZIP of .npy arrays), as np.savez writes them: enough to read the camera
// files of NeuS/IDR-style datasets (PoRF's cameras_arkit.npz). Entries must be stored without
// compression (np.savez; np.savez_compressed is refused with a message); arrays of float32 or
// float64, little-endian, C or Fortran order.
#pragma once

#include <Eigen/Core>
#include <map>
#include <string>

namespace raytime {

// Every array of the archive by name (the entry name without ".npy"), as a matrix (1-D arrays
// become one column). InputError naming the file and the entry on anything else.
std::map<std::string, Eigen::MatrixXd> ReadNpz(const std::string& path);

}  // namespace raytime
