// The extension module _raytime, wrapped by the package raytime (python/raytime/__init__.py).
#include <spdlog/sinks/stdout_color_sinks.h>
#include <spdlog/spdlog.h>

#include <exception>
#include <string>

#include "core/resource_failure.h"
#include "python/bindings.h"

namespace py = pybind11;

namespace raytime::python {
namespace {

// Raises `type` with `message` and the failure's class as its `cause` attribute (input, memory,
// threads, open_files, disk_space, error: summary.json's "cause").
void RaiseWithCause(const py::handle& type, const FailureDescription& failure) {
  py::object error = type(failure.message);
  error.attr("cause") = failure.cause;
  PyErr_SetObject(type.ptr(), error.ptr());
}

}  // namespace

void BindErrors(py::module_& m) {
  // Leaked on purpose: the translator below refers to them for the interpreter's lifetime.
  static py::handle error = py::exception<std::exception>(m, "Error", PyExc_RuntimeError).release();
  static py::handle input_error =
      py::exception<std::exception>(m, "InputError", error.ptr()).release();
  // The message is the CLI's (what `raytime run` prints after the log's prefix): DescribeFailure
  // classes the error as the CLI does for its exit status.
  py::register_exception_translator([](std::exception_ptr pointer) {
    try {
      if (pointer) std::rethrow_exception(pointer);
    } catch (const py::error_already_set&) {
      throw;
    } catch (const py::builtin_exception&) {
      throw;
    } catch (const std::exception& e) {
      const FailureDescription failure = DescribeFailure(e);
      RaiseWithCause(failure.cause == "input" ? input_error : error, failure);
    }
  });
}

}  // namespace raytime::python

PYBIND11_MODULE(_raytime, m) {
  m.doc() = "raytime's C++ library; use the package raytime, which wraps it";
  // Logs on stderr in the CLI's format, never on stdout (a script's own output).
  spdlog::set_default_logger(std::make_shared<spdlog::logger>(
      "raytime", std::make_shared<spdlog::sinks::stderr_color_sink_mt>()));
  spdlog::set_pattern("%H:%M:%S %^%l%$ %v");
  raytime::python::BindErrors(m);
  raytime::python::BindRun(m);
  raytime::python::BindRefine(m);
  raytime::python::BindPoseFiles(m);
}
