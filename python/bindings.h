// The pieces of the extension module _raytime (python/README.md), each binding one job: run a
// pipeline, refine arrays, read and write pose files.
#pragma once

#include <pybind11/pybind11.h>
// The STL conversions in every source of the module: a source without them binds
// std::vector<std::string> as an opaque type, which a unity build hid (pybind11 asks for one
// choice per type across the module).
#include <pybind11/stl.h>

#include <functional>

namespace raytime::python {

// raytime.Error and raytime.InputError, and the translation of raytime's C++ errors into them
// (module.cc).
void BindErrors(pybind11::module_& m);

// Runs `work` on a worker thread without the GIL while the calling thread runs Python's signal
// handlers. When one raises (KeyboardInterrupt), the work is stopped as the CLI stops it on SIGINT
// (core/interrupt.h RequestStop: the registered actions, then the work's next StopPoint) and that
// exception is raised once the worker has ended; otherwise the work's own exception is (run.cc).
void RunStoppable(const std::function<void()>& work);

// _raytime.run (run.cc).
void BindRun(pybind11::module_& m);

// _raytime.refine (refine_arrays.cc).
void BindRefine(pybind11::module_& m);

// _raytime.read_poses, _raytime.write_poses, _raytime.pose_file_formats (pose_files.cc).
void BindPoseFiles(pybind11::module_& m);

}  // namespace raytime::python
