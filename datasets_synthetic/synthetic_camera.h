#pragma once
// The simulated rig's camera behind the capture module's Camera interface: a
// "synthetic:<scene>" URI opens a camera that photographs the synthetic room (paper_scenes.h)
// lit by whatever each of its projectors' in-memory displays shows, so `procam capture` and the
// capture tests run real structured-light sessions without hardware.
//
//   synthetic:c_shaped?patches=300&format=BGR8&noise=1
//
// What real photographs have besides noise (test_camera.h, each off by default): projector
// defocus (`projector_blur`: applied to each projector's light before it lights the room,
// DefocusProjectorCodes), camera defocus (`camera_blur`), ambient light (`ambient`, a fraction of
// radiance 1), a non-linear response (`response_gamma`) and JPEG compression (`jpeg_quality`).
//
// A scene file with a "chessboard" (docs/scene_format.md) also holds a board in front of the
// camera: `board_pose=K` photographs the board at its pose K instead of the room — the board the
// only surface in view (BoardInRoom, board_structured_light.h), lit by the same projectors'
// displays — so that `procam capture` records the structured-light sessions of a board
// calibration (docs/chessboard.md).
//
// Keys: `patches` (the solver patch count the scene and the rig's world mesh are built for,
// [20, 5000], default 300; the world mesh is SimulatedRigOptions::world_factor = 4 times finer),
// `albedo` (SimulatedRigOptions::albedo_variation: the room's uneven paint, [0, 0.5), default 0)
// and every key of the test camera (test_camera.h: format, width, height, fps, buffers,
// exposure_us, reference_exposure_us, gain_db, black, noise, latency_ms, seed, fault, ...), with
// these defaults changed: width and height = the rig camera's, format BGR8 (the rig's camera
// sees colour). A width or height other than the rig camera's resamples its image (nearest
// neighbour, as the test camera does).
//
// The frame model is the test camera's (timing, buffering, read noise, quantisation, faults);
// what it photographs is SimulatedRig::RenderRadiance of the patterns on the projectors'
// displays at the frame's exposure start: exact direct light per camera pixel, bounces from the
// finer radiosity mesh. The rig's own exposure, vignetting and shot noise (PhotographLinear) are
// not applied: the test camera's exposure, gain and read noise take their place.
//
// Dependency: datasets_synthetic uses capture, never the other way round; the capture module
// only reserves the scheme until RegisterSyntheticCameraBackend() is called.

#include <atomic>
#include <filesystem>
#include <memory>
#include <string>
#include <vector>

#include "capture/camera.h"
#include "capture/display.h"
#include "capture/scene_cameras.h"
#include "capture/test_camera.h"
#include "datasets_synthetic/board_structured_light.h"
#include "datasets_synthetic/simulated_rig.h"

namespace procam {

// A synthetic room with its projectors and camera, and one in-memory display per projector:
// showing a pattern on displays[k] is projector k of the rig showing it.
struct SyntheticWorld {
  std::string scene;  // a name of SyntheticSceneNames(), or the scene file as the URI names it
  // The room as a scene text the pipeline loads (geometry/stage.h): "synthetic:NAME", or the
  // scene file's path.
  std::string scene_source;
  int patches = 0;    // solver patch count the scene and the rig were built for
  // The camera's settings before a URI's keys override them: TestCameraOptions' defaults with
  // the rig camera's size and BGR8 (a built-in scene), or the scene file's camera entry.
  TestCameraOptions camera_settings;
  // A tape-measure guess of the camera's pose, "x,y,z,look_x,look_y,look_z": its position
  // rounded to 5 cm and a point 3 m ahead of it (built-in scenes: the point it aims at) rounded
  // to 25 cm.
  std::string camera_guess;
  std::shared_ptr<const SimulatedRig> rig;
  // One per rig projector, same order; resolution = the projector's width × height, named
  // "synthetic:<scene>/<projector name>".
  std::vector<std::shared_ptr<MemoryDisplay>> displays;
  // Radiance scale of the camera's SceneView: view = RenderRadiance × radiance_scale, with
  // radiance_scale = 1 / (the largest channel value of RenderRadiance when every projector shows
  // full white), computed once when the world is built. So 1.0 is the brightest any pixel gets
  // (no hot spot sets it: in tiny_box and c_shaped the 99.9th percentile is within 2% of it); no
  // pattern clips at the test camera's reference exposure; one projector's full white reads
  // well below 1 (tiny_box: about 0.4 where it lights the walls, nearly half of it bounce light).
  double radiance_scale = 1.0;
  // RenderRadiance calls made by the SceneViews of this world (frames of one pattern share one
  // render; see MakeSyntheticView).
  mutable std::atomic<int> renders{0};
  // With a board pose (PlaceSceneChessboard): the board the camera photographs instead of the
  // room, and which pose of the scene file's chessboard it is (−1: none, the room).
  std::shared_ptr<const BoardInRoom> board;
  int board_pose = -1;
};

// Puts pose `pose` of the scene file's "chessboard" (scene_files.h) in front of the world's
// camera: from then on its SceneViews photograph that board, alone, lit by the displays, and
// radiance_scale is the board's (1: its brightest pixel with every projector at full white).
// Throws IoError naming the file and key: no chessboard key, a pose out of range.
void PlaceSceneChessboard(SyntheticWorld* world, const std::filesystem::path& scene_file, int pose);

// Builds the world of a synthetic scene: MakeSyntheticScene(scene, patches), projectors and
// camera from its placements (ProjectorFromPlacement, CameraFromPlacement with distortion), the
// rig (SimulatedRigOptions with solver_patches = patches), one display per projector and the
// radiance scale (one full-white render). At 300 patches this takes about 1 s for tiny_box and
// 1.4 s for c_shaped on two cores. Throws std::invalid_argument naming the scene when it is
// unknown or patches is outside [20, 5000].
std::shared_ptr<SyntheticWorld> MakeSyntheticWorld(const std::string& scene, int patches = 300,
                                                   double albedo_variation = 0.0);
// What a synthetic rig is built from: the scene, its projectors and its camera.
struct SyntheticRigSource {
  Scene scene;
  std::vector<Projector> projectors;
  CameraGeometry camera;
  SceneCamera camera_entry;  // a scene file's camera entry (name, settings); empty otherwise
};

// A scene file's rig (docs/scene_format.md): its surfaces with patch target `patches`, its
// projectors as written and its camera `camera` (a name of its cameras; "" = the first). Throws
// IoError naming the file and key (a scene without projectors or cameras, an unknown camera
// name), std::invalid_argument for patches outside [20, 5000].
SyntheticRigSource LoadSceneFileRig(const std::filesystem::path& scene_file,
                                    const std::string& camera, int patches);

// A built-in scene's rig (MakeSyntheticScene, its placements as MakeSyntheticWorld takes them) or,
// for a path ending in .json, a scene file's with its first camera (LoadSceneFileRig). Throws
// std::invalid_argument for an unknown scene, as LoadSceneFileRig for a scene file.
SyntheticRigSource LoadSyntheticRig(const std::string& scene, int patches);

// The world of a scene file with `projectors` and `cameras` (docs/scene_format.md): the scene's
// surfaces, its projectors as written (models and photometry), and its camera `camera` (a name
// of its cameras; "" = the first) with the entry's settings; the rest as MakeSyntheticWorld.
// `uri_path` names the world (SyntheticWorld::scene). Throws IoError naming the file and key
// (a scene without projectors or cameras, an unknown camera name), std::invalid_argument for
// patches outside [20, 5000].
std::shared_ptr<SyntheticWorld> MakeSceneFileWorld(const std::filesystem::path& scene_file,
                                                   const std::string& camera, int patches = 300,
                                                   double albedo_variation = 0.0,
                                                   const std::string& uri_path = "");

// The SceneView (camera.h) of the world's camera: for an exposure start time, the radiance of
// what every display shows at that time (MemoryDisplay::ShownAt; 8-bit grey or B, G, R
// patterns become projector codes, R, G, B, scaled to the projector's bits; a display that has
// shown nothing shows black), as CV_32FC3 B, G, R scaled by world->radiance_scale, at the rig
// camera's resolution. The last render is cached, keyed by the patterns shown (same buffer or
// same pixels), so the frames of one pattern render once. Thread-safe. With projector_blur_px
// > 0 each projector's codes pass through DefocusProjectorCodes first (the projectors' defocus).
// Throws std::invalid_argument when `world` is empty or its displays do not match its projectors.
SceneView MakeSyntheticView(std::shared_ptr<const SyntheticWorld> world,
                            double projector_blur_px = 0.0);

// A defocused projector: the light of `codes` (each channel's response, ResponseCurve::Light)
// blurred by a Gaussian of σ = sigma_px projector pixels — nothing beyond the image's edge — and
// turned back into codes: the drive that emits the blurred light (ResponseCurve::Drive),
// rounded to the nearest code. Blurring the light of each primary is blurring the output, which
// is affine in it (colour mixing is linear); going back to codes lets the rig render it as any
// image. The rounding costs at most half a code step of light (gamma 2.2, 8 bits: under 0.45%
// of full white), less than the camera's own 8-bit step. `codes` itself when sigma_px is 0.
ProjectorImage DefocusProjectorCodes(const ProjectorImage& codes, const Projector& projector,
                                     double sigma_px);

// The world's camera value per unit exitance (the scale calibrate all needs of a camera) for a
// single exposure: radiance_scale · full scale · exposure / the camera's reference exposure ·
// 10^(gain/20).
double CameraValuePerExitance(const SyntheticWorld& world, const TestCameraOptions& camera, double exposure_us,
                              double gain_db, double full_scale);

// The world a "synthetic:" URI names: its path is a built-in scene's name or a scene file
// (ending in .json, relative to the working directory); its keys `patches`, `albedo` and, for a
// scene file, `camera` (which of its cameras) and `board_pose` (PlaceSceneChessboard) are read,
// other keys are left unread.
// Worlds are shared while alive: opening the same scene and patch count again, while a camera
// or caller still holds the world, returns the same world — so the capture command shows its
// patterns on the displays the camera looks at. Throws IoError naming the URI: not a synthetic
// URI, unknown scene (the message lists the scenes), or a bad `patches`.
std::shared_ptr<SyntheticWorld> OpenSyntheticWorld(const CameraUri& uri);

// The test camera looking at a synthetic world; reports itself as "synthetic:<scene>" (backend
// "synthetic") so capture sessions name the scene they photographed.
// A display's 8-bit pattern (CV_8UC1 grey or CV_8UC3 B, G, R) as the codes the projector
// shows (R, G, B at the projector's bit depth, rounded). Throws std::invalid_argument naming
// the projector when the size or type does not fit.
ProjectorImage CodesFromPattern(const cv::Mat& pattern, const Projector& projector);

class SyntheticCamera : public TestCamera {
 public:
  // options.projector_blur_px defocuses the world's projectors (MakeSyntheticView), the rest of
  // the options are the test camera's. Throws std::invalid_argument when options.Check() fails
  // or world is empty.
  SyntheticCamera(const TestCameraOptions& options, std::shared_ptr<SyntheticWorld> world);

  CameraInfo Info() const override;
  const std::shared_ptr<SyntheticWorld>& world() const { return world_; }

 private:
  std::shared_ptr<SyntheticWorld> world_;
};

// The "synthetic" backend: opens SyntheticCameras (OpenCameraOptions::scene_view is ignored:
// the world is the view) and, with ListCamerasOptions::include_virtual, lists one camera per
// synthetic scene.
CameraBackend SyntheticCameraBackend();
// Registers SyntheticCameraBackend() with the camera registry. Further calls do nothing.
void RegisterSyntheticCameraBackend();
// The synthetic world as the product reaches it, through registries: the "synthetic" camera
// backend and the "synthetic" scene source (synthetic:NAME, geometry/stage.h; patch target 1000
// until a stage overrides it). Called by the command line, tests and benchmarks; the libraries
// never include datasets_synthetic. Further calls do nothing.
void RegisterSyntheticWorld();

}  // namespace procam
