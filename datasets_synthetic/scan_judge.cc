#include "datasets_synthetic/scan_judge.h"

#include <fmt/format.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <numeric>
#include <random>

#include "calibration/registration.h"
#include "calibration/self_calibration.h"
#include "compensation/stage.h"
#include "datasets_synthetic/evaluation.h"
#include "datasets_synthetic/random_rooms.h"
#include "datasets_synthetic/scan_accuracy.h"
#include "datasets_synthetic/simulated_rig.h"
#include "geometry/ray_scene.h"
#include "geometry/scene_from_points.h"
#include "geometry/stage.h"
#include "projection/camera_rays.h"
#include "projection/projection_rig.h"

namespace procam {
namespace {

constexpr double kPi = 3.14159265358979323846;

double DistanceToSegment(const Vec3& p, const Vec3& a, const Vec3& b) {
  const Vec3 d = b - a;
  const double t = std::clamp(d.dot(p - a) / std::max(d.squaredNorm(), 1e-18), 0.0, 1.0);
  return (a + t * d - p).norm();
}

// Whether a surface's facets all lie in one plane (its first facet's), within `tolerance`.
bool Planar(const std::vector<const ModelFacet*>& facets, double cos_tolerance) {
  for (const ModelFacet* facet : facets)
    if (facet->normal.dot(facets.front()->normal) < cos_tolerance) return false;
  return true;
}

struct UnionFind {
  std::vector<int> parent;
  explicit UnionFind(int n) : parent(n) { std::iota(parent.begin(), parent.end(), 0); }
  int Find(int i) { return parent[i] == i ? i : parent[i] = Find(parent[i]); }
  void Join(int a, int b) { parent[Find(a)] = Find(b); }
};

double FacetArea(const ModelFacet& facet) {
  double area = 0.0;
  for (size_t k = 1; k + 1 < facet.corners.size(); ++k)
    area += 0.5 * (facet.corners[k] - facet.corners[0]).cross(facet.corners[k + 1] - facet.corners[0]).norm();
  return area;
}

Vec3 Centroid(const ModelFacet& facet) {
  Vec3 centroid = Vec3::Zero();
  for (const Vec3& corner : facet.corners) centroid += corner / facet.corners.size();
  return centroid;
}

// The camera's lens with its image scaled by `scale` (the same field of view).
CameraGeometry ScaledCamera(const CameraGeometry& camera, double scale) {
  std::vector<double> intrinsics = camera.intrinsics();
  intrinsics[0] *= scale;
  intrinsics[1] *= scale;
  intrinsics[2] = (intrinsics[2] + 0.5) * scale - 0.5;
  intrinsics[3] = (intrinsics[3] + 0.5) * scale - 0.5;
  return CameraGeometry(camera.lens_model(), intrinsics,
                        static_cast<int>(std::lround(camera.width() * scale)),
                        static_cast<int>(std::lround(camera.height() * scale)), camera.proj_from_world());
}

}  // namespace

void ScanJudgeOptions::Declare(OptionTable* table) {
  table->Number("camera-scale", &camera_scale, OptionTable::Interval::AboveMin(0.0, 1.0), "",
                "the camera's image scaled (same field of view)");
  DeclareSeedOption(table, "noise-seed", &noise_seed, "the decoding noise's seed")
      .Flag("compensate", &compensate,
            "also compensate on the true model and on the scan and compare their photographs")
      .Integer("patches", &patches, 20, 5000, "", "solver patches with --compensate");
}

bool ScanJudgeOptions::Check(std::string* why) const {
  const auto fail = [&](const std::string& text) {
    *why = text;
    return false;
  };
  if (!(camera_scale > 0.0 && camera_scale <= 1.0)) return fail("camera_scale must be in (0, 1]");
  if (pixel_step < 1) return fail("pixel_step must be at least 1");
  if (!(decoding_noise_px >= 0.0)) return fail("decoding_noise_px must be ≥ 0");
  if (!(min_seen_m2 >= 0.0)) return fail("min_seen_m2 must be ≥ 0");
  if (!(off_m > 0.0) || !(cell_m > 0.0)) return fail("off_m and cell_m must be > 0");
  if (!(found_share > 0.0 && found_share <= 1.0)) return fail("found_share must be in (0, 1]");
  if (patches < 20 || patches > 5000) return fail("patches must be in [20, 5000]");
  if (!(planar_rms_mm > 0.0 && curved_rms_mm > 0.0 && area_percent > 0.0 && spurious_percent > 0.0))
    return fail("the aims must be > 0");
  return true;
}

std::vector<std::vector<int>> PhysicalSurfaces(const Scene& scene) {
  const RoomModel model(scene);
  const int n = static_cast<int>(scene.surfaces.size());
  std::vector<std::vector<const ModelFacet*>> facets(n);
  for (const ModelFacet& facet : model.facets()) facets[facet.surface].push_back(&facet);
  const double cos_1deg = std::cos(kPi / 180.0);
  std::vector<bool> planar(n);
  for (int s = 0; s < n; ++s) planar[s] = !facets[s].empty() && Planar(facets[s], cos_1deg);
  UnionFind groups(n);
  for (int a = 0; a < n; ++a) {
    if (!planar[a]) continue;
    const ModelFacet& fa = *facets[a].front();
    for (int b = a + 1; b < n; ++b) {
      if (!planar[b]) continue;
      const ModelFacet& fb = *facets[b].front();
      if (fa.normal.dot(fb.normal) < cos_1deg || std::abs(fa.offset - fb.offset) > 0.005) continue;
      // Touching: a corner of one within 1 cm of an edge of the other.
      bool touching = false;
      for (const ModelFacet* x : facets[a])
        for (const ModelFacet* y : facets[b])
          for (const Vec3& corner : x->corners)
            for (size_t k = 0; k < y->corners.size() && !touching; ++k)
              touching = DistanceToSegment(corner, y->corners[k], y->corners[(k + 1) % y->corners.size()]) < 0.01;
      for (const ModelFacet* y : facets[b])
        for (const ModelFacet* x : facets[a])
          for (const Vec3& corner : y->corners)
            for (size_t k = 0; k < x->corners.size() && !touching; ++k)
              touching = DistanceToSegment(corner, x->corners[k], x->corners[(k + 1) % x->corners.size()]) < 0.01;
      if (touching) groups.Join(a, b);
    }
  }
  std::vector<std::vector<int>> out;
  std::vector<int> index_of_root(n, -1);
  for (int s = 0; s < n; ++s) {
    const int root = groups.Find(s);
    if (index_of_root[root] < 0) {
      index_of_root[root] = static_cast<int>(out.size());
      out.emplace_back();
    }
    out[index_of_root[root]].push_back(s);
  }
  return out;
}

bool ScanJudgement::PlanarRmsMet(const ScanJudgeOptions& options) const {
  return worst_planar_rms_mm <= options.planar_rms_mm;
}
bool ScanJudgement::CurvedRmsMet(const ScanJudgeOptions& options) const {
  return worst_curved_rms_mm <= options.curved_rms_mm;
}
bool ScanJudgement::AreaMet(const ScanJudgeOptions& options) const {
  return std::abs(worst_area_error_percent) <= options.area_percent;
}
bool ScanJudgement::CompensationMet(const ScanJudgeOptions& options) const {
  return scan_delta_e2000 - model_delta_e2000 <= options.delta_e2000 && scan_seam < options.seam;
}
bool ScanJudgement::SpuriousMet(const ScanJudgeOptions& options) const {
  return largest_spurious_percent <= options.spurious_percent;
}

std::string ScanJudgement::Report() const {
  std::string out = fmt::format("{}: {} scan points, {} of {} seen-and-lit surfaces found\n", room, scan_points,
                                found, expected);
  for (const PhysicalSurfaceJudgement& p : physical) {
    if (p.seen_and_lit_m2 <= 0.0 && p.scanned_m2 <= 0.0) continue;
    out += fmt::format("  true {}{}: seen and lit {:.3f} m², scanned {:.3f} m² ({:+.2f}%), {:.2f} mm RMS{}\n",
                       p.name, p.curved ? " (curved)" : "", p.seen_and_lit_m2, p.scanned_m2,
                       p.area_error_percent, p.rms_mm, p.expected ? "" : " (not expected)");
  }
  for (const ScannedSurfaceJudgement& s : scanned)
    out += fmt::format("  scanned {}: {:.3f} m², {:.2f} mm RMS, {:.3f} m² off the true room\n", s.name,
                       s.area_m2, s.rms_mm, s.off_m2);
  if (scan_delta_e2000 >= 0.0)
    out += fmt::format("  compensation photographed: mean CIEDE2000 {:.2f} on the model, {:.2f} on the scan ({:+.2f}), "
                       "seam on the scan {:.2f}\n",
                       model_delta_e2000, scan_delta_e2000, scan_delta_e2000 - model_delta_e2000, scan_seam);
  out += fmt::format(
      "  worst planar RMS {:.2f} mm, worst curved RMS {:.2f} mm, worst area {:+.2f}%, largest spurious "
      "{:.2f}% of {:.2f} m² ({:.1f} s)",
      worst_planar_rms_mm, worst_curved_rms_mm, worst_area_error_percent, largest_spurious_percent,
      room_seen_and_lit_m2, seconds);
  return out;
}

nlohmann::json ScanJudgement::Json() const {
  nlohmann::json physical_json = nlohmann::json::array();
  for (const PhysicalSurfaceJudgement& p : physical)
    physical_json.push_back({{"name", p.name},
                             {"curved", p.curved},
                             {"seen_and_lit_m2", p.seen_and_lit_m2},
                             {"expected", p.expected},
                             {"scanned_m2", p.scanned_m2},
                             {"rms_mm", p.rms_mm},
                             {"area_error_percent", p.area_error_percent}});
  nlohmann::json scanned_json = nlohmann::json::array();
  for (const ScannedSurfaceJudgement& s : scanned)
    scanned_json.push_back({{"name", s.name}, {"area_m2", s.area_m2}, {"off_m2", s.off_m2}, {"rms_mm", s.rms_mm}});
  return {{"room", room},
          {"calibrated", calibrated},
          {"calibration", calibration_report},
          {"scan_points", scan_points},
          {"expected", expected},
          {"found", found},
          {"worst_planar_rms_mm", worst_planar_rms_mm},
          {"worst_curved_rms_mm", worst_curved_rms_mm},
          {"worst_area_error_percent", worst_area_error_percent},
          {"largest_spurious_percent", largest_spurious_percent},
          {"room_seen_and_lit_m2", room_seen_and_lit_m2},
          {"model_delta_e2000", model_delta_e2000},
          {"scan_delta_e2000", scan_delta_e2000},
          {"scan_seam", scan_seam},
          {"seconds", seconds},
          {"physical_surfaces", physical_json},
          {"scanned_surfaces", scanned_json}};
}

ScanJudgement ScanAndJudge(const std::filesystem::path& scene_file, const ScanJudgeOptions& options) {
  std::string why;
  if (!options.Check(&why)) throw std::invalid_argument("scan judge: " + why);
  const auto start = std::chrono::steady_clock::now();
  const SyntheticRigSource source = LoadSceneFileRig(scene_file, "", options.patches);
  ScanJudgement judgement;
  judgement.room = scene_file.stem().string();

  // The rig, its camera scaled; the world mesh as coarse as will do (only the points each camera
  // pixel sees are used).
  SimulatedRigOptions rig_options;
  rig_options.solver_patches = 60;
  rig_options.world_factor = 1;
  const SimulatedRig rig(source.scene, source.projectors, ScaledCamera(source.camera, options.camera_scale),
                         rig_options);
  const Scene& truth_scene = rig.scene();
  const RoomModel truth(truth_scene);
  const RayScene rays(truth_scene);

  // The truth: physical surfaces, what of each the camera sees and a projector lights.
  std::vector<ProjectorGeometry> projectors;
  for (const Projector& p : rig.projectors()) projectors.push_back(p.geometry);
  const std::vector<std::vector<int>> groups = PhysicalSurfaces(truth_scene);
  std::vector<int> group_of_surface(truth_scene.surfaces.size());
  const double cos_1deg = std::cos(kPi / 180.0);
  for (size_t g = 0; g < groups.size(); ++g) {
    PhysicalSurfaceJudgement p;
    p.surfaces = groups[g];
    for (int s : groups[g]) {
      group_of_surface[s] = static_cast<int>(g);
      p.name += (p.name.empty() ? "" : " + ") + truth_scene.surfaces[s].name;
      p.seen_and_lit_m2 += SeenAndLitArea(truth, rays, s, rig.camera(), projectors, options.cell_m);
      std::vector<const ModelFacet*> facets;
      for (const ModelFacet& facet : truth.facets())
        if (facet.surface == s) facets.push_back(&facet);
      p.curved = p.curved || !Planar(facets, cos_1deg);
    }
    p.expected = p.seen_and_lit_m2 >= options.min_seen_m2;
    judgement.room_seen_and_lit_m2 += p.seen_and_lit_m2;
    judgement.physical.push_back(p);
  }

  // The correspondences: every pixel_step-th camera pixel whose point a projector lights
  // unoccluded, that projector's pixel of it plus decoding noise.
  RoomCalibrationProblem problem;
  problem.camera_lens_model = rig.camera().lens_model();
  problem.camera_intrinsics = rig.camera().intrinsics();
  std::mt19937_64 noise_engine(options.noise_seed);
  const auto gaussian = [&] {
    // Box–Muller on two explicit uniforms (portable, unlike std::normal_distribution).
    const double u1 = (static_cast<double>(noise_engine() >> 11) + 0.5) * 0x1.0p-53;
    const double u2 = static_cast<double>(noise_engine() >> 11) * 0x1.0p-53;
    return std::sqrt(-2.0 * std::log(u1)) * std::cos(2.0 * kPi * u2);
  };
  for (size_t k = 0; k < rig.projectors().size(); ++k) {
    const ProjectorGeometry& projector = rig.projectors()[k].geometry;
    ProjectorObservations observations;
    observations.name = rig.projectors()[k].name;
    observations.width = projector.width();
    observations.height = projector.height();
    for (int row = 0; row < rig.camera().height(); row += options.pixel_step)
      for (int col = 0; col < rig.camera().width(); col += options.pixel_step) {
        Vec3 point, normal;
        Vec2 pixel;
        if (!rig.PointSeenByPixel(row, col, &point, &normal)) continue;
        if (projector.Gain(point, normal, &pixel) <= 0.0 || !projector.InImage(pixel)) continue;
        if (rays.Occluded(point, projector.CentreInWorld(), 1e-4)) continue;
        const double du = options.decoding_noise_px * gaussian();
        const double dv = options.decoding_noise_px * gaussian();
        observations.camera_pixels.push_back(Vec2(col, row));
        observations.projector_pixels.push_back(pixel + Vec2(du, dv));
      }
    problem.projectors.push_back(observations);
  }

  SelfCalibrationOptions calibration_options;
  const Eigen::Isometry3d& cam_from_world = rig.camera().proj_from_world();
  calibration_options.camera_height = cam_from_world.inverse().translation().z();  // floor at z = 0
  const Vec3 true_up = cam_from_world.linear() * Vec3::UnitZ();
  if (options.chessboard_lens) {
    // The offsets of SelfCalibrateRoom's scan tests (about the chessboard's uncertainty).
    const double off[] = {0.15, -0.05, -0.1, 0.2, 1e-3, -4e-3, 1.5e-4, -5e-5};
    for (int i = 0; i < 8 && i < static_cast<int>(problem.camera_intrinsics.size()); ++i)
      problem.camera_intrinsics[i] += off[i];
    calibration_options.floor_normal_in_camera =
        Eigen::AngleAxisd(0.03 * kPi / 180.0, Vec3::UnitX()) * true_up;
  } else {
    calibration_options.floor_normal_in_camera = true_up;
  }
  RoomCalibration calibration;
  SelfCalibrationSummary summary;
  judgement.calibrated = SelfCalibrateRoom(calibration_options, problem, &calibration, nullptr, &summary);
  judgement.calibration_report = summary.BriefReport();
  const auto finish = [&] {
    judgement.expected = 0;
    for (const PhysicalSurfaceJudgement& p : judgement.physical) judgement.expected += p.expected;
    judgement.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    return judgement;
  };
  if (!judgement.calibrated) return finish();

  std::vector<Vec3> points_in_room;
  for (const TriangulatedPoint& point : TriangulateScan(problem, calibration))
    points_in_room.push_back(calibration.room_from_camera * point.p_in_cam);
  judgement.scan_points = static_cast<int>(points_in_room.size());
  SceneFromPointsOptions scene_options;
  scene_options.viewpoint = calibration.room_from_camera.translation();
  scene_options.points_on_viewpoint_rays = true;
  ScannedScene scan;
  try {
    scan = SceneFromPoints(points_in_room, scene_options);
  } catch (const std::invalid_argument& error) {
    judgement.calibrated = false;
    judgement.calibration_report += std::string("; SceneFromPoints: ") + error.what();
    return finish();
  }
  judgement.scan_report = scan.Report();

  // Each scanned facet, through the camera's pose, on the physical surface nearest its centroid.
  const RoomModel scanned(scan.scene);
  const Eigen::Isometry3d world_from_room = cam_from_world.inverse() * calibration.room_from_camera.inverse();
  std::vector<double> squares(groups.size(), 0.0);
  std::vector<int> samples(groups.size(), 0);
  judgement.scanned.resize(scan.scene.surfaces.size());
  std::vector<double> scanned_squares(scan.scene.surfaces.size(), 0.0);
  std::vector<int> scanned_samples(scan.scene.surfaces.size(), 0);
  for (size_t s = 0; s < scan.scene.surfaces.size(); ++s) judgement.scanned[s].name = scan.scene.surfaces[s].name;
  // Per scanned surface, its area on each physical surface (for the reflectance it takes).
  std::vector<std::vector<double>> area_on(scan.scene.surfaces.size(), std::vector<double>(groups.size(), 0.0));
  for (const ModelFacet& facet : scanned.facets()) {
    const double area = FacetArea(facet);
    Vec3 nearest;
    double distance = 0.0;
    const int at = truth.Closest(world_from_room * Centroid(facet), &nearest, &distance);
    const int g = group_of_surface[truth.facets()[at].surface];
    ScannedSurfaceJudgement& mine = judgement.scanned[facet.surface];
    mine.area_m2 += area;
    const bool off = distance > options.off_m;  // spurious: counted apart
    if (off) {
      mine.off_m2 += area;
    } else {
      judgement.physical[g].scanned_m2 += area;
    }
    area_on[facet.surface][g] += area;
    std::vector<Vec3> points = facet.corners;
    points.push_back(Centroid(facet));
    for (const Vec3& p : points) {
      truth.Closest(world_from_room * p, &nearest, &distance);
      scanned_squares[facet.surface] += distance * distance;
      ++scanned_samples[facet.surface];
      if (off) continue;
      squares[g] += distance * distance;
      ++samples[g];
    }
  }
  for (size_t s = 0; s < judgement.scanned.size(); ++s) {
    ScannedSurfaceJudgement& mine = judgement.scanned[s];
    mine.rms_mm = 1e3 * std::sqrt(scanned_squares[s] / std::max(1, scanned_samples[s]));
    judgement.largest_spurious_percent =
        std::max(judgement.largest_spurious_percent, 100.0 * mine.off_m2 / judgement.room_seen_and_lit_m2);
  }
  for (size_t g = 0; g < groups.size(); ++g) {
    PhysicalSurfaceJudgement& p = judgement.physical[g];
    p.rms_mm = samples[g] > 0 ? 1e3 * std::sqrt(squares[g] / samples[g]) : 0.0;
    if (p.seen_and_lit_m2 > 0.0) p.area_error_percent = 100.0 * (p.scanned_m2 / p.seen_and_lit_m2 - 1.0);
    if (!p.expected) continue;
    if (p.scanned_m2 >= options.found_share * p.seen_and_lit_m2) ++judgement.found;
    double& worst_rms = p.curved ? judgement.worst_curved_rms_mm : judgement.worst_planar_rms_mm;
    worst_rms = std::max(worst_rms, p.rms_mm);
    if (std::abs(p.area_error_percent) > std::abs(judgement.worst_area_error_percent))
      judgement.worst_area_error_percent = p.area_error_percent;
  }
  if (!options.compensate) return finish();

  // Compensation on the true model with the true rig, photographed in the true room.
  EvaluationOptions evaluation_options;
  evaluation_options.patches = options.patches;
  evaluation_options.methods = {CompensationMethod::kPerceptual};
  const SceneEvaluation evaluation = EvaluateSyntheticScene(scene_file.string(), evaluation_options);
  judgement.model_delta_e2000 = evaluation.methods.front().mean_delta_e2000;

  // On the scanned room: each surface with the reflectance of the true one it covers most, the
  // desired appearance carried through the camera (each patch the mean of the true desired
  // picture over the pixels that see it), the self-calibrated projectors with the true photometry.
  Scene scanned_scene = scan.scene;
  scanned_scene.target_patches = options.patches;
  for (size_t s = 0; s < scanned_scene.surfaces.size(); ++s) {
    const int g = static_cast<int>(std::max_element(area_on[s].begin(), area_on[s].end()) - area_on[s].begin());
    scanned_scene.surfaces[s].reflectance = truth_scene.surfaces[groups[g].front()].reflectance;
  }
  GeometryOptions geometry_options;
  geometry_options.patches = options.patches;
  GeometryStage geometry = RunGeometryStage(std::move(scanned_scene), geometry_options);
  const CameraGeometry& true_camera = evaluation.world->camera();
  const CameraGeometry camera_in_room(true_camera.lens_model(), true_camera.intrinsics(), true_camera.width(),
                                      true_camera.height(), calibration.room_from_camera.inverse());
  PatchLevel& fine = geometry.patches.fine;
  const CameraPixelRays pixel_rays = CastCameraPixels(geometry.scene, fine, {}, camera_in_room);
  Eigen::MatrixX3d sum = Eigen::MatrixX3d::Zero(fine.size(), 3);
  Eigen::VectorXd count = Eigen::VectorXd::Zero(fine.size());
  Vec3 mean = Vec3::Zero();
  int seen = 0;
  const cv::Mat& desired = evaluation.desired;
  for (int y = 0; y < std::min(pixel_rays.height, desired.rows); ++y)
    for (int x = 0; x < std::min(pixel_rays.width, desired.cols); ++x) {
      const cv::Vec3f& value = desired.at<cv::Vec3f>(y, x);
      const Vec3 rgb(value[0], value[1], value[2]);
      const int patch = pixel_rays.patch[static_cast<size_t>(y) * pixel_rays.width + x];
      if (patch < 0 || !(rgb.maxCoeff() > 0.0)) continue;
      sum.row(patch) += rgb.transpose();
      count[patch] += 1.0;
      mean += rgb;
      ++seen;
    }
  if (seen > 0) mean /= seen;
  for (int i = 0; i < fine.size(); ++i)
    fine.desired_linear.row(i) = count[i] > 0.0 ? Eigen::RowVector3d(sum.row(i) / count[i]) : mean.transpose();
  geometry.patches.coarse.desired_linear = CoarsenPatchValues(
      fine.desired_linear, fine.Areas(), geometry.patches.coarse_of_fine, geometry.patches.coarse.size());
  std::vector<Projector> calibrated;
  for (size_t k = 0; k < calibration.projectors.size(); ++k) {
    const RoomProjector& p = calibration.projectors[k];
    Projector projector = evaluation.world->projectors()[k];
    projector.geometry = ProjectorGeometry(p.lens_model, p.intrinsics, p.width, p.height, p.proj_from_room);
    calibrated.push_back(projector);
  }
  const ProjectionRig recovered = BuildProjectionRig(fine, calibrated, ProjectionRigOptions());
  CompensationOptions compensation;
  compensation.solver.method = CompensationMethod::kPerceptual;
  compensation.alpha = evaluation_options.alpha;
  compensation.lower = recovered.lower;
  compensation.upper = recovered.upper;
  MethodEvaluation on_scan;
  on_scan.run = RunCompensation(geometry, compensation);
  on_scan.images = RenderProjectorImages(recovered, on_scan.run.solution.emittance, evaluation_options.render,
                                         &on_scan.render);
  on_scan.radiance = evaluation.world->RenderRadiance(on_scan.images);
  PixelDeltaE(on_scan.radiance, evaluation, on_scan.run.fine.rgb_to_xyz, on_scan.run.fine.white_xyz, &on_scan);
  judgement.scan_delta_e2000 = on_scan.mean_delta_e2000;
  judgement.scan_seam = on_scan.seams.seam;
  return finish();
}

}  // namespace procam
