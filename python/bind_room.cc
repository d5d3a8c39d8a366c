// procam.Room (a calibrated room, built once: projection/calibrated_room.h), procam.compensate
// as `procam compensate` runs it, and the solution directory read and written by its owner.
#include <pybind11/eigen.h>
#include <pybind11/functional.h>
#include <pybind11/stl.h>
#include <pybind11/stl/filesystem.h>

#include <stdexcept>

#include "compensation/stage.h"
#include "projection/calibrated_room.h"
#include "projection/projector_images.h"
#include "python/bindings.h"

namespace py = pybind11;

namespace procam::python {
namespace {

// An optional path argument: None is none (empty); str and os.PathLike are the path.
std::filesystem::path OptionalPath(const py::object& value) {
  if (value.is_none()) return {};
  return py::module_::import("os").attr("fspath")(value).cast<std::string>();
}

}  // namespace

void BindRoom(py::module_& m) {
  py::class_<CalibratedRoom>(m, "Room",
                             "A room calibrated by a rig at a patch count: geometry with the rig's "
                             "reflectance, the projectors and their bounds, the problem.")
      .def_readonly("geometry", &CalibratedRoom::geometry)
      .def_readonly("problem", &CalibratedRoom::problem,
                    "the fine level's Problem within the projectors' bounds (empty with problem=False)")
      .def_property_readonly("size", &CalibratedRoom::size, "fine patches n")
      .def_property_readonly("projectors", [](const CalibratedRoom& room) {
            std::vector<std::string> names;
            for (const Projector& projector : room.projectors) names.push_back(projector.name);
            return names;
          }, "the projectors' names (the rig's, else the scene's)")
      .def_property_readonly("lower", [](const CalibratedRoom& room) -> const Eigen::MatrixX3d& { return room.projection.lower; },
                             py::return_value_policy::reference_internal,
                             "(n,3) the projectors' direct-light lower bound on E (empty without projectors; view)")
      .def_property_readonly("upper", [](const CalibratedRoom& room) -> const Eigen::MatrixX3d& { return room.projection.upper; },
                             py::return_value_policy::reference_internal,
                             "(n,3) the projectors' upper bound on E (empty without projectors; view)")
      .def_property_readonly("rig", [](const CalibratedRoom& room) -> py::object {
            return room.rig ? py::cast(room.rig->dir.string()) : py::none();
          }, "the rig directory, or None");

  m.def(
      "load_room",
      [](const std::string& scene, const py::object& rig, const py::object& solution, int patches,
         const std::string& form_factors, bool problem, double alpha, const py::object& progress) {
        CalibratedRoomOptions options;
        options.scene = scene;
        options.rig_dir = OptionalPath(rig);
        options.solution_dir = OptionalPath(solution);
        options.patches = patches;
        if (form_factors != "dense" && form_factors != "compressed") {
          throw std::invalid_argument("form_factors: 'dense' or 'compressed', got '" + form_factors + "'");
        }
        options.storage = form_factors == "compressed" ? FormFactorStorage::kCompressed : FormFactorStorage::kDense;
        options.problem = problem && options.storage == FormFactorStorage::kDense;
        options.alpha = alpha;
        options.progress = PythonProgress(progress);
        std::string why;
        if (!options.Check(&why)) throw std::invalid_argument(why);
        py::gil_scoped_release release;
        return LoadCalibratedRoom(options);
      },
      py::arg("scene") = "", py::arg("rig") = py::none(), py::arg("solution") = py::none(),
      py::arg("patches") = 0, py::arg("form_factors") = "dense", py::arg("problem") = true, py::arg("alpha") = 0.5,
      py::arg("progress") = py::none(),
      "Loads a room as every command does: `scene` (a file or 'synthetic:NAME'; '' with a solution: its "
      "scene), calibrated by the rig directory `rig` (its projectors and reflectance; None for the "
      "scene's own), at `patches` (0: the solution's or the scene's), checked against the solution "
      "directory `solution` (None for none). Raises procam.IoError naming the file and key, or the patch counts "
      "that disagree. Releases the GIL while it runs.");

  m.def(
      "compensate",
      [](const CalibratedRoom& room, const SolverOptions& solver, double alpha,
         const py::object& progress) {
        CompensationOptions options;
        options.solver = solver;
        options.alpha = alpha;
        options.progress = PythonProgress(progress);
        // As `procam compensate`: the projectors' light bounds E; without projectors the
        // scene's "bounds".
        if (!room.projectors.empty()) {
          options.lower = room.projection.lower;
          options.upper = room.projection.upper;
        }
        std::string why;
        if (!options.Check(&why)) throw std::invalid_argument(why);
        py::gil_scoped_release release;
        return RunCompensation(room.geometry, options);
      },
      py::arg("room"), py::arg("options") = RecommendedSolverOptions(), py::arg("alpha") = 0.5,
      py::arg("progress") = py::none(),
      "Compensates `room` as `procam compensate` does (within its projectors' bounds): returns a "
      "Compensation. Releases the GIL while it solves.");

  m.def(
      "write_solution",
      [](const CalibratedRoom& room, const CompensationRun& run, const std::filesystem::path& out, bool export_problem) {
        nlohmann::json extra = nlohmann::json::object();
        if (room.rig) extra["rig"] = room.rig->Describe();
        py::gil_scoped_release release;
        WriteCompensation(room.geometry, run, out, export_problem, extra);
      },
      py::arg("room"), py::arg("compensation"), py::arg("out"), py::arg("export_problem") = false,
      "Writes the solution directory `out` as `procam compensate --out` does (result.json, E.npy, B.npy; "
      "with export_problem the whole problem), each file atomically; `procam project` and `verify` read it.");

  m.def(
      "projector_images",
      [](const CalibratedRoom& room, const Eigen::MatrixX3d& emittance, const std::string& dither,
         const std::string& light) {
        if (room.projectors.empty()) throw std::invalid_argument("room: no projectors (load_room with a rig, or a scene with projectors)");
        RenderOptions options;
        if (!ParseDither(dither, &options.dither)) throw std::invalid_argument("dither: unknown '" + dither + "'");
        if (!ParseLightField(light, &options.light)) throw std::invalid_argument("light: unknown '" + light + "'");
        options.reflectance = HasReflectanceMaps(room.projection);  // as procam project
        std::vector<ProjectorImage> images;
        {
          py::gil_scoped_release release;
          RenderSummary summary;
          images = RenderProjectorImages(room.projection, room.geometry.scene, emittance, options, &summary);
        }
        py::list arrays;
        for (const ProjectorImage& image : images) arrays.append(MatArray(image.codes));
        return arrays;
      },
      py::arg("room"), py::arg("emittance"), py::arg("dither") = DitherName(RenderOptions().dither),
      py::arg("light") = LightFieldName(RenderOptions().light),
      "Each projector's image that delivers `emittance` (n,3) (e.g. compensate(room).emittance), in "
      "room.projectors' order: (height,width,3) uint16 code values, row 0 at the top, R,G,B, each in "
      "[0, 2^bits - 1] of that projector (what `procam project` writes as PNG). `dither`: the command "
      "line's --dither names; `light`: its --light names. Releases the GIL while it renders.");

  py::class_<RigDirectory>(m, "RigDirectory", "A rig directory as read back (docs/rig_format.md).")
      .def_property_readonly("dir", [](const RigDirectory& r) { return r.dir.string(); })
      .def_property_readonly("projectors", [](const RigDirectory& r) {
            std::vector<std::string> names;
            for (const Projector& projector : r.projectors) names.push_back(projector.name);
            return names;
          }, "the projectors' names, in rig.json's order")
      .def_property_readonly("projector_models", [](const RigDirectory& r) {
            std::vector<std::string> paths;
            for (const Projector& projector : r.projectors) paths.push_back(projector.model_path.string());
            return paths;
          }, "each projector's .cameramodel ('' before calibrate projectors)")
      .def_property_readonly("camera_model", [](const RigDirectory& r) {
            return r.file.camera.model.empty() ? std::string() : (r.dir / r.file.camera.model).string();
          }, "the camera's .cameramodel ('' before it is calibrated)")
      .def_readonly("reflectance", &RigDirectory::reflectance,
                    "(n,3) the patches' reflectance estimated by calibrate photometric (empty without; view)")
      .def_readonly("reflectance_target_patches", &RigDirectory::reflectance_target_patches,
                    "the patch target `reflectance` was estimated for")
      .def("describe", [](const RigDirectory& r) { return r.Describe().dump(); },
           "What a solution's result.json records about the rig (JSON text).");
  m.def("read_rig", &ReadRigDirectory, py::arg("directory"),
        "Reads and checks a rig directory (rig.json and what it names); raises procam.IoError naming "
        "the file and key.");

  py::class_<SolutionDirectory>(m, "SolutionDirectory", "A solution directory as read back (docs/solution_format.md).")
      .def_property_readonly("scene", [](const SolutionDirectory& s) { return s.scene; })
      .def_readonly("patches", &SolutionDirectory::patches)
      .def_readonly("target_patches", &SolutionDirectory::target_patches)
      .def_property_readonly("method", [](const SolutionDirectory& s) { return MethodName(s.method); })
      .def_readonly("alpha", &SolutionDirectory::alpha)
      .def_property_readonly("rig", [](const SolutionDirectory& s) { return s.rig_dir.string(); })
      .def_readonly("emittance", &SolutionDirectory::emittance, "(n,3) E.npy (view)")
      .def_readonly("radiosity", &SolutionDirectory::radiosity, "(n,3) B.npy (view)");
  m.def("read_solution", &ReadSolutionDirectory, py::arg("directory"),
        "Reads and checks a solution directory; raises procam.IoError naming the file and key.");
}

}  // namespace procam::python
