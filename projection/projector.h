#pragma once
// Projector models: geometry (an mrcal lens model with its intrinsics, image size and pose) and
// photometry (black level, maximum brightness, response curve, colour mixing).
//
// Conventions, stated once for the whole projection module:
// - Pixel coordinates q = (x, y) in pixels, x to the right, y down, with the CENTRE of the
//   top-left pixel at (0, 0): pixel (column c, row r) covers [c − ½, c + ½] × [r − ½, r + ½]
//   and is row r, column c of the projector's image. This is mrcal's (and OpenCV's) convention.
// - Projector frame: origin at the projection centre, x right, y down, z forward (out of the
//   lens), metres. `proj_from_world` maps world points into it: p_in_proj = proj_from_world ·
//   p_in_world (COLMAP naming). mrcal's `rt_cam_ref` appears only inside the mrcal adapter
//   (base/camera_model.h), with ref = world.
// - Light: "output" is linear working RGB (the scene's radiosity units, sRGB/Rec. 709
//   primaries by default) measured as the IRRADIANCE a projector delivers on a plane
//   perpendicular to its optical axis, 1 m in front of it, where the axis meets that plane.
//   Every pixel of one projector carries the same flux for the same drive (no vignetting), so
//   a pixel's irradiance on a surface point x is output · g(x) with the geometric gain
//   g(x) = (density(x) / density(axis)) · cos θ / d² (1/m²), density = pixels per steradian
//   of the lens in x's direction, θ the incidence angle, d the distance (see Gain()).

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <array>
#include <filesystem>
#include <memory>
#include <string>
#include <vector>

#include "base/camera_model.h"
#include "geometry/scene.h"

namespace procam {

// A projector's lens, image size and pose. Immutable once made; cheap to copy (the parsed
// lens model is shared). Thread-safe.
class ProjectorGeometry {
 public:
  // A placeholder: a 1×1 pinhole at the world origin (fx = fy = 1); assign a real one.
  ProjectorGeometry();
  // `lens_model` is an mrcal lens-model name with its configuration, e.g. "LENSMODEL_PINHOLE",
  // "LENSMODEL_OPENCV8", "LENSMODEL_SPLINED_STEREOGRAPHIC_order=3_Nx=16_Ny=12_fov_x_deg=50";
  // `intrinsics` in mrcal's order (fx, fy, cx, cy, then the distortion parameters, pixels).
  // Throws std::invalid_argument (one line) for an unknown or unsupported model (CAHVORE cannot
  // be unprojected), a wrong number of intrinsics, non-finite values, or a size < 1.
  ProjectorGeometry(const std::string& lens_model, std::vector<double> intrinsics, int width,
                    int height, const Eigen::Isometry3d& proj_from_world);
  // A pinhole projector: focal lengths and principal point in pixels.
  static ProjectorGeometry Pinhole(double fx, double fy, double cx, double cy, int width,
                                   int height, const Eigen::Isometry3d& proj_from_world);

  const std::string& lens_model() const { return lens_.name(); }
  const std::vector<double>& intrinsics() const { return lens_.intrinsics(); }
  int width() const { return width_; }
  int height() const { return height_; }
  const Eigen::Isometry3d& proj_from_world() const { return proj_from_world_; }
  // As a .cameramodel (the reference frame is the world), and back (throws as the constructor).
  CameraModel Model() const;
  static ProjectorGeometry FromModel(const CameraModel& model);
  Vec3 CentreInWorld() const { return proj_from_world_.inverse().translation(); }

  // Pixel of a point in the projector frame (metres); false when the point is not in front of
  // the lens (z ≤ 0). The pixel may lie outside the image (see InImage()). With `density`, also
  // the lens's pixels per steradian in the point's direction.
  bool ProjectFromProj(const Vec3& p_in_proj, Vec2* pixel, double* density = nullptr) const;
  bool Project(const Vec3& p_in_world, Vec2* pixel, double* density = nullptr) const;
  // True when the pixel coordinate falls on the image: −½ ≤ x < width − ½, same for y.
  bool InImage(const Vec2& pixel) const;

  // Unit directions in the projector frame of `count` pixel coordinates (mrcal_unproject).
  void Unproject(const Vec2* pixels, int count, Vec3* directions_in_proj) const;
  Vec3 Unproject(const Vec2& pixel) const;
  // Unit directions of every pixel centre, row-major (height × width entries), and the pixel
  // density in each direction. Computed by unprojecting a coarse grid exactly and refining
  // bilinear interpolation between its nodes with Newton steps on the forward projection, so it
  // is as exact as mrcal_unproject (reprojection error < 1e-8 px) and several times faster.
  void UnprojectImage(std::vector<Vec3>* directions_in_proj, std::vector<double>* densities) const;

  // Pixels per steradian of the lens at a unit direction in the projector frame, and on the
  // optical axis (0, 0, 1): the ratio is how much brighter an off-axis ray is (Gain()).
  double PixelDensity(const Vec3& direction_in_proj) const;
  double AxisPixelDensity() const { return axis_density_; }

  // Geometric gain g (1/m²) at a world point with unit surface normal: output · g is the
  // irradiance there (header comment). 0 if the point is behind the projector or the surface
  // faces away; does not check the image bounds or occlusion.
  double Gain(const Vec3& p_in_world, const Vec3& normal, Vec2* pixel = nullptr) const;

 private:
  LensModel lens_;
  int width_ = 0, height_ = 0;
  Eigen::Isometry3d proj_from_world_ = Eigen::Isometry3d::Identity();
  double axis_density_ = 1.0;
};

// The pose of a projector at `centre` (world, metres) whose optical axis points at `target`,
// with image "up" (−y) as close to `up` as possible. Throws std::invalid_argument if the axis is
// parallel to `up` or centre = target.
Eigen::Isometry3d ProjFromWorldLookingAt(const Vec3& centre, const Vec3& target, const Vec3& up);

// Reads an mrcal .cameramodel file (through libmrcal). Throws IoError naming the file.
ProjectorGeometry ReadCameraModel(const std::filesystem::path& path);
// Writes an mrcal .cameramodel file atomically, every number with 17 significant digits so
// that write → read is lossless (mrcal 2.2's own C writer prints 6 decimals). The text is
// parsed back by libmrcal before it is written. Throws IoError.
void WriteCameraModel(const std::filesystem::path& path, const ProjectorGeometry& geometry);
// The .cameramodel text WriteCameraModel writes.
std::string CameraModelText(const ProjectorGeometry& geometry);

// A projector's response: drive d in [0,1] (code value / (2^bits − 1)) → relative light r in
// [0,1], strictly increasing, r(0) = 0, r(1) = 1 (black level and maximum carry the absolute
// levels). A power law r = d^gamma or a measured table at evenly spaced drives, linearly
// interpolated; both invertible.
class ResponseCurve {
 public:
  ResponseCurve() = default;  // gamma 2.2
  // gamma > 0 (1 is linear). Throws std::invalid_argument otherwise.
  static ResponseCurve Gamma(double gamma);
  // Light at drives 0, 1/(m−1), ..., 1; m ≥ 2, finite and strictly increasing. Normalised to
  // run from 0 to 1 (first value subtracted, then divided by the range). Throws
  // std::invalid_argument otherwise.
  static ResponseCurve Table(const std::vector<double>& light);

  double Light(double drive) const;  // r(d); d clamped to [0,1]
  double Drive(double light) const;  // r⁻¹(r); r clamped to [0,1]
  bool is_table() const { return !table_.empty(); }
  double gamma() const { return gamma_; }
  const std::vector<double>& table() const { return table_; }

 private:
  double gamma_ = 2.2;
  std::vector<double> table_;  // normalised; empty for a power law
};

// Photometric model, per pixel: output(d) = black + diag(max − black) · mixing · r(d), where
// r(d) applies each channel's response to the drive d ∈ [0,1]³ (projector RGB) and output is
// working linear RGB (units in the header comment). `mixing` says how much each projector
// primary adds to each working channel; its rows sum to 1, so full white gives exactly `max`.
// Because of mixing, the colours a projector reaches are a parallelepiped inside the box
// [black, max]; the solver's per-channel bounds use the box, and renderers clip to the
// parallelepiped.
struct ProjectorPhotometry {
  Vec3 black = Vec3::Zero();  // output at drive 0, each ≥ 0
  Vec3 max = Vec3::Ones();    // output at drive (1,1,1), each > black
  std::array<ResponseCurve, 3> response;
  Eigen::Matrix3d mixing = Eigen::Matrix3d::Identity();  // entries ≥ 0, rows sum to 1
  int bits = 8;  // code values per channel: 8 (0..255) or 10 (0..1023)

  // Empty if consistent; otherwise one line naming the field.
  std::string Validate() const;
  int MaxCode() const { return (1 << bits) - 1; }
  Vec3 Output(const Vec3& drive) const;
  // Drive whose output is `output`, clipped to [0,1]³ when outside the reachable set;
  // `clipped` (optional) says whether it was.
  Vec3 DriveFor(const Vec3& output, bool* clipped = nullptr) const;
};

struct Projector {
  std::string name;
  std::filesystem::path model_path;  // the .cameramodel it was read from (may be empty)
  ProjectorGeometry geometry;
  ProjectorPhotometry photometry;
};

// The scene's "projectors" array (format: docs/scene_format.md, section Projectors), model
// paths resolved against the scene file. Empty when the scene has none. Throws IoError naming
// the scene file and the key, e.g. "room.json: projectors[1].max: each value must be greater
// than black".
std::vector<Projector> ReadProjectors(const Scene& scene);
// Parses a "projectors" JSON array (text) as if it were in `scene_file`, with model paths
// relative to `base`. Same errors as ReadProjectors.
std::vector<Projector> ParseProjectors(const std::string& projectors_json,
                                       const std::string& scene_file,
                                       const std::filesystem::path& base);

}  // namespace procam
