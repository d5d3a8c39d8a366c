#pragma once
// Simulated cameras as the product reaches them: what the pipeline needs of a camera that only
// a simulation can tell (the displays its world shows projector images on, its colour
// calibration), registered per URI scheme by the simulation itself. The synthetic world
// (datasets_synthetic) registers "synthetic"; a URI of any other scheme is a real camera, whose
// colour calibration comes from the rig (rig.json camera.colour) or the user.

#include <Eigen/Core>
#include <filesystem>
#include <functional>
#include <memory>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <vector>

#include "capture/display.h"

namespace procam {

// Camera colour calibration: exitance (working RGB, scene units) = to_exitance · (camera RGB −
// black) for single exposures; HDR merges have the black removed already.
struct CameraColour {
  Eigen::Matrix3d to_exitance = Eigen::Matrix3d::Identity();
  double black = 0.0;
  std::string source;  // where it came from, for result.json
  nlohmann::json Json() const;
};

// What verification needs of a simulated camera that it cannot read off a real one: the
// displays its world shows the projectors' images on, and its colour calibration for a photo
// taken with a session's settings (`manifest`: session.json; `hdr`: bracketed exposures merged;
// `full_scale`: the frames' full scale; `black_override` ≥ 0: the black level to assume).
struct SimulatedCamera {
  std::string description;                   // for messages, e.g. "synthetic scene 'tiny_box'"
  std::vector<std::string> projector_names;  // one per display
  std::vector<std::shared_ptr<PatternDisplay>> displays;
  double black_level = 0.0;  // the camera's black level, DN (what the HDR merge subtracts)
  // Its colour calibration: camera value per unit exitance k per channel for a photo taken
  // with the session's settings, `black` the black level assumed (the HDR merge's scale
  // depends on it).
  std::function<Eigen::Vector3d(const nlohmann::json& manifest, bool hdr, double full_scale,
                                double black)>
      value_per_exitance;
  // What a whole-rig calibration needs: the room the camera looks at (a scene text such as
  // "synthetic:c_shaped", geometry/stage.h) and its patch target; a tape-measure guess of the
  // camera's pose ("x,y,z,look_x,look_y,look_z" in the room, metres); and chessboard photos of
  // the camera (a board of corners_x × corners_y inner corners, `square` metres, held in several
  // poses), written as PNGs into `folder`, returning how many.
  std::string scene;
  int patches = 0;
  std::string camera_guess;
  std::function<int(int corners_x, int corners_y, double square,
                    const std::filesystem::path& folder)>
      render_chessboard;
  // A photo (written to `file`, a PNG) of a board of corners_x × corners_y inner corners lying
  // flat on the floor in the camera's view, taken from the camera's pose: the metric scale of a
  // scan (calibration/floor_chessboard.h); returns the board's square size, metres (sized to the
  // camera's view, as a user would pick a board large enough to see).
  std::function<double(int corners_x, int corners_y, const std::filesystem::path& file)>
      render_floor_chessboard;
};
// For camera URIs of `scheme`: the simulated camera behind a URI, or an IoError naming it. The
// synthetic world registers "synthetic"; a URI of any other scheme is a real camera.
using SimulatedCameraSource = std::function<SimulatedCamera(const std::string& camera_uri)>;
void RegisterSimulatedCameraSource(const std::string& scheme, SimulatedCameraSource source);

// A simulated camera's colour calibration as verification applies it: to_exitance = diag(1/k),
// black = the black level (`black_override` ≥ 0, else the camera's; 0 for HDR merges, which
// removed it).
CameraColour SimulatedColour(const SimulatedCamera& camera, const nlohmann::json& manifest, bool hdr,
                             double full_scale, double black_override);

// The simulated camera behind `camera_uri` when its scheme has a registered source (which throws
// IoError naming the URI when it cannot open it); nullopt for any other camera.
std::optional<SimulatedCamera> FindSimulatedCamera(const std::string& camera_uri);

}  // namespace procam
