#pragma once
// Shared by the Python module's binding files (python/bind_*.cc): each adds its part of procam
// to the module `m`.

#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>

#include <opencv2/core/mat.hpp>
#include <string>

#include "base/progress.h"

namespace procam::python {

void BindGeometry(pybind11::module_& m);
void BindCompensation(pybind11::module_& m);
void BindCalibration(pybind11::module_& m);
void BindRoom(pybind11::module_& m);

// A ProgressCallback that calls the Python callable `callback` (None: no callback) with each line,
// holding the GIL while it runs (the long calls that take it release the GIL).
ProgressCallback PythonProgress(const pybind11::object& callback);

// A NumPy view of `mat` (no copy): (H,W) or (H,W,C) of uint8, uint16, float32 or float64; the
// array holds a reference-counted cv::Mat header that keeps the pixels alive.
pybind11::array MatArray(const cv::Mat& mat);

}  // namespace procam::python
