#include "datasets_synthetic/board_structured_light.h"

#include <cmath>
#include <numbers>
#include <random>
#include <stdexcept>

#include <opencv2/imgproc.hpp>

namespace procam {
namespace {

// Where a camera ray (in the camera's frame) meets the board's plane within one square around its
// printed area: the distance `t` along the ray and whether it lands on a dark square. False when
// it misses that area or meets the plane behind the camera.
bool HitBoard(const ChessboardSpec& board, const Eigen::Isometry3d& board_from_cam,
              const Vec3& ray_in_cam, double* t, bool* dark) {
  const Vec3 origin = board_from_cam.translation();
  const Vec3 ray = board_from_cam.linear() * ray_in_cam;
  *t = -origin.z() / ray.z();
  if (!(*t > 0.0)) return false;
  const Vec3 p = origin + *t * ray;
  const double square = board.square_size;
  const double u = p.x() / square + 1.0, v = p.y() / square + 1.0;  // from the board's edge
  if (!(u >= -1.0 && u < board.corners_x + 2.0 && v >= -1.0 && v < board.corners_y + 2.0))
    return false;
  const bool inside = u >= 0 && u < board.corners_x + 1 && v >= 0 && v < board.corners_y + 1;
  *dark = inside && ((static_cast<int>(u) + static_cast<int>(v)) % 2 == 0);
  return true;
}

// The projector pixel nearest `pixel` as an index into its image, or -1 outside the image.
int PixelIndex(const ProjectorGeometry& projector, const Vec2& pixel) {
  const int x = static_cast<int>(std::lround(pixel.x()));
  const int y = static_cast<int>(std::lround(pixel.y()));
  if (x < 0 || y < 0 || x >= projector.width() || y >= projector.height()) return -1;
  return y * projector.width() + x;
}

}  // namespace

BoardRig DefaultBoardRig() {
  BoardRig rig;
  rig.camera = ProjectorGeometry("LENSMODEL_OPENCV4", {1600.0, 1598.0, 641.3, 398.2, -0.08, 0.03,
                                                       0.0006, -0.0004},
                                 1280, 800, Eigen::Isometry3d::Identity());
  rig.projector = ProjectorGeometry("LENSMODEL_OPENCV4", {1500.0, 1503.0, 509.6, 700.4, 0.02,
                                                          -0.01, 0.0, 0.0},
                                    1024, 768, Eigen::Isometry3d::Identity());
  // The projector's centre 0.2 m right of the camera's, its axis toed in by 8° and tilted down by
  // 12°: its lens's centre sits near the image's bottom (cy), throwing the image upwards as a
  // projector's is, so the image's middle comes out about level and both devices see the same
  // region about 1 m away.
  Eigen::Isometry3d cam_from_projector = Eigen::Isometry3d::Identity();
  const double deg = std::numbers::pi / 180.0;
  cam_from_projector.linear() = (Eigen::AngleAxisd(-8.0 * deg, Vec3::UnitY()) *
                                 Eigen::AngleAxisd(-12.0 * deg, Vec3::UnitX()))
                                    .toRotationMatrix();
  cam_from_projector.translation() = Vec3(0.2, 0.03, -0.02);
  rig.projector_from_camera = cam_from_projector.inverse();
  return rig;
}

bool BoardRenderOptions::Check(std::string* why) const {
  if (!(dark_reflectance >= 0.0 && dark_reflectance <= 1.0 && light_reflectance >= 0.0 &&
        light_reflectance <= 1.0)) {
    *why = "board render: reflectances must be in [0, 1]";
    return false;
  }
  if (!(projector_gain > 0.0) || !(ambient >= 0.0) || !(blur_sigma_px >= 0.0) ||
      !(noise_sigma >= 0.0)) {
    *why = "board render: projector_gain > 0, ambient, blur_sigma_px and noise_sigma ≥ 0";
    return false;
  }
  if (supersample < 1 || supersample > 8) {
    *why = "board render: supersample must be in [1, 8]";
    return false;
  }
  return true;
}

std::vector<Eigen::Isometry3d> BoardRigPoses(const BoardRig& rig, const ChessboardSpec& board,
                                             int count, double distance) {
  struct Placement {
    double x, y, z, tilt_x_deg, tilt_y_deg, roll_deg;  // offsets in metres
  };
  const Placement placements[] = {
      {0.00, 0.00, 0.00, 30, 0, 0},       {-0.12, -0.06, -0.03, -30, 40, 5},
      {0.12, -0.06, 0.05, 35, -35, -10},  {-0.12, 0.06, 0.10, -40, -25, 15},
      {0.12, 0.06, -0.03, 40, 30, -20},   {0.00, 0.00, 0.15, 0, -45, 90},
      {0.00, 0.00, -0.10, 45, 10, 30},    {0.00, 0.00, 0.05, -25, -40, -30},
  };
  // Centre the poses where the projector's axis crosses the plane `distance` ahead of the camera.
  const Eigen::Isometry3d cam_from_projector = rig.projector_from_camera.inverse();
  const Vec3 projector_centre = cam_from_projector.translation();
  const Vec3 projector_axis =
      cam_from_projector.linear() *
      rig.projector.Unproject(Vec2((rig.projector.width() - 1) / 2.0,
                                   (rig.projector.height() - 1) / 2.0));
  const double along = (distance - projector_centre.z()) / projector_axis.z();
  const Vec3 centre = projector_centre + along * projector_axis;
  const Vec3 board_centre((board.corners_x - 1) * board.square_size / 2,
                          (board.corners_y - 1) * board.square_size / 2, 0.0);
  const double deg = std::numbers::pi / 180.0;
  std::vector<Eigen::Isometry3d> poses;
  for (int k = 0; k < count && k < 8; ++k) {
    const Placement& p = placements[k];
    Eigen::Isometry3d cam_from_board = Eigen::Isometry3d::Identity();
    cam_from_board.linear() = (Eigen::AngleAxisd(p.tilt_x_deg * deg, Vec3::UnitX()) *
                               Eigen::AngleAxisd(p.tilt_y_deg * deg, Vec3::UnitY()) *
                               Eigen::AngleAxisd(p.roll_deg * deg, Vec3::UnitZ()))
                                  .toRotationMatrix();
    cam_from_board.translation() =
        centre + Vec3(p.x, p.y, p.z) - cam_from_board.linear() * board_centre;
    poses.push_back(cam_from_board);
  }
  return poses;
}

std::vector<cv::Mat> RenderBoardUnderPatterns(const BoardRig& rig, const ChessboardSpec& board,
                                              const Eigen::Isometry3d& cam_from_board,
                                              const CaptureSequence& sequence,
                                              const BoardRenderOptions& options) {
  std::string why;
  if (!options.Check(&why) || !board.Check(&why)) throw std::invalid_argument(why);
  const ProjectorGeometry& camera = rig.camera;
  const ProjectorGeometry& projector = rig.projector;
  for (const Pattern& pattern : sequence.patterns) {
    if (pattern.image.cols != projector.width() || pattern.image.rows != projector.height())
      throw std::invalid_argument("board render: pattern " + pattern.name +
                                  " is not the projector's size");
  }
  // A camera `supersample` times finer with the same lens (chessboard_views.cc does the same).
  const int s = options.supersample;
  std::vector<double> fine = camera.intrinsics();
  for (int k = 0; k < 2; ++k) fine[k] *= s;
  for (int k = 2; k < 4; ++k) fine[k] = s * fine[k] + (s - 1) / 2.0;
  const ProjectorGeometry fine_camera(camera.lens_model(), fine, camera.width() * s,
                                      camera.height() * s, Eigen::Isometry3d::Identity());
  std::vector<Vec3> rays;
  std::vector<double> densities;
  fine_camera.UnprojectImage(&rays, &densities);

  // Every ray that meets the board: its camera pixel, the projector pixel lighting it (−1: none)
  // and the board's reflectance there. The rest of the view is empty (no light returns).
  struct Hit {
    int pixel;
    int projector_pixel;
    float reflectance;
  };
  std::vector<Hit> hits;
  const Eigen::Isometry3d board_from_cam = cam_from_board.inverse();
  for (int row = 0; row < fine_camera.height(); ++row) {
    for (int col = 0; col < fine_camera.width(); ++col) {
      const Vec3& ray_in_cam = rays[static_cast<size_t>(row) * fine_camera.width() + col];
      double t = 0.0;
      bool dark = false;
      if (!HitBoard(board, board_from_cam, ray_in_cam, &t, &dark)) continue;
      Vec2 projector_pixel;
      int lit = -1;
      if (projector.ProjectFromProj(rig.projector_from_camera * (t * ray_in_cam), &projector_pixel))
        lit = PixelIndex(projector, projector_pixel);
      hits.push_back({(row / s) * camera.width() + col / s, lit,
                      static_cast<float>(dark ? options.dark_reflectance
                                              : options.light_reflectance)});
    }
  }

  std::mt19937 random(options.seed);
  std::normal_distribution<float> noise(0.0f, static_cast<float>(options.noise_sigma));
  const float per_ray = 1.0f / static_cast<float>(s * s);
  std::vector<cv::Mat> images;
  for (const Pattern& pattern : sequence.patterns) {
    cv::Mat grey;
    cv::extractChannel(pattern.image, grey, 0);
    const uint8_t* light = grey.ptr<uint8_t>(0);
    cv::Mat image = cv::Mat::zeros(camera.height(), camera.width(), CV_32F);
    float* values = image.ptr<float>(0);
    for (const Hit& hit : hits) {
      const double projected =
          hit.projector_pixel < 0 ? 0.0 : options.projector_gain * light[hit.projector_pixel] / 255.0;
      values[hit.pixel] += per_ray * hit.reflectance * static_cast<float>(options.ambient + projected);
    }
    if (options.blur_sigma_px > 0.0)
      cv::GaussianBlur(image, image, cv::Size(0, 0), options.blur_sigma_px);
    if (options.noise_sigma > 0.0) {
      for (float& value : cv::Mat_<float>(image)) value += noise(random);
    }
    images.push_back(image);
  }
  return images;
}

BoardInRoom::BoardInRoom(const ProjectorGeometry& camera,
                         const std::vector<ProjectorGeometry>& projectors,
                         const ChessboardSpec& board, const Eigen::Isometry3d& cam_from_board,
                         double dark_reflectance, double light_reflectance, int supersample)
    : width_(camera.width()),
      height_(camera.height()),
      projector_count_(static_cast<int>(projectors.size())) {
  std::string why;
  if (!board.Check(&why)) throw std::invalid_argument(why);
  if (!(dark_reflectance >= 0.0 && light_reflectance <= 1.0 &&
        dark_reflectance <= light_reflectance))
    throw std::invalid_argument("board: reflectances must be 0 <= dark <= light <= 1");
  if (supersample < 1 || supersample > 8)
    throw std::invalid_argument("board: supersample must be in [1, 8]");
  const int s = supersample;
  per_ray_ = 1.0f / static_cast<float>(s * s);
  std::vector<double> fine = camera.intrinsics();
  for (int k = 0; k < 2; ++k) fine[k] *= s;
  for (int k = 2; k < 4; ++k) fine[k] = s * fine[k] + (s - 1) / 2.0;
  const ProjectorGeometry fine_camera(camera.lens_model(), fine, camera.width() * s,
                                      camera.height() * s, Eigen::Isometry3d::Identity());
  std::vector<Vec3> rays;
  std::vector<double> densities;
  fine_camera.UnprojectImage(&rays, &densities);
  const Eigen::Isometry3d board_from_cam = cam_from_board.inverse();
  const Eigen::Isometry3d world_from_cam = camera.proj_from_world().inverse();
  const Vec3 normal_in_world = -(world_from_cam.linear() * cam_from_board.linear().col(2));
  for (int row = 0; row < fine_camera.height(); ++row) {
    for (int col = 0; col < fine_camera.width(); ++col) {
      const Vec3& ray_in_cam = rays[static_cast<size_t>(row) * fine_camera.width() + col];
      double t = 0.0;
      bool dark = false;
      if (!HitBoard(board, board_from_cam, ray_in_cam, &t, &dark)) continue;
      pixel_.push_back((row / s) * width_ + col / s);
      reflectance_.push_back(static_cast<float>(dark ? dark_reflectance : light_reflectance));
      // The side facing the camera is lit; a projector behind the board gets gain 0.
      const Vec3 p_in_world = world_from_cam * (t * ray_in_cam);
      const Vec3 facing = normal_in_world.dot(world_from_cam.translation() - p_in_world) > 0.0
                              ? normal_in_world
                              : Vec3(-normal_in_world);
      for (const ProjectorGeometry& projector : projectors) {
        Vec2 pixel;
        const double gain = projector.Gain(p_in_world, facing, &pixel);
        int lit = -1;
        if (gain > 0.0) lit = PixelIndex(projector, pixel);
        lit_.push_back(lit);
        gain_.push_back(lit < 0 ? 0.0f : static_cast<float>(gain));
      }
    }
  }
}

cv::Mat BoardInRoom::RenderRadiance(const std::vector<cv::Mat>& outputs) const {
  if (static_cast<int>(outputs.size()) != projector_count_)
    throw std::invalid_argument("board: " + std::to_string(outputs.size()) + " outputs for " +
                                std::to_string(projector_count_) + " projectors");
  cv::Mat radiance = cv::Mat::zeros(height_, width_, CV_32FC3);
  cv::Vec3f* values = radiance.ptr<cv::Vec3f>(0);
  for (int k = 0; k < projector_count_; ++k) {
    if (outputs[k].empty()) continue;
    if (outputs[k].type() != CV_32FC3 || !outputs[k].isContinuous())
      throw std::invalid_argument("board: a projector's output must be continuous CV_32FC3");
    const cv::Vec3f* light = outputs[k].ptr<cv::Vec3f>(0);
    const size_t total = outputs[k].total();
    for (size_t ray = 0; ray < pixel_.size(); ++ray) {
      const size_t at = ray * projector_count_ + k;
      const int lit = lit_[at];
      if (lit < 0 || static_cast<size_t>(lit) >= total) continue;
      values[pixel_[ray]] += (per_ray_ * reflectance_[ray] * gain_[at]) * light[lit];
    }
  }
  return radiance;
}

}  // namespace procam
