// procam's Python module: `import procam` (docs/python.md). The native part, procam._procam; the
// package's __init__.py re-exports it.
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl/filesystem.h>

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <stdexcept>

#include "base/image_io.h"
#include "base/io.h"
#include "datasets_synthetic/synthetic_camera.h"
#include "python/bindings.h"

namespace py = pybind11;

namespace procam::python {

ProgressCallback PythonProgress(const py::object& callback) {
  if (callback.is_none()) return {};
  // The callable outlives the call that took it only inside the returned function, which holds
  // a reference; it is released with the GIL held.
  auto held = std::shared_ptr<py::object>(new py::object(callback), [](py::object* object) {
    py::gil_scoped_acquire gil;
    delete object;
  });
  return [held](const std::string& line) {
    py::gil_scoped_acquire gil;
    (*held)(line);
  };
}

py::array MatArray(const cv::Mat& mat) {
  py::dtype dtype;
  switch (mat.depth()) {
    case CV_8U: dtype = py::dtype::of<uint8_t>(); break;
    case CV_16U: dtype = py::dtype::of<uint16_t>(); break;
    case CV_32F: dtype = py::dtype::of<float>(); break;
    case CV_64F: dtype = py::dtype::of<double>(); break;
    default: throw std::runtime_error("internal: an image of an unsupported depth");
  }
  auto* held = new cv::Mat(mat);
  py::capsule owner(held, [](void* p) { delete static_cast<cv::Mat*>(p); });
  const ssize_t element = static_cast<ssize_t>(mat.elemSize1());
  std::vector<ssize_t> shape{mat.rows, mat.cols}, strides{static_cast<ssize_t>(mat.step[0]),
                                                          static_cast<ssize_t>(mat.elemSize())};
  if (mat.channels() > 1) {
    shape.push_back(mat.channels());
    strides.push_back(element);
  }
  return py::array(dtype, shape, strides, held->data, owner);
}

}  // namespace procam::python

PYBIND11_MODULE(_procam, m) {
  m.doc() =
      "procam: projector-camera compensation of interreflections (Sheng et al. 2011).\n\n"
      "Scenes, patches and form factors; the compensation problem and its solvers; "
      "structured-light decoding. Arrays are NumPy arrays in and out; docs/python.md.";
  // procam's errors: IoError (a file, key or argument named in one line) is procam.IoError, a
  // subclass of OSError; std::invalid_argument is ValueError, other std::runtime_errors
  // RuntimeError (pybind11's own translation).
  py::register_exception<procam::IoError>(m, "IoError", PyExc_OSError);
  // The synthetic world's scenes by name (synthetic:c_shaped, ...), as the command line has them.
  procam::RegisterSyntheticWorld();
  m.def(
      "read_image",
      [](const std::filesystem::path& path) {
        cv::Mat image = procam::ReadImage(path, cv::IMREAD_UNCHANGED);
        if (image.channels() == 4) cv::cvtColor(image, image, cv::COLOR_BGRA2RGB);
        else if (image.channels() == 3) cv::cvtColor(image, image, cv::COLOR_BGR2RGB);
        return procam::python::MatArray(image);
      },
      py::arg("path"),
      "Reads a PNG, JPEG, TIFF, BMP or Netpbm image as it is stored: (H,W) or (H,W,3) in R,G,B "
      "order, uint8 or uint16 (alpha dropped). Raises procam.IoError naming the file.");
  procam::python::BindGeometry(m);
  procam::python::BindCompensation(m);
  procam::python::BindCalibration(m);
  procam::python::BindRoom(m);
}
