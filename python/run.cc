// _raytime.run: a pipeline run in this process as `raytime run` runs it (cli/main.cc), except
// that Ctrl-C does not end the interpreter. The CLI's watcher thread takes SIGINT, runs the
// registered actions (summary.json "interrupted", children stopped, temporaries removed) and
// exits; here Python keeps its own SIGINT handler, the calling thread polls it while a worker
// thread runs the pipeline without the GIL, and on KeyboardInterrupt the same actions run through
// RequestStop, the worker stops at its next StopPoint (core/interrupt.h) and the exception is
// raised once it has.
#include <signal.h>

#include <chrono>
#include <future>
#include <string>
#include <thread>
#include <vector>

#include "core/atomic_file.h"
#include "core/error.h"
#include "core/interrupt.h"
#include "core/user_paths.h"
#include "pipelines/pipeline.h"
#include "python/bindings.h"

namespace py = pybind11;

namespace raytime::python {
namespace {

// How often the calling thread looks for Python's pending signals while the pipeline runs.
constexpr std::chrono::milliseconds kSignalPoll{100};

// The pipeline file with the overrides applied, as RunCommand::Spec in cli/main.cc.
PipelineSpec SpecOf(const std::string& pipeline, const std::vector<std::string>& overrides) {
  PipelineSpec spec = LoadPipeline(ExpandUser(pipeline));
  for (const std::string& assignment : overrides) ApplyOverride(&spec, assignment);
  // A sweep's runs are processes of this executable (/proc/self/exe): the interpreter here.
  if (!spec.sweep.empty()) {
    throw InputError(spec.path +
                     ": a pipeline with a sweep runs each combination as a process of the "
                     "raytime command; run it with `raytime run`");
  }
  return spec;
}

}  // namespace

void RunStoppable(const std::function<void()>& work) {
  ClearStopRequest();
  std::packaged_task<void()> task(work);
  std::future<void> result = task.get_future();
  PyObject* type = nullptr;
  PyObject* value = nullptr;
  PyObject* trace = nullptr;
  {
    py::gil_scoped_release release;
    std::thread worker(std::move(task));
    while (result.wait_for(kSignalPoll) != std::future_status::ready) {
      bool signalled = false;
      {
        py::gil_scoped_acquire acquire;
        if (PyErr_CheckSignals() != 0) {
          PyErr_Fetch(&type, &value, &trace);
          signalled = true;
        }
      }
      if (signalled) {
        RequestStop(SIGINT);
        result.wait();
        break;
      }
    }
    worker.join();
  }
  if (type != nullptr) {
    // What the worker wrote after the actions ran (a file it was writing when it stopped).
    RemovePendingTemporaryFiles();
    ClearStopRequest();
    PyErr_Restore(type, value, trace);
    throw py::error_already_set();
  }
  try {
    result.get();
  } catch (const StopRequested&) {
    // Only RequestStop throws it, and only the poll above requests it.
    throw std::logic_error("raytime: the work stopped without an interruption");
  }
}

namespace {

std::string Run(const std::string& pipeline, const std::string& workdir,
                const std::vector<std::string>& overrides, const std::string& cache_dir,
                bool force) {
  if (workdir.empty()) {
    throw InputError("raytime.run: workdir is empty; give a directory");
  }
  const PipelineSpec spec = SpecOf(pipeline, overrides);
  RunOptions options;
  options.workdir = ExpandUser(workdir);
  options.cache_dir = cache_dir.empty() ? "" : ExpandUser(cache_dir);
  options.force = force;
  std::string summary;
  RunStoppable([&] { summary = RunPipeline(spec, options).dump(); });
  return summary;
}

}  // namespace

void BindRun(py::module_& m) {
  m.def("run", &Run, py::arg("pipeline"), py::arg("workdir"), py::arg("overrides"),
        py::arg("cache_dir"), py::arg("force"),
        "Runs a pipeline file in workdir with STAGE.KEY=VALUE overrides; returns summary.json's "
        "text (raytime.run wraps it)");
}

}  // namespace raytime::python
