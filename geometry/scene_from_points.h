#pragma once
// The room from its own scan: a scene (geometry/scene.h) built from a triangulated point cloud.
//
// Input: points on the room's surfaces in the room frame (metres, z up), with noise of a few
// millimetres, as structured light decodes them (one point per decoded camera pixel), and the
// point they were seen from (the camera's centre). Output: planar surfaces as polygons with their
// outlines and holes, neighbouring planes meeting at exact edges, and what is not planar (curved
// walls, columns) as triangle meshes. The method (docs/scan.md), each step a CGAL algorithm:
//
//  1. Normals by PCA over each point's k nearest neighbours (CGAL pca_estimate_normals).
//  2. Planar regions by region growing over the k-nearest-neighbour graph (CGAL
//     Shape_detection::Region_growing with Least_squares_plane_fit_region: a point joins when it
//     is within plane_distance of the region's least-squares plane and its normal within
//     plane_angle_deg of the plane's). Points left between regions at edges are given to a
//     neighbouring region whose plane is within plane_distance of them.
//  3. Curved or planar: a region is curved when a quadratic height field over its plane fits its
//     points better than the plane by more than curvature_tolerance (RMS); a planar region that
//     meets a curved one, or another planar one, at less than smooth_angle_deg (a faceted curve)
//     is curved too. Adjacent planar regions on one plane (normals within coplanar_angle_deg,
//     offsets within plane_distance) are merged. What is then left unplanar (curved regions and
//     points no region took), in connected groups: a group flat by the same quadratic test with
//     an RMS to its plane of at most noisy_plane_rms is a plane seen through more noise than
//     region growing allows for (a far wall triangulated along its normal) and becomes one.
//  4. Outlines: the regularised alpha shape of each plane's points in the plane (CGAL
//     Alpha_shape_2; radius outline_alpha_spacings × the points' spacing 1/√density, or 1.5 × the
//     reach of their 12 nearest neighbours where a grazing view leaves rows far apart), its
//     boundary cycles as the outer polygons and holes, simplified to outline_tolerance (CGAL
//     Polyline_simplification_2, topology kept); with points_on_viewpoint_rays, each point taken
//     where its ray meets the plane, and simplified again as seen from the viewpoint, within 1.5
//     pixels (a free edge seen at a grazing angle is a sawtooth on the plane, a staircase one
//     pixel deep in the image). The outermost points lie inside the true edge: each edge moves
//     out by the expected gap, half the depth spacing of the points along it, leaning as the
//     points along it do.
//  5. Edges: outline vertices within snap_distance of the line where the plane meets a
//     neighbouring plane are moved onto that line; vertices near two such lines onto the point
//     where the three planes meet, so neighbouring polygons share their edges exactly. Beside
//     such a point, an outline that stops short of it within max_notch_deg seen from the
//     viewpoint (pixels that decoded nothing by the corner of two walls) is run on to it, unless
//     points seen through the area gained show an opening, or points in front of it hide it.
//  6. Meshes: curved regions and points no plane took, in connected groups, smoothed (CGAL
//     jet_smooth_point_set), thinned to one point per mesh_vertex_spacing cell (CGAL
//     grid_simplify_point_set) and meshed by advancing-front surface reconstruction (CGAL
//     Advancing_front_surface_reconstruction); each triangle faces the viewpoint. Then, before
//     step 5's snapping, outline vertices within snap_distance of a mesh move onto the mesh's
//     nearest point (seen along the plane's normal; CGAL AABB_tree): where a floor meets a
//     curved wall or a column, its outline follows the surface it meets.
//
// Planar polygons become scene surfaces: a convex 4-corner polygon without holes a quad, any other
// polygon (holes, more corners) a mesh triangulated by a constrained Delaunay triangulation (CGAL
// Polygon_triangulation_decomposition_2). Every surface faces the viewpoint (its lit side).

#include <filesystem>
#include <limits>
#include <string>
#include <vector>

#include "base/vector.h"
#include "geometry/scene.h"

namespace procam {

struct SceneFromPointsOptions {
  // Where the points were seen from (the camera's centre), room frame, metres: every surface's
  // lit side faces it. NaN (default): the centre of the cloud's bounding box, right for a room
  // scanned from inside but not for the outward faces of a column.
  Vec3 viewpoint = Vec3::Constant(std::numeric_limits<double>::quiet_NaN());
  // Each point lies on the ray from `viewpoint` through its camera pixel, its error along that
  // ray (a camera's triangulated pixels): the outlines then take each point where its ray meets
  // its plane, not its foot on the plane. Seen at a grazing angle, a few millimetres of error
  // along the ray put a point centimetres along the plane. Needs `viewpoint`.
  bool points_on_viewpoint_rays = false;
  int normal_neighbors = 24;      // k of the PCA normals, ≥ 6
  int growing_neighbors = 12;     // k of the region-growing graph, ≥ 4
  double plane_distance = 0.01;   // a plane's points are within this of it, metres, > 0 (≈ 4σ)
  double plane_angle_deg = 25.0;  // and their normals within this of its normal, (0, 90)
  int min_plane_points = 200;     // a plane has at least this many points, ≥ 3
  // A region is curved when sqrt(plane RMS² − quadratic RMS²) exceeds this, metres, > 0.
  double curvature_tolerance = 0.002;
  // Points left unplanar (too noisy for plane_distance and plane_angle_deg: a far wall
  // triangulated along its normal) whose connected group is flat by the same test, its RMS to
  // its plane at most this, become a plane instead of a mesh, metres, ≥ 0 (0: never).
  double noisy_plane_rms = 0.02;
  double smooth_angle_deg = 15.0;   // regions meeting at less than this are one curved surface
  double coplanar_angle_deg = 3.0;  // adjacent regions within this are one plane, [0, smooth)
  double outline_alpha_spacings = 2.5;  // alpha-shape radius in mean point spacings, > 0.5
  double outline_tolerance = 0.01;  // outline simplification: largest deviation, metres, > 0
  double snap_distance = 0.04;      // vertices this close to a neighbour's edge line snap, m, ≥ 0
  // Notches: where a plane's outline retreats from the edge it shares with a neighbour by no more
  // than this angle seen from the viewpoint, the edge runs straight along the line, or through the
  // point where three planes meet, unless points are seen through the notch or in front of it,
  // degrees, [0, 90) (0: none filled).
  double max_notch_deg = 3.0;
  double min_hole_area = 0.01;      // smaller holes in an outline are filled, m², ≥ 0
  double min_surface_area = 0.02;   // smaller polygons and meshes are left out, m², ≥ 0
  int min_mesh_points = 300;        // smaller groups of non-planar points are left out, ≥ 3
  int smoothing_neighbors = 24;     // k of the jet smoothing before meshing, ≥ 6 (0: none)
  double mesh_vertex_spacing = 0.02;  // meshes keep one smoothed point per cell this wide, m, ≥ 0
                                      // (0: every point)
  // Meshes are then coarsened for as long as they stay within this of the finer mesh (edge
  // collapse checked at samples of the new triangles; outlines kept), m, ≥ 0 (0: not
  // coarsened): a curved wall needs small triangles only where it bends, and every triangle is
  // at least four patches.
  double mesh_tolerance = 0.004;
  // and until it has fewer edges than this (0: target_patches), the tolerance or not: fewer
  // triangles still, a mesh having fewer triangles than edges.
  int max_mesh_edges = 0;
  // What the written scene says of each surface: reflectance (each in [0,1)) and a neutral
  // desired colour (sRGB); the patch target.
  Vec3 reflectance = Vec3::Constant(0.9);
  Vec3 desired_srgb = Vec3::Constant(0.5);
  int target_patches = 1000;
  bool Check(std::string* why) const;
};

// One surface of the result: how many points it took, how far they lie from it, its area.
struct ScannedSurfaceStats {
  enum Kind { kPlane, kMesh };
  Kind kind = kPlane;
  int points = 0;          // cloud points assigned to it
  double rms_mm = 0.0;     // planes: RMS distance of its points to the plane; meshes: of its
                           // points to their smoothed positions (on the fitted surface)
  double area_m2 = 0.0;    // of the polygon (holes removed) or mesh
  int outline_vertices = 0;  // planes: corners of its outlines; meshes: triangles
  int holes = 0;             // planes: holes in its outlines
  int snapped_vertices = 0;  // planes: corners moved onto an edge with a neighbouring plane
};

// Points on no surface, in a connected group too small for one (fewer than min_mesh_points):
// noise along edges, or, spread over a wide area, a surface where decoding left too few points.
struct LeftOutGroup {
  int points = 0;
  Vec3 centroid = Vec3::Zero();  // room frame, metres
  double area_m2 = 0.0;          // of the convex hull of its points in their best-fit plane
  // The plane surface most of the group's points lie on (within snap_distance of its plane,
  // inside its outer outline), or "": a badly measured part of a surface that was found (a far
  // wall's noisy points by a corner, a thin thing hung on a wall), not a surface missed.
  std::string on_surface;
};

struct ScannedScene {
  // The room: surfaces named floor, ceiling, wall_N (vertical planes), plane_N (other planes),
  // mesh_N (curved); mesh surfaces carry mesh_path "NAME.obj" for WriteScannedScene.
  Scene scene;
  std::vector<ScannedSurfaceStats> stats;  // one per scene.surfaces, same order
  int points = 0;      // in the cloud
  int unassigned = 0;  // on no surface (noise, too small groups)
  std::vector<LeftOutGroup> left_out;  // the groups of ≥ 3 of them, largest area first
  double mean_spacing = 0.0;  // of the cloud's points (mean distance to the nearest ones), m
  double time_s = 0.0;
  // One line per surface ("floor: plane, 48210 points, RMS 2.4 mm, 11.68 m², 12 corners, 2
  // holes") and a summary line.
  std::string Report() const;
};

// Builds the scene (method above). Throws std::invalid_argument when the options fail Check(),
// a point is not finite, or there are fewer than options.min_plane_points points.
ScannedScene SceneFromPoints(const std::vector<Vec3>& points, const SceneFromPointsOptions& options);

// One line for the largest left-out group on no found surface (LeftOutGroup::on_surface "")
// that spans more than `max_fraction` of the scanned surfaces' area (and more than
// min_area_m2): where it is, how many points over how much area, and what a surface needs; ""
// when there is none. A scan whose decoding failed over part of a surface leaves such a group
// instead of the surface.
std::string LeftOutSurfaceError(const ScannedScene& scanned, const SceneFromPointsOptions& options,
                                double max_fraction = 0.01, double min_area_m2 = 0.1);

// Writes the scene into `dir` (created if missing): room.json (docs/scene_format.md) and one
// NAME.obj per mesh surface, each through a temporary file and a rename; LoadScene reads it back.
// Returns room.json's path. Throws IoError naming the file that cannot be written.
std::filesystem::path WriteScannedScene(const std::filesystem::path& dir, const ScannedScene& scanned);

}  // namespace procam
