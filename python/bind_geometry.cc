// procam.Scene, procam.load_scene and procam.Geometry: a scene, its patches and form factors.
#include <pybind11/eigen.h>
#include <pybind11/functional.h>
#include <pybind11/stl.h>
#include <pybind11/stl/filesystem.h>

#include "geometry/stage.h"
#include "python/bindings.h"

namespace py = pybind11;

namespace procam::python {
namespace {

// Rows of one vector per patch: centroids or normals (n,3).
template <typename Field>
Eigen::MatrixX3d PatchRows(const PatchLevel& level, Field field) {
  Eigen::MatrixX3d rows(level.size(), 3);
  for (int i = 0; i < level.size(); ++i) rows.row(i) = field(level.patches[i]).transpose();
  return rows;
}

Eigen::Matrix<int64_t, Eigen::Dynamic, 2, Eigen::RowMajor> AdjacencyArray(const PatchLevel& level) {
  Eigen::Matrix<int64_t, Eigen::Dynamic, 2, Eigen::RowMajor> pairs(level.adjacency.size(), 2);
  for (size_t k = 0; k < level.adjacency.size(); ++k) {
    pairs(k, 0) = level.adjacency[k][0];
    pairs(k, 1) = level.adjacency[k][1];
  }
  return pairs;
}

}  // namespace

void BindGeometry(py::module_& m) {
  py::class_<Surface>(m, "Surface", "One surface of a scene: a planar quad or a triangle mesh.")
      .def_readonly("name", &Surface::name)
      .def_property_readonly("kind", [](const Surface& s) { return s.kind == Surface::Kind::kQuad ? "quad" : "mesh"; },
                             "'quad' or 'mesh'")
      .def_property_readonly("reflectance", [](const Surface& s) { return Eigen::Vector3d(s.reflectance); },
                             "(3,) diffuse reflectance per channel, each in [0,1) (a copy)")
      .def_property_readonly("desired_srgb", [](const Surface& s) { return Eigen::Vector3d(s.desired.srgb); },
                             "(3,) desired sRGB colour in [0,1] (when the surface has no texture; a copy)")
      .def_property_readonly("has_texture", [](const Surface& s) { return s.desired.HasTexture(); })
      .def("area", &Surface::Area, "Area in m²")
      .def("__repr__", [](const Surface& s) { return "<procam.Surface '" + s.name + "'>"; });

  py::class_<Scene>(m, "Scene", "A room: surfaces, reflectance, desired appearance (docs/scene_format.md).")
      .def_readonly("name", &Scene::name)
      .def_property_readonly("path", [](const Scene& s) { return s.path.string(); },
                             "The file it was read from, or PREFIX:NAME ('' for a scene made in code)")
      .def_readonly("surfaces", &Scene::surfaces)
      .def_readonly("target_patches", &Scene::target_patches, "Fine patches wanted in total")
      .def_readonly("white", &Scene::white, "Reference white radiosity w")
      .def_property_readonly("has_projectors", [](const Scene& s) { return !s.projectors_json.empty(); })
      .def("area", &Scene::Area, "Total area in m²")
      .def("__repr__", [](const Scene& s) {
        return "<procam.Scene '" + s.name + "', " + std::to_string(s.surfaces.size()) + " surfaces>";
      });

  m.def("load_scene", &LoadSceneArgument, py::arg("scene"),
        "Reads and validates a scene: a scene file's path, or 'synthetic:NAME' for a scene of the "
        "synthetic world. Raises procam.IoError naming the file and the key.");

  py::class_<PatchLevel>(m, "PatchLevel", "One level of patches: what the solver computes on.")
      .def_property_readonly("size", &PatchLevel::size, "Patch count n")
      .def_property_readonly("area", &PatchLevel::Areas, "(n,) patch areas, m² (a copy)")
      .def_property_readonly("centroid", [](const PatchLevel& l) { return PatchRows(l, [](const Patch& p) { return p.centroid; }); },
                             "(n,3) patch centroids, m (a copy)")
      .def_property_readonly("normal", [](const PatchLevel& l) { return PatchRows(l, [](const Patch& p) { return p.normal; }); },
                             "(n,3) unit normals of the lit side (a copy)")
      .def_property_readonly("surface", [](const PatchLevel& l) {
            Eigen::VectorXi surface(l.size());
            for (int i = 0; i < l.size(); ++i) surface(i) = l.patches[i].surface;
            return surface;
          }, "(n,) index of each patch's surface in Scene.surfaces (a copy)")
      .def_property_readonly("adjacency", &AdjacencyArray,
                             "(m,2) int64 pairs i<j of patches sharing an edge, each once (a copy)")
      .def_readonly("reflectance", &PatchLevel::reflectance, "(n,3) reflectance per patch and channel (read-only view)")
      .def_readonly("desired", &PatchLevel::desired_linear,
                    "(n,3) desired radiosity, linear RGB × the scene's white (read-only view)");

  py::class_<GeometryStage>(m, "Geometry",
                            "A scene subdivided into patches (fine and coarse levels) with the fine "
                            "level's form factors.")
      .def_readonly("scene", &GeometryStage::scene)
      .def_property_readonly("fine", [](const GeometryStage& g) -> const PatchLevel& { return g.patches.fine; },
                             py::return_value_policy::reference_internal)
      .def_property_readonly("coarse", [](const GeometryStage& g) -> const PatchLevel& { return g.patches.coarse; },
                             py::return_value_policy::reference_internal)
      .def_property_readonly("coarse_of_fine", [](const GeometryStage& g) {
            return Eigen::Map<const Eigen::VectorXi>(g.patches.coarse_of_fine.data(),
                                                      static_cast<Eigen::Index>(g.patches.coarse_of_fine.size())).eval();
          }, "(n,) each fine patch's coarse parent (a copy)")
      .def_readonly("form_factors", &GeometryStage::form_factors,
                    "(n,n) form factors F of the fine level, F[i,j] the share of light leaving i that "
                    "reaches j (read-only view, no copy); empty when compressed")
      .def("brief_report", &GeometryStage::BriefReport);

  m.def(
      "geometry",
      [](const std::string& scene, int patches, const std::string& form_factors, const py::object& progress) {
        GeometryOptions options;
        options.patches = patches;
        if (form_factors == "dense") {
          options.storage = FormFactorStorage::kDense;
        } else if (form_factors == "compressed") {
          options.storage = FormFactorStorage::kCompressed;
        } else {
          throw std::invalid_argument("form_factors: 'dense' or 'compressed', got '" + form_factors + "'");
        }
        options.progress = PythonProgress(progress);
        py::gil_scoped_release release;
        return RunGeometryStage(scene, options);
      },
      py::arg("scene"), py::arg("patches") = 0, py::arg("form_factors") = "dense", py::arg("progress") = py::none(),
      "Loads `scene` (a file or 'synthetic:NAME'), subdivides it into `patches` fine patches (0: the "
      "scene's own target) and computes their form factors ('dense': n² float64; 'compressed': "
      "rooms of 10k+ patches). `progress`: None or a callable taking one line of text. Releases the "
      "GIL while it runs.");
}

}  // namespace procam::python
