// procam.Problem, procam.SolverOptions, procam.solve and procam.compensate: the compensation
// problem (DESIGN.md) and its solvers (compensation/solver.h), with the same names.
#include <pybind11/eigen.h>
#include <pybind11/functional.h>
#include <pybind11/stl.h>

#include <chrono>
#include <stdexcept>
#include <vector>

#include "compensation/problem.h"
#include "compensation/solver.h"
#include "compensation/stage.h"
#include "python/bindings.h"

namespace py = pybind11;

namespace procam::python {
namespace {

// An enumeration field of SolverOptions read and written by its name, as the command line spells it.
template <typename Enum>
void CheckedParse(bool (*parse)(const std::string&, Enum*), const std::string& field, const std::string& name,
                  Enum* value) {
  if (!parse(name, value)) throw std::invalid_argument("SolverOptions." + field + ": unknown value '" + name + "'");
}

bool ParsePreconditioner(const std::string& name, SolverOptions::Preconditioner* value) {
  if (name == "free_colour_hessian") *value = SolverOptions::Preconditioner::kFreeColourHessian;
  else if (name == "inverse_hessian") *value = SolverOptions::Preconditioner::kInverseHessian;
  else return false;
  return true;
}

const char* PreconditionerName(SolverOptions::Preconditioner value) {
  return value == SolverOptions::Preconditioner::kFreeColourHessian ? "free_colour_hessian" : "inverse_hessian";
}

void CheckOptions(const SolverOptions& options) {
  std::string why;
  if (!options.Check(&why)) throw std::invalid_argument("SolverOptions: " + why);
}

}  // namespace

void BindCompensation(py::module_& m) {
  py::class_<CompensationProblem>(
      m, "Problem",
      "The compensation problem exactly as DESIGN.md defines it: minimise over the emittance E (n,3) "
      "the perceptual objective of the radiosity B = (I - diag(rho) F)^-1 E against the desired Bd, "
      "lower <= E <= upper. Every array field is copied in and out (NumPy to Eigen's layout).")
      .def(py::init<>())
      .def_readwrite("form_factors", &CompensationProblem::form_factors, "(n,n) F, shared by all channels")
      .def_readwrite("area", &CompensationProblem::area, "(n,) A_i, m²")
      .def_readwrite("reflectance", &CompensationProblem::reflectance, "(n,3) rho, each in [0,1)")
      .def_readwrite("adjacency", &CompensationProblem::adjacency, "list of (i,j), i<j, patches sharing an edge")
      .def_readwrite("lower", &CompensationProblem::lower, "(n,3) lower bound on E (direct-light exitance)")
      .def_readwrite("upper", &CompensationProblem::upper, "(n,3) upper bound on E")
      .def_readwrite("desired", &CompensationProblem::desired, "(n,3) desired radiosity Bd, linear RGB")
      .def_readwrite("rgb_to_xyz", &CompensationProblem::rgb_to_xyz, "(3,3) T, linear RGB to CIE XYZ")
      .def_readwrite("white_xyz", &CompensationProblem::white_xyz, "(3,) (Xn,Yn,Zn) = T (w,w,w)")
      .def_readwrite("alpha", &CompensationProblem::alpha, "weight of the absolute term, in (0,1]")
      .def_readwrite("patch_weight", &CompensationProblem::patch_weight,
                     "(n,) or empty: multiplies each patch's absolute term")
      .def_property_readonly("size", &CompensationProblem::size)
      .def("validate", &CompensationProblem::Validate, "'' if consistent, else one line naming what is wrong");

  m.def(
      "make_problem",
      [](const GeometryStage& geometry, double alpha) {
        return MakeProblem(geometry.scene, geometry.patches.fine, geometry.form_factors, alpha);
      },
      py::arg("geometry"), py::arg("alpha") = 0.5,
      "The fine level's problem of `geometry` with the scene's bounds and sRGB primaries (a copy "
      "of its form factors).");

  py::class_<SolverOptions>(m, "SolverOptions",
                            "The solver's options (compensation/solver.h documents each); check() "
                            "raises ValueError naming the first bad one.")
      .def(py::init<>())
      .def_property(
          "method", [](const SolverOptions& o) { return MethodName(o.method); },
          [](SolverOptions& o, const std::string& name) {
            CheckedParse(&ParseMethod, "method", name, &o.method);
          },
          "naive | reverse | linear | perceptual (Sheng et al. 2011, CIE76) | perceptual2000 "
          "(the objective in CIEDE2000 under a robust loss)")
      .def_property(
          "device", [](const SolverOptions& o) { return DeviceName(o.device); },
          [](SolverOptions& o, const std::string& name) {
            CheckedParse(&ParseDevice, "device", name, &o.device);
          },
          "cpu | cuda: where K^-1 is applied (cuda needs a CUDA build and a GPU)")
      .def_property(
          "robust_loss", [](const SolverOptions& o) { return RobustLossName(o.robust_loss); },
          [](SolverOptions& o, const std::string& name) {
            CheckedParse(&ParseRobustLoss, "robust_loss", name, &o.robust_loss);
          },
          "perceptual2000: squared | soft_l1 | huber | cauchy, on each patch's ΔE00²")
      .def_property(
          "preconditioner",
          [](const SolverOptions& o) { return PreconditionerName(o.preconditioner); },
          [](SolverOptions& o, const std::string& name) {
            CheckedParse(&ParsePreconditioner, "preconditioner", name, &o.preconditioner);
          },
          "CG's preconditioner on the CPU: free_colour_hessian | inverse_hessian")
      .def_readwrite("robust_scale", &SolverOptions::robust_scale,
                     "perceptual2000: the loss's scale c, ΔE00 units, > 0")
      .def_readwrite("metric_rounds", &SolverOptions::metric_rounds,
                     "perceptual2000: reweighting rounds, >= 1")
      .def_readwrite("multires", &SolverOptions::multires,
                     "solve the coarse level first (solve() needs one)")
      .def_readwrite("max_iterations", &SolverOptions::max_iterations,
                     "outer (Gauss-Newton) iterations, >= 1")
      .def_readwrite("max_inner_iterations", &SolverOptions::max_inner_iterations,
                     "projected-Newton steps per outer iteration")
      .def_readwrite("max_cg_iterations", &SolverOptions::max_cg_iterations,
                     "CG iterations per Newton system")
      .def_readwrite("cg_tolerance", &SolverOptions::cg_tolerance,
                     "CG's relative residual tolerance (forcing term)")
      .def_readwrite("gradient_tolerance", &SolverOptions::gradient_tolerance,
                     "stop when the projected gradient's max norm <= this (1 + f)")
      .def_readwrite("function_tolerance", &SolverOptions::function_tolerance,
                     "stop when an iteration lowers f by <= this times f")
      .def_readwrite(
          "device_float32", &SolverOptions::device_float32,
          "cuda: objective values, gradients and line searches with the float32 K^-1 too")
      .def_readwrite("device_host_loop", &SolverOptions::device_host_loop,
                     "cuda: Alg. 1 on the host, only K^-1 products on the device (for comparison)")
      .def_readwrite(
          "device_fused", &SolverOptions::device_fused,
          "cuda: problems under 4096 patches run the whole loop in one cooperative kernel")
      .def_readwrite("device_product_rows", &SolverOptions::device_product_rows,
                     "cuda, dense F: outputs per block of the K^-1 product kernel (1, 2, 4, 8; 0 "
                     "cuBLAS; -1 best)")
      .def_readwrite("device_graphs", &SolverOptions::device_graphs,
                     "cuda: replay fixed kernel sequences as CUDA graphs")
      .def_readwrite("device_fused_blocks", &SolverOptions::device_fused_blocks,
                     "cuda, fused loop: blocks of the cooperative grid (0: one per multiprocessor)")
      .def_readwrite("device_profile", &SolverOptions::device_profile,
                     "cuda: print where each solve's time went (stderr)")
      .def_property(
          "device_preconditioner",
          [](const SolverOptions& o) { return DevicePreconditionerName(o.device_preconditioner); },
          [](SolverOptions& o, const std::string& name) {
            if (name == "block_jacobi_neumann")
              o.device_preconditioner = SolverOptions::DevicePreconditioner::kBlockJacobiNeumann;
            else if (name == "block_jacobi")
              o.device_preconditioner = SolverOptions::DevicePreconditioner::kBlockJacobi;
            else
              throw std::invalid_argument("SolverOptions.device_preconditioner: unknown value '" +
                                          name + "'");
          },
          "cuda: CG's preconditioner, block_jacobi_neumann | block_jacobi")
      .def_property(
          "device_cg_matrix",
          [](const SolverOptions& o) { return DeviceCgMatrixName(o.device_cg_matrix); },
          [](SolverOptions& o, const std::string& name) {
            if (name == "float16")
              o.device_cg_matrix = SolverOptions::DeviceCgMatrix::kFloat16;
            else if (name == "float32")
              o.device_cg_matrix = SolverOptions::DeviceCgMatrix::kFloat32;
            else
              throw std::invalid_argument("SolverOptions.device_cg_matrix: unknown value '" + name +
                                          "'");
          },
          "cuda, dense F: the copy of K^-1 CG's products read, float16 | float32")
      .def_readwrite("metric_round_tolerance", &SolverOptions::metric_round_tolerance,
                     "perceptual2000: relative decrease at which every round but the last stops "
                     "(0: the full tolerances)")
      .def_property(
          "metric_update", [](const SolverOptions& o) { return MetricUpdateName(o.metric_update); },
          [](SolverOptions& o, const std::string& name) {
            CheckedParse(&ParseMetricUpdate, "metric_update", name, &o.metric_update);
          },
          "perceptual2000: rounds (each a whole solve) | every_iteration (inside one Gauss-Newton "
          "run)")
      .def_readwrite("metric_update_tolerance", &SolverOptions::metric_update_tolerance,
                     "perceptual2000, every_iteration: relative decrease of the robust objective "
                     "at which it stops")
      .def_readwrite("armijo", &SolverOptions::armijo,
                     "the line search's sufficient-decrease constant")
      .def_readwrite("second_order", &SolverOptions::second_order,
                     "Gauss-Newton's second-order term")
      .def(
          "check", [](const SolverOptions& o) { CheckOptions(o); },
          "Raises ValueError naming the first bad option.");

  py::class_<SolverSummary>(m, "SolverSummary", "What a solve did (compensation/solver.h).")
      .def_property_readonly("method", [](const SolverSummary& s) { return MethodName(s.method); })
      .def_property_readonly("termination", [](const SolverSummary& s) { return TerminationName(s.termination); })
      .def_readonly("message", &SolverSummary::message)
      .def_readonly("initial_cost", &SolverSummary::initial_cost)
      .def_readonly("final_cost", &SolverSummary::final_cost)
      .def_readonly("iterations", &SolverSummary::iterations, "outer iterations")
      .def_readonly("inner_iterations", &SolverSummary::inner_iterations)
      .def_readonly("cg_iterations", &SolverSummary::cg_iterations)
      .def_readonly("setup_seconds", &SolverSummary::setup_seconds, "factorising K")
      .def_readonly("solve_seconds", &SolverSummary::solve_seconds, "everything after the setup")
      .def("brief_report", &SolverSummary::BriefReport)
      .def("__repr__", [](const SolverSummary& s) { return "<procam.SolverSummary " + s.BriefReport() + ">"; });

  py::class_<CompensationSolution>(m, "Solution", "A solve's result.")
      .def_readonly("emittance", &CompensationSolution::emittance, "(n,3) E within the bounds (read-only view)")
      .def_readonly("radiosity", &CompensationSolution::radiosity, "(n,3) B = K^-1 E (read-only view)");

  m.def(
      "solve",
      [](const CompensationProblem& problem, const SolverOptions& options, const py::object& progress) {
        CheckOptions(options);
        if (options.multires) throw std::invalid_argument("SolverOptions.multires: solve() takes one level; use compensate()");
        SolverOptions run = options;
        ProgressCallback lines = PythonProgress(progress);
        if (lines) {
          run.progress = [lines](int iteration, double cost, double seconds) {
            lines("iteration " + std::to_string(iteration) + " cost " + std::to_string(cost) + " " +
                  std::to_string(seconds) + " s");
          };
        }
        SolverSummary summary;
        CompensationSolution solution;
        {
          py::gil_scoped_release release;
          solution = Solve(run, problem, &summary);
        }
        return py::make_tuple(std::move(solution), std::move(summary));
      },
      py::arg("problem"), py::arg("options") = SolverOptions(), py::arg("progress") = py::none(),
      "Solves `problem`: returns (Solution, SolverSummary). Raises ValueError for an invalid "
      "problem or options. `progress`: None or a callable taking one line per outer iteration. "
      "Releases the GIL while it solves.");

  // The same solve timed in C++ alone, for tools/python_overhead.py: what a call from Python
  // costs beyond it is the binding's overhead.
  m.def(
      "_solve_seconds_in_cpp",
      [](const CompensationProblem& problem, const SolverOptions& options, int repeats) {
        CheckOptions(options);
        py::gil_scoped_release release;
        std::vector<double> seconds;
        for (int k = 0; k < repeats; ++k) {
          // Timed until the result is freed, as a call from Python that drops it is.
          const auto start = std::chrono::steady_clock::now();
          {
            SolverSummary summary;
            const CompensationSolution solution = Solve(options, problem, &summary);
          }
          seconds.push_back(std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count());
        }
        return seconds;
      },
      py::arg("problem"), py::arg("options"), py::arg("repeats"),
      "Wall seconds of each of `repeats` calls of the C++ Solve on `problem` (benchmarks only).");

  py::class_<CompensationRun>(m, "Compensation",
                              "A compensation of a scene: the solution and its colour differences.")
      .def_property_readonly("emittance", [](const CompensationRun& r) -> const Eigen::MatrixX3d& { return r.solution.emittance; },
                             py::return_value_policy::reference_internal, "(n,3) E (read-only view)")
      .def_property_readonly("radiosity", [](const CompensationRun& r) -> const Eigen::MatrixX3d& { return r.solution.radiosity; },
                             py::return_value_policy::reference_internal, "(n,3) B = K^-1 E (read-only view)")
      .def_readonly("problem", &CompensationRun::fine, "the fine level's Problem")
      .def_readonly("summary", &CompensationRun::summary)
      .def_readonly("perceptual_objective", &CompensationRun::perceptual_objective, "f in L*a*b*, whatever the method")
      .def_readonly("delta_e76", &CompensationRun::delta_e76, "(n,) ΔE76 per fine patch")
      .def_readonly("delta_e2000", &CompensationRun::delta_e2000, "(n,) CIEDE2000 per fine patch")
      .def_readonly("mean_delta_e76", &CompensationRun::mean_delta_e76, "area-weighted mean")
      .def_readonly("mean_delta_e2000", &CompensationRun::mean_delta_e2000, "area-weighted mean");

  m.def(
      "compensate_geometry",
      [](const GeometryStage& geometry, const SolverOptions& options, double alpha,
         const Eigen::MatrixX3d& lower, const Eigen::MatrixX3d& upper, const py::object& progress) {
        CompensationOptions run;
        run.solver = options;
        run.alpha = alpha;
        run.lower = lower;
        run.upper = upper;
        run.progress = PythonProgress(progress);
        std::string why;
        if (!run.Check(&why)) throw std::invalid_argument(why);
        py::gil_scoped_release release;
        return RunCompensation(geometry, run);
      },
      py::arg("geometry"), py::arg("options") = RecommendedSolverOptions(), py::arg("alpha") = 0.5,
      py::arg("lower") = Eigen::MatrixX3d(), py::arg("upper") = Eigen::MatrixX3d(),
      py::arg("progress") = py::none(),
      "Compensates `geometry`'s fine patches (with the coarse level for multires) within `lower` "
      "and "
      "`upper` (n,3) (empty: the scene's bounds). Releases the GIL while it runs.");
}

}  // namespace procam::python
