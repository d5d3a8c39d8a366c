// procam's structured light and camera calibration from Python: patterns out, photos in,
// projector coordinates and masks out; chessboard corners and a calibrated lens.
#include <pybind11/eigen.h>
#include <pybind11/numpy.h>
#include <pybind11/stl.h>
#include <pybind11/stl/filesystem.h>

#include <stdexcept>

#include "calibration/board_projector.h"
#include "calibration/camera_calibration.h"
#include "calibration/capture_layout.h"
#include "calibration/structured_light.h"
#include "python/bindings.h"

namespace py = pybind11;

namespace procam::python {
namespace {

// A cv::Mat of a 2-D (H,W) or 3-D (H,W,C) array of uint8, uint16, float32 or float64: a header
// over its memory when it is C-contiguous (no copy), else a copy; `what` names the argument.
cv::Mat ArrayMat(const py::array& given, const std::string& what) {
  if (given.ndim() != 2 && given.ndim() != 3) {
    throw std::invalid_argument(what + ": an (H,W) or (H,W,C) array, got " + std::to_string(given.ndim()) + " dimensions");
  }
  const bool contiguous = given.flags() & py::array::c_style;
  const py::array array = contiguous ? given : py::module_::import("numpy").attr("ascontiguousarray")(given).cast<py::array>();
  const int channels = array.ndim() == 3 ? static_cast<int>(array.shape(2)) : 1;
  if (channels != 1 && channels != 3) throw std::invalid_argument(what + ": 1 or 3 channels, got " + std::to_string(channels));
  int depth;
  if (array.dtype().is(py::dtype::of<uint8_t>())) depth = CV_8U;
  else if (array.dtype().is(py::dtype::of<uint16_t>())) depth = CV_16U;
  else if (array.dtype().is(py::dtype::of<float>())) depth = CV_32F;
  else if (array.dtype().is(py::dtype::of<double>())) depth = CV_64F;
  else throw std::invalid_argument(what + ": dtype uint8, uint16, float32 or float64, got " + py::str(array.dtype()).cast<std::string>());
  const cv::Mat header(static_cast<int>(array.shape(0)), static_cast<int>(array.shape(1)), CV_MAKETYPE(depth, channels),
                       const_cast<void*>(array.data()));
  return contiguous ? header : header.clone();
}

// The photos of a capture: a sequence of images, or one (N,H,W) or (N,H,W,C) array; read in
// place (no copy) where C-contiguous. The caller's objects keep the pixels alive.
std::vector<cv::Mat> Photos(const py::object& photos) {
  std::vector<cv::Mat> images;
  if (py::isinstance<py::array>(photos)) {
    const py::array stack = photos.cast<py::array>();
    if (stack.ndim() != 3 && stack.ndim() != 4) {
      throw std::invalid_argument("photos: a list of images or an (N,H,W[,C]) array, got " +
                                  std::to_string(stack.ndim()) + " dimensions");
    }
    for (ssize_t k = 0; k < stack.shape(0); ++k) {
      images.push_back(ArrayMat(stack[py::int_(k)].cast<py::array>(), "photos[" + std::to_string(k) + "]"));
    }
    return images;
  }
  int k = 0;
  for (const py::handle& item : photos) {
    images.push_back(ArrayMat(py::reinterpret_borrow<py::object>(item).cast<py::array>(),
                              "photos[" + std::to_string(k++) + "]"));
  }
  return images;
}

StructuredLightLayout LayoutArgument(const py::object& layout) {
  if (py::isinstance<StructuredLightOptions>(layout)) return LayoutOf(layout.cast<StructuredLightOptions>());
  if (py::isinstance<CaptureLayout>(layout)) return layout.cast<CaptureLayout>().Decodable();
  if (py::isinstance<StructuredLightLayout>(layout)) return layout.cast<StructuredLightLayout>();
  throw std::invalid_argument("layout: a StructuredLightOptions, a CaptureLayout (read_capture_layout) or a StructuredLightLayout");
}

}  // namespace

void BindBoardProjector(py::module_& m);

void BindCalibration(py::module_& m) {
  py::class_<StructuredLightOptions>(m, "StructuredLightOptions",
                                     "procam's own structured-light sequence: Gray codes and phase shifts "
                                     "(calibration/structured_light.h).")
      .def(py::init<>())
      .def(py::init([](int width, int height) {
             StructuredLightOptions options;
             options.width = width;
             options.height = height;
             return options;
           }),
           py::arg("width"), py::arg("height"))
      .def_readwrite("width", &StructuredLightOptions::width, "projector pixels, [4, 16384]")
      .def_readwrite("height", &StructuredLightOptions::height, "projector pixels, [4, 16384]")
      .def_readwrite("columns", &StructuredLightOptions::columns, "encode the column u")
      .def_readwrite("rows", &StructuredLightOptions::rows, "encode the row v")
      .def_readwrite("phase_period", &StructuredLightOptions::phase_period, "projector pixels per sinusoid period")
      .def_readwrite("phase_steps", &StructuredLightOptions::phase_steps, "sinusoids per axis, [3, 64]")
      .def_readwrite("xor_codes", &StructuredLightOptions::xor_codes, "XOR Gray codes (Gupta et al. 2011)")
      .def("check", [](const StructuredLightOptions& o) {
        std::string why;
        if (!o.Check(&why)) throw std::invalid_argument("StructuredLightOptions: " + why);
      });

  py::class_<StructuredLightLayout>(m, "StructuredLightLayout", "What each photo of a capture shows, for the decoder.")
      .def_readonly("width", &StructuredLightLayout::width)
      .def_readonly("height", &StructuredLightLayout::height)
      .def_readonly("image_count", &StructuredLightLayout::image_count);
  m.def("layout_of", &LayoutOf, py::arg("options"), "procam's own sequence of `options` as a layout.");

  py::class_<CaptureLayout>(m, "CaptureLayout", "A layout file's contents (docs/capture_layout.md).")
      .def_readonly("width", &CaptureLayout::width)
      .def_readonly("height", &CaptureLayout::height)
      .def_readonly("projector_name", &CaptureLayout::projector_name)
      .def("decodable", [](const CaptureLayout& layout) { return layout.Decodable(); },
           "The decoder's view; raises procam.IoError naming the key when it cannot be decoded.");
  m.def("read_capture_layout", &ReadCaptureLayout, py::arg("path"),
        "Reads a layout file (docs/capture_layout.md); raises procam.IoError 'FILE: key: what'.");

  m.def(
      "structured_light_patterns",
      [](const StructuredLightOptions& options) {
        py::list images;
        for (const Pattern& pattern : MakeStructuredLightSequence(options).patterns) images.append(MatArray(pattern.image));
        return images;
      },
      py::arg("options"),
      "procam's patterns for `options`, in the order the decoder expects: a list of (height,width,3) "
      "uint8 images.");

  py::class_<StructuredLightMap>(m, "StructuredLightMap", "Per camera pixel, what it sees of the projector.")
      .def_property_readonly("column", [](const StructuredLightMap& map) { return MatArray(map.column); },
                             "(H,W) float32 projector column (pixel centres at integers), NaN where not decoded (no copy)")
      .def_property_readonly("row", [](const StructuredLightMap& map) { return MatArray(map.row); },
                             "(H,W) float32 projector row, NaN where not decoded (no copy)")
      .def_property_readonly("mask", [](const StructuredLightMap& map) { return MatArray(map.mask); },
                             "(H,W) uint8, 255 where every encoded axis decoded (no copy)")
      .def_property_readonly("refused", [](const StructuredLightMap& map) { return MatArray(map.refused); },
                             "(H,W) uint8 reason per pixel: 0 decoded, 1 shadowed, 2 ambiguous, 3 weak phase, "
                             "4 out of range, 5 unwrap (no copy)")
      .def_readonly("noise_sigma", &StructuredLightMap::noise_sigma, "the photos' noise, one sigma, in their units")
      .def_readonly("shadowed", &StructuredLightMap::shadowed)
      .def_readonly("ambiguous", &StructuredLightMap::ambiguous)
      .def_readonly("weak_phase", &StructuredLightMap::weak_phase)
      .def_readonly("out_of_range", &StructuredLightMap::out_of_range)
      .def_readonly("unwrap", &StructuredLightMap::unwrap);

  m.def(
      "decode_structured_light",
      [](const py::object& photos, const py::object& layout, double noise_sigmas) {
        const StructuredLightLayout decodable = LayoutArgument(layout);
        const std::vector<cv::Mat> images = Photos(photos);
        StructuredLightDecodeOptions options;
        options.noise_sigmas = noise_sigmas;
        py::gil_scoped_release release;
        return DecodeStructuredLight(decodable, images, options);
      },
      py::arg("photos"), py::arg("layout"), py::arg("noise_sigmas") = StructuredLightDecodeOptions().noise_sigmas,
      "Decodes a structured-light capture. `photos`: a list of (H,W) or (H,W,3) arrays (uint8, uint16, "
      "float32 or float64; read in place when C-contiguous, else copied) or one (N,H,W[,3]) array, in the "
      "layout's order, linear in light. `layout`: StructuredLightOptions (procam's own patterns), a "
      "CaptureLayout (read_capture_layout) or a StructuredLightLayout. Returns a StructuredLightMap. "
      "Raises ValueError when the count or sizes do not match. Releases the GIL while it decodes.");

  py::class_<ChessboardSpec>(m, "Chessboard", "A planar chessboard: inner corners and square size.")
      .def(py::init([](int corners_x, int corners_y, double square_size) {
             ChessboardSpec board;
             board.corners_x = corners_x;
             board.corners_y = corners_y;
             board.square_size = square_size;
             std::string why;
             if (!board.Check(&why)) throw std::invalid_argument("Chessboard: " + why);
             return board;
           }),
           py::arg("corners_x"), py::arg("corners_y"), py::arg("square_size"),
           "Inner corners along a row and a column, square side in metres.")
      .def_readonly("corners_x", &ChessboardSpec::corners_x)
      .def_readonly("corners_y", &ChessboardSpec::corners_y)
      .def_readonly("square_size", &ChessboardSpec::square_size);

  m.def(
      "detect_chessboard",
      [](const py::array& image, const ChessboardSpec& board) -> py::object {
        std::vector<Vec2> corners;
        const cv::Mat mat = ArrayMat(image, "image");
        bool found;
        {
          py::gil_scoped_release release;
          found = DetectChessboard(mat, board, &corners);
        }
        if (!found) return py::none();
        Eigen::MatrixX2d points(corners.size(), 2);
        for (size_t k = 0; k < corners.size(); ++k) points.row(k) = corners[k].transpose();
        return py::cast(points);
      },
      py::arg("image"), py::arg("board"),
      "The board's inner corners in an 8- or 16-bit image: (corners_x*corners_y, 2) pixels, row-major, "
      "or None when the whole grid is not found.");

  py::class_<CameraCalibrationSummary>(m, "CameraCalibrationSummary")
      .def_property_readonly("converged", [](const CameraCalibrationSummary& s) { return s.termination == CameraCalibrationSummary::kConverged; })
      .def_readonly("views", &CameraCalibrationSummary::views)
      .def_readonly("outliers", &CameraCalibrationSummary::outliers)
      .def_readonly("rms", &CameraCalibrationSummary::rms, "RMS residual per coordinate over inliers, px")
      .def_readonly("message", &CameraCalibrationSummary::message)
      .def("brief_report", &CameraCalibrationSummary::BriefReport);
  py::class_<CameraCalibration>(m, "CameraCalibration", "A calibrated lens (mrcal) and the board's pose per view.")
      .def_readonly("lens_model", &CameraCalibration::lens_model)
      .def_readonly("intrinsics", &CameraCalibration::intrinsics, "mrcal order: fx, fy, cx, cy, distortion...")
      .def_readonly("width", &CameraCalibration::width)
      .def_readonly("height", &CameraCalibration::height)
      .def("write", &WriteCalibrationModel, py::arg("path"), "Writes the .cameramodel atomically (mrcal's format).");

  m.def(
      "calibrate_camera",
      [](const std::vector<Eigen::MatrixX2d>& views, const ChessboardSpec& board, int width, int height,
         const std::string& lens_model, bool reject_outliers) {
        CameraCalibrationOptions options;
        options.lens_model = lens_model;
        options.reject_outliers = reject_outliers;
        std::string why;
        if (!options.Check(&why)) throw std::invalid_argument(why);
        std::vector<ChessboardView> chessboard_views;
        for (size_t k = 0; k < views.size(); ++k) {
          ChessboardView view;
          view.name = "views[" + std::to_string(k) + "]";
          for (Eigen::Index i = 0; i < views[k].rows(); ++i) view.corners.push_back(views[k].row(i).transpose());
          chessboard_views.push_back(std::move(view));
        }
        CameraCalibration calibration;
        CameraCalibrationSummary summary;
        {
          py::gil_scoped_release release;
          CalibrateCamera(options, board, chessboard_views, width, height, &calibration, &summary);
        }
        return py::make_tuple(calibration, summary);
      },
      py::arg("views"), py::arg("board"), py::arg("width"), py::arg("height"),
      py::arg("lens_model") = CameraCalibrationOptions().lens_model, py::arg("reject_outliers") = true,
      "Calibrates a camera of width x height pixels from the corners of `board` seen in each view "
      "(a list of (corners_x*corners_y, 2) arrays, e.g. detect_chessboard's): returns "
      "(CameraCalibration, CameraCalibrationSummary). Releases the GIL while mrcal solves.");
  BindBoardProjector(m);
}


// A projector calibrated with the camera from a chessboard and structured light (docs/chessboard.md).
void BindBoardProjector(py::module_& m) {
  py::class_<BoardProjectorSummary>(m, "BoardProjectorSummary")
      .def_property_readonly("converged", [](const BoardProjectorSummary& s) { return s.termination == BoardProjectorSummary::kConverged; })
      .def_readonly("poses", &BoardProjectorSummary::poses)
      .def_readonly("camera_rms", &BoardProjectorSummary::camera_rms, "px, per coordinate, inliers")
      .def_readonly("projector_rms", &BoardProjectorSummary::projector_rms, "px, per coordinate, inliers")
      .def_readonly("message", &BoardProjectorSummary::message)
      .def("brief_report", &BoardProjectorSummary::BriefReport);
  py::class_<BoardProjectorCalibration>(m, "BoardProjectorCalibration",
                                        "A camera and a projector calibrated together (mrcal).")
      .def_readonly("lens_model", &BoardProjectorCalibration::lens_model)
      .def_readonly("camera_intrinsics", &BoardProjectorCalibration::camera_intrinsics, "mrcal order")
      .def_readonly("projector_intrinsics", &BoardProjectorCalibration::projector_intrinsics, "mrcal order")
      .def_property_readonly("projector_from_camera", [](const BoardProjectorCalibration& c) {
            return Eigen::Matrix4d(c.projector_from_camera.matrix());
          }, "(4,4) rigid transform from camera to projector coordinates, metres")
      .def("write", [](const BoardProjectorCalibration& c, const std::filesystem::path& camera,
                       const std::filesystem::path& projector) {
            WriteCameraModelFile(camera, c.CameraModelOut(), "procam board calibration: the camera");
            WriteCameraModelFile(projector, c.ProjectorModelOut(), "procam board calibration: the projector");
          }, py::arg("camera"), py::arg("projector"), "Writes both .cameramodel files atomically.");

  m.def(
      "locate_board_corners",
      [](const py::array& white, const StructuredLightMap& map, const ChessboardSpec& board) -> py::object {
        BoardPoseCapture capture;
        capture.white = ArrayMat(white, "white");
        capture.map = map;
        BoardPoseCorners corners;
        bool found;
        {
          py::gil_scoped_release release;
          found = LocateBoardCorners(BoardProjectorOptions(), board, capture, &corners);
        }
        if (!found) return py::none();
        Eigen::MatrixX2d camera(corners.camera.size(), 2), projector(corners.projector.size(), 2);
        Eigen::Matrix<bool, Eigen::Dynamic, 1> seen(corners.projector_found.size());
        for (size_t k = 0; k < corners.camera.size(); ++k) camera.row(k) = corners.camera[k].transpose();
        for (size_t k = 0; k < corners.projector.size(); ++k) projector.row(k) = corners.projector[k].transpose();
        for (size_t k = 0; k < corners.projector_found.size(); ++k) seen(k) = corners.projector_found[k];
        return py::make_tuple(camera, projector, seen);
      },
      py::arg("white"), py::arg("map"), py::arg("board"),
      "One pose: the board's corners in the photo under full white and, through local homographies "
      "of the decoded structured light `map`, in the projector: (camera (k,2), projector (k,2), "
      "seen (k,) bool), or None when the board is not found.");

  m.def(
      "calibrate_board_projector",
      [](const std::vector<std::tuple<Eigen::MatrixX2d, Eigen::MatrixX2d, std::vector<bool>>>& poses,
         const ChessboardSpec& board, std::pair<int, int> camera_size, std::pair<int, int> projector_size,
         const std::string& lens_model) {
        BoardProjectorOptions options;
        options.lens_model = lens_model;
        std::string why;
        if (!options.Check(&why)) throw std::invalid_argument(why);
        std::vector<BoardPoseCorners> corners;
        for (size_t p = 0; p < poses.size(); ++p) {
          const auto& [camera, projector, seen] = poses[p];
          if (camera.rows() != board.CornerCount() || projector.rows() != board.CornerCount() ||
              static_cast<int>(seen.size()) != board.CornerCount()) {
            throw std::invalid_argument("poses[" + std::to_string(p) + "]: " + std::to_string(board.CornerCount()) +
                                        " corners in each of camera, projector and seen");
          }
          BoardPoseCorners pose;
          pose.name = "poses[" + std::to_string(p) + "]";
          for (int k = 0; k < board.CornerCount(); ++k) {
            pose.camera.push_back(camera.row(k).transpose());
            pose.projector.push_back(projector.row(k).transpose());
          }
          pose.projector_found = seen;
          pose.window_pixels.assign(board.CornerCount(), 0);
          corners.push_back(std::move(pose));
        }
        BoardProjectorCalibration calibration;
        BoardProjectorSummary summary;
        {
          py::gil_scoped_release release;
          CalibrateBoardProjector(options, board, corners, camera_size.first, camera_size.second, projector_size.first,
                                  projector_size.second, &calibration, &summary);
        }
        return py::make_tuple(calibration, summary);
      },
      py::arg("poses"), py::arg("board"), py::arg("camera_size"), py::arg("projector_size"),
      py::arg("lens_model") = BoardProjectorOptions().lens_model,
      "Calibrates the camera and the projector together (Moreno & Taubin's method, solved by mrcal) "
      "from poses of `board`: each (camera (k,2), projector (k,2), seen (k,)) as locate_board_corners "
      "gives. Sizes are (width, height). Returns (BoardProjectorCalibration, BoardProjectorSummary). "
      "Releases the GIL while mrcal solves.");
}

}  // namespace procam::python
