#include "geometry/scene_from_points.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <functional>
#include <map>
#include <numeric>
#include <stdexcept>

#include <CGAL/AABB_traits.h>
#include <CGAL/AABB_tree.h>
#include <CGAL/AABB_triangle_primitive.h>
#include <CGAL/Alpha_shape_2.h>
#include <CGAL/Alpha_shape_face_base_2.h>
#include <CGAL/Alpha_shape_vertex_base_2.h>
#include <CGAL/Delaunay_triangulation_2.h>
#include <CGAL/Exact_predicates_inexact_constructions_kernel.h>
#include <CGAL/Polygon_triangulation_decomposition_2.h>
#include <CGAL/Polygon_with_holes_2.h>
#include <CGAL/Polyline_simplification_2/simplify.h>
#include <CGAL/Shape_detection/Region_growing/Region_growing.h>
#include <CGAL/Shape_detection/Region_growing/Region_growing_on_point_set.h>
#include <CGAL/compute_average_spacing.h>
#include <CGAL/convex_hull_2.h>
#include <CGAL/pca_estimate_normals.h>
#include <CGAL/property_map.h>
#include <Eigen/Eigenvalues>
#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include "base/io.h"
#include "base/timing.h"
#include "geometry/polygon.h"
#include "geometry/scene_from_points_mesh.h"

namespace procam {
namespace {

using Kernel = CGAL::Exact_predicates_inexact_constructions_kernel;
using Point3 = Kernel::Point_3;
using Vector3 = Kernel::Vector_3;
using Point2 = Kernel::Point_2;
using PointWithNormal = std::pair<Point3, Vector3>;
using Cloud = std::vector<PointWithNormal>;
using PointMap = CGAL::First_of_pair_property_map<PointWithNormal>;
using NormalMap = CGAL::Second_of_pair_property_map<PointWithNormal>;
using NeighborQuery = CGAL::Shape_detection::Point_set::K_neighbor_query<Kernel, Cloud, PointMap>;
using PlaneRegion =
    CGAL::Shape_detection::Point_set::Least_squares_plane_fit_region<Kernel, Cloud, PointMap, NormalMap>;
using PlaneSorting =
    CGAL::Shape_detection::Point_set::Least_squares_plane_fit_sorting<Kernel, Cloud, NeighborQuery, PointMap>;
using RegionGrowing =
    CGAL::Shape_detection::Region_growing<Cloud, NeighborQuery, PlaneRegion, PlaneSorting::Seed_map>;
using Triangle3 = Kernel::Triangle_3;
using TriangleTree = CGAL::AABB_tree<
    CGAL::AABB_traits<Kernel, CGAL::AABB_triangle_primitive<Kernel, std::vector<Triangle3>::const_iterator>>>;
using Polygon2 = CGAL::Polygon_2<Kernel>;
using PolygonWithHoles2 = CGAL::Polygon_with_holes_2<Kernel>;
using AlphaShape = CGAL::Alpha_shape_2<CGAL::Delaunay_triangulation_2<
    Kernel, CGAL::Triangulation_data_structure_2<CGAL::Alpha_shape_vertex_base_2<Kernel>,
                                                 CGAL::Alpha_shape_face_base_2<Kernel>>>>;

constexpr double kPi = 3.14159265358979323846;
// Two regions are neighbours when at least this many k-nearest-neighbour edges join them.
constexpr int kMinAdjacentEdges = 5;

// A plane n·p + offset = 0 (n unit, towards the viewpoint) with an in-plane frame: p = origin +
// u·axis_u + v·axis_v, axis_u × axis_v = n (so counter-clockwise in (u, v) is counter-clockwise
// seen from the lit side).
struct Plane {
  Vec3 normal = Vec3::UnitZ();
  double offset = 0.0;
  Vec3 origin = Vec3::Zero();
  Vec3 axis_u = Vec3::UnitX(), axis_v = Vec3::UnitY();
  double Distance(const Vec3& p) const { return normal.dot(p) + offset; }
  Vec2 ToPlane(const Vec3& p) const { return Vec2((p - origin).dot(axis_u), (p - origin).dot(axis_v)); }
  Vec3 FromPlane(const Vec2& uv) const { return origin + uv.x() * axis_u + uv.y() * axis_v; }
  // Where the ray from `eye` through p meets the plane; p itself where that ray never does.
  Vec3 SeenAt(const Vec3& eye, const Vec3& p) const {
    const double from = Distance(eye), t = from / (from - Distance(p));
    return t > 0 && std::isfinite(t) ? Vec3(eye + t * (p - eye)) : p;
  }
};

// The least-squares plane of the points (PCA), its normal turned towards `viewpoint`; horizontal
// u axis for walls (x for floors and ceilings).
Plane FitPlane(const std::vector<Vec3>& points, const std::vector<int>& indices, const Vec3& viewpoint) {
  Vec3 centroid = Vec3::Zero();
  for (int i : indices) centroid += points[i];
  centroid /= double(indices.size());
  Eigen::Matrix3d scatter = Eigen::Matrix3d::Zero();
  for (int i : indices) scatter += (points[i] - centroid) * (points[i] - centroid).transpose();
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eigen(scatter);
  Plane plane;
  plane.normal = eigen.eigenvectors().col(0).normalized();
  if (plane.normal.dot(viewpoint - centroid) < 0) plane.normal = -plane.normal;
  plane.offset = -plane.normal.dot(centroid);
  plane.origin = centroid;
  const Vec3 reference = std::abs(plane.normal.z()) > 0.9 ? Vec3::UnitX() : Vec3::UnitZ();
  plane.axis_v = std::abs(plane.normal.z()) > 0.9 ? plane.normal.cross(reference).normalized()
                                                 : (reference - reference.dot(plane.normal) * plane.normal).normalized();
  plane.axis_u = plane.axis_v.cross(plane.normal).normalized();
  return plane;
}

// RMS distance of the points to the plane and to the best quadratic height field over it.
void PlaneAndQuadraticRms(const std::vector<Vec3>& points, const std::vector<int>& indices,
                          const Plane& plane, double* plane_rms, double* quadratic_rms) {
  double scale = 1e-9;
  for (int i : indices) scale = std::max(scale, plane.ToPlane(points[i]).cwiseAbs().maxCoeff());
  Eigen::Matrix<double, 6, 6> normal_matrix = Eigen::Matrix<double, 6, 6>::Zero();
  Eigen::Matrix<double, 6, 1> rhs = Eigen::Matrix<double, 6, 1>::Zero();
  double sum_squares = 0.0;
  for (int i : indices) {
    const Vec2 uv = plane.ToPlane(points[i]) / scale;
    const double h = plane.Distance(points[i]);
    Eigen::Matrix<double, 6, 1> basis;
    basis << 1, uv.x(), uv.y(), uv.x() * uv.x(), uv.x() * uv.y(), uv.y() * uv.y();
    normal_matrix += basis * basis.transpose();
    rhs += basis * h;
    sum_squares += h * h;
  }
  const Eigen::Matrix<double, 6, 1> coefficients = normal_matrix.ldlt().solve(rhs);
  // Residual sum of squares of a linear least-squares fit: Σh² − cᵀ(Bᵀh).
  const double residual = std::max(0.0, sum_squares - coefficients.dot(rhs));
  *plane_rms = std::sqrt(sum_squares / indices.size());
  *quadratic_rms = std::sqrt(residual / indices.size());
}

double AngleDeg(const Vec3& a, const Vec3& b) {
  return std::acos(std::clamp(std::abs(a.dot(b)), 0.0, 1.0)) * 180.0 / kPi;
}

int Find(std::vector<int>& parent, int i) {
  while (parent[i] != i) i = parent[i] = parent[parent[i]];
  return i;
}

// The boundary cycles of the regularised alpha shape of `uv`: counter-clockwise outer boundaries
// and clockwise holes, each a simple polygon (where two parts touch at a vertex, each cycle turns
// into its own part).
std::vector<Polygon2> AlphaShapeCycles(const std::vector<Point2>& uv, double alpha_radius) {
  AlphaShape shape(uv.begin(), uv.end(), Kernel::FT(alpha_radius * alpha_radius), AlphaShape::REGULARIZED);
  using Vertex = AlphaShape::Vertex_handle;
  std::vector<std::pair<Vertex, Vertex>> edges;
  std::map<Vertex, std::vector<int>> outgoing;
  for (auto face = shape.finite_faces_begin(); face != shape.finite_faces_end(); ++face) {
    if (shape.classify(face) != AlphaShape::INTERIOR) continue;
    for (int i = 0; i < 3; ++i) {
      const auto neighbour = face->neighbor(i);
      if (!shape.is_infinite(neighbour) && shape.classify(neighbour) == AlphaShape::INTERIOR) continue;
      // The edge opposite vertex i, with the face on its left.
      outgoing[face->vertex(face->ccw(i))].push_back(static_cast<int>(edges.size()));
      edges.emplace_back(face->vertex(face->ccw(i)), face->vertex(face->cw(i)));
    }
  }
  auto direction = [](Vertex from, Vertex to) {
    return Vec2(to->point().x() - from->point().x(), to->point().y() - from->point().y());
  };
  std::vector<bool> used(edges.size(), false);
  std::vector<Polygon2> cycles;
  for (size_t start = 0; start < edges.size(); ++start) {
    if (used[start]) continue;
    Polygon2 cycle;
    int edge = static_cast<int>(start);
    while (edge >= 0 && !used[edge]) {
      used[edge] = true;
      cycle.push_back(edges[edge].first->point());
      const Vertex at = edges[edge].second;
      const Vec2 back = direction(at, edges[edge].first);
      // Of the unused edges leaving `at`, the first met turning clockwise from the way back:
      // it bounds the same part of the shape.
      int next = -1;
      double best = 10.0;
      for (int candidate : outgoing[at]) {
        if (used[candidate]) continue;
        const Vec2 out = direction(at, edges[candidate].second);
        double angle = std::atan2(out.x() * back.y() - out.y() * back.x(), out.dot(back));
        if (angle <= 0) angle += 2 * kPi;
        if (angle < best) best = angle, next = candidate;
      }
      edge = next;
    }
    if (cycle.size() >= 3) cycles.push_back(cycle);
  }
  return cycles;
}

// The line where planes a and b meet: a point on it and its unit direction.
bool PlaneIntersection(const Plane& a, const Plane& b, Vec3* point, Vec3* direction) {
  const Vec3 d = a.normal.cross(b.normal);
  if (d.squaredNorm() < 1e-6) return false;
  // The point of the line closest to a's origin.
  Eigen::Matrix3d m;
  m.row(0) = a.normal.transpose();
  m.row(1) = b.normal.transpose();
  m.row(2) = d.transpose();
  *point = m.colPivHouseholderQr().solve(Vec3(-a.offset, -b.offset, d.dot(a.origin)));
  *direction = d.normalized();
  return true;
}

bool ThreePlanePoint(const Plane& a, const Plane& b, const Plane& c, Vec3* point) {
  Eigen::Matrix3d m;
  m.row(0) = a.normal.transpose();
  m.row(1) = b.normal.transpose();
  m.row(2) = c.normal.transpose();
  if (std::abs(m.determinant()) < 0.05) return false;
  *point = m.colPivHouseholderQr().solve(Vec3(-a.offset, -b.offset, -c.offset));
  return true;
}

// One planar region on its way to a surface.
struct PlaneSurface {
  Plane plane;
  std::vector<int> indices;
  std::vector<PolygonWithHoles2> polygons;  // in the plane's (u, v)
  int snapped = 0;
};

// Places each edge of a simplified ring where the sampled surface most likely ends. The outermost
// points lie inside the true edge, by a gap that depends on how the samples are laid out along it:
// half the depth spacing of a camera's lattice of pixels turned against the edge (1/(2ρw) for bins
// of width w at density ρ), but half the spacing of its rows where they run along the edge (a
// wall's vertical end seen at a grazing angle, its pixel columns far apart in depth), which can be
// several times more. The gap is measured on the edge's own points: cut each bin at a depth t
// beyond its reference point (below), for t spread over several spacings, and take the mean
// distance from the cut to the bin's next point, as from a true edge at an unknown place among the
// samples. The edge moves to the bins' reference depths (their mean, or with four bins or more
// the line through them) minus that gap.
// `uv`: the plane's points; counter-clockwise outer rings and clockwise holes alike have the
// surface on their left.
void PlaceEdges(const std::vector<Point2>& uv, double density, double spacing, Polygon2* ring) {
  const int n = static_cast<int>(ring->size());
  std::vector<Vec2> corner(n), outward(n);
  // How far each edge moves out at its start (corner k) and at its end (corner k + 1).
  std::vector<double> shift_start(n, 0.0), shift_end(n, 0.0);
  for (int k = 0; k < n; ++k) corner[k] = Vec2((*ring)[k].x(), (*ring)[k].y());
  const double band = 6 * spacing, bin_width = 2 * spacing;
  // The cuts: kCuts depths spread evenly over `reach` beyond each bin's reference point.
  constexpr int kCuts = 24;
  const double reach = 4 * spacing, deep = 12 * spacing;
  for (int k = 0; k < n; ++k) {
    const Vec2 a = corner[k], b = corner[(k + 1) % n];
    const double length = (b - a).norm();
    outward[k] = Vec2((b - a).y(), -(b - a).x()) / std::max(length, 1e-12);
    if (length < 2 * bin_width) continue;
    const int bins = static_cast<int>(length / bin_width);
    std::vector<std::vector<double>> depths(bins);
    for (const Point2& point : uv) {
      const Vec2 p(point.x(), point.y());
      const double along = (p - a).dot(b - a) / length;
      const double depth = -(p - a).dot(outward[k]);
      if (along < 0 || along >= length || depth < -band || depth > deep) continue;
      depths[std::min(bins - 1, static_cast<int>(along / length * bins))].push_back(depth);
    }
    // Each bin's reference: its second point from the edge (its only one if it has one). The
    // outermost of several noisy points lies beyond their mean by about their noise (a
    // triangulated point's noise runs along the camera's ray, nearly in the plane at a grazing
    // view), which put edges of triangulated scans centimetres beyond the truth; the second is
    // much less so. The cuts below are measured from it too, and their gap to the first point
    // after them: on a noise-free lattice the edge then lies a fraction of the spacing along the
    // edge inside (areas 0.3-1.2% small on the point-cloud tests, 2.7% on tiny_box's walls at
    // 74°), a bias kept on purpose, as beyond the truth is where a scan is wrong in the room.
    const auto reference = [](const std::vector<double>& bin) {
      return bin.size() > 1 ? bin[1] : bin.front();
    };
    double sum = 0, gap_sum = 0;
    int filled = 0, gaps = 0;
    std::vector<Vec2> along_and_reference;  // per filled bin: its centre along the edge, its reference
    for (int b = 0; b < bins; ++b) {
      std::vector<double>& bin = depths[b];
      std::sort(bin.begin(), bin.end());
      if (bin.empty() || bin.front() > band) continue;
      sum += reference(bin), ++filled;
      along_and_reference.emplace_back((b + 0.5) * length / bins, reference(bin));
      for (int c = 0; c < kCuts; ++c) {
        const double cut = reference(bin) + (c + 0.5) / kCuts * reach;
        const auto next = std::upper_bound(bin.begin(), bin.end(), cut);
        if (next != bin.end()) gap_sum += *next - cut, ++gaps;
      }
    }
    if (filled < std::max(2, bins / 2)) continue;  // not an edge of this point set
    // Without a next point anywhere (a strip narrower than the cuts reach), the turned lattice's.
    const double gap = gaps > 0 ? gap_sum / gaps : 1.0 / (2 * density * (length / bins));
    double edge_depth = sum / filled - gap, slope = 0.0;
    // The simplified edge runs from one kept outline corner to another, and where a corner's place
    // is off by the noise its edge leans against the points. With several bins the edge leans as
    // their references do (least squares), on the bins within a few spacings of the shallowest
    // half of them (a notch the edge bridges would lean it).
    if (filled >= 4) {
      std::vector<double> references;
      for (const Vec2& bin : along_and_reference) references.push_back(bin.y());
      std::nth_element(references.begin(), references.begin() + filled / 2, references.end());
      const double within = references[filled / 2] + 2 * spacing;
      double count = 0, mean_along = 0, mean_reference = 0;
      for (const Vec2& bin : along_and_reference)
        if (bin.y() <= within) ++count, mean_along += bin.x(), mean_reference += bin.y();
      mean_along /= count, mean_reference /= count;
      double sxx = 0, sxy = 0;
      for (const Vec2& bin : along_and_reference)
        if (bin.y() <= within)
          sxx += std::pow(bin.x() - mean_along, 2), sxy += (bin.x() - mean_along) * (bin.y() - mean_reference);
      if (count >= 4 && sxx > 0) {
        slope = sxy / sxx;
        edge_depth = mean_reference - slope * mean_along - gap;  // at the edge's start
      }
    }
    // Never inwards: the simplified edge runs through boundary points already, and where it
    // bridges a notch its bins' reference points lie deep inside.
    shift_start[k] = std::clamp(-edge_depth, 0.0, band / 2);
    shift_end[k] = std::clamp(-(edge_depth + slope * length), 0.0, band / 2);
  }
  Polygon2 placed;
  for (int k = 0; k < n; ++k) {
    const int prev = (k + n - 1) % n;
    // The corner where the moved edges prev and k meet: (p − c)·outward = each one's shift there
    // (an edge that leans turns by at most band / length: its normal is kept).
    Eigen::Matrix2d m;
    m.row(0) = outward[prev].transpose();
    m.row(1) = outward[k].transpose();
    Vec2 p = corner[k];
    const double largest = std::max(std::abs(shift_end[prev]), std::abs(shift_start[k]));
    const Vec2 move = std::abs(m.determinant()) > 0.1 ? Vec2(m.inverse() * Vec2(shift_end[prev], shift_start[k]))
                                                      : Vec2(1e300, 0);
    if (move.norm() <= 2 * largest) {
      p += move;
    } else {  // nearly parallel edges: along their mean normal
      p += 0.5 * (shift_end[prev] + shift_start[k]) * (outward[prev] + outward[k]).normalized();
    }
    placed.push_back(Point2(p.x(), p.y()));
  }
  static const Kernel traits;
  if (CGAL::is_simple_2(placed.vertices_begin(), placed.vertices_end(), traits) &&
      placed.orientation() == ring->orientation()) {
    *ring = placed;
  }
}

// Seen at a grazing angle, a camera's pixel columns lie on a plane 1/cos θ farther apart than its
// rows (θ: the incidence), and a free edge slanted across them is a sawtooth as deep as that gap,
// one tooth per column, wider than any tolerance on the plane can take for one edge without
// rounding the corners of surfaces seen face on. In the image it is a staircase one pixel deep.
constexpr double kSeenTolerance = 1.5;  // pixels

// Simplifies `polygon` as seen from `viewpoint`: its vertices mapped to an image plane facing its
// centre (a central projection, which keeps lines straight and a simple polygon simple), simplified
// there within `tolerance` (rad at the image's centre), and the kept vertices mapped back.
void SimplifyAsSeen(const Plane& plane, const Vec3& viewpoint, double tolerance, PolygonWithHoles2* polygon) {
  Vec3 towards = Vec3::Zero();
  for (const Point2& q : polygon->outer_boundary().container())
    towards += (plane.FromPlane(Vec2(q.x(), q.y())) - viewpoint).normalized();
  if (!(towards.norm() > 1e-9)) return;
  towards.normalize();
  const Vec3 across = towards.unitOrthogonal(), up = towards.cross(across);
  // Image point → plane point: simplify keeps the vertices it does not remove unchanged.
  std::map<std::pair<double, double>, Point2> on_plane;
  bool in_front = true;
  const auto to_image = [&](const Polygon2& ring) {
    Polygon2 image;
    for (const Point2& q : ring.container()) {
      const Vec3 ray = plane.FromPlane(Vec2(q.x(), q.y())) - viewpoint;
      const double depth = ray.dot(towards);
      in_front = in_front && depth > 1e-3 * ray.norm();
      const Point2 seen(ray.dot(across) / depth, ray.dot(up) / depth);
      on_plane[{seen.x(), seen.y()}] = q;
      image.push_back(seen);
    }
    return image;
  };
  PolygonWithHoles2 image(to_image(polygon->outer_boundary()));
  for (auto hole = polygon->holes_begin(); hole != polygon->holes_end(); ++hole) image.add_hole(to_image(*hole));
  if (!in_front) return;  // a surface around the viewpoint has no one image plane
  namespace simplification = CGAL::Polyline_simplification_2;
  image = simplification::simplify(image, simplification::Squared_distance_cost(),
                                   simplification::Stop_above_cost_threshold(tolerance * tolerance));
  const auto back = [&](const Polygon2& ring) {
    Polygon2 kept;
    for (const Point2& q : ring.container()) kept.push_back(on_plane.at({q.x(), q.y()}));
    return kept;
  };
  PolygonWithHoles2 simplified(back(image.outer_boundary()));
  for (auto hole = image.holes_begin(); hole != image.holes_end(); ++hole) simplified.add_hole(back(*hole));
  *polygon = std::move(simplified);
}

// Step 4: outlines of the plane's points, simplified, each edge where the surface ends.
// `spacing`: the points' typical spacing on this plane (1/√density); the alpha shape's radius is
// the larger of outline_alpha_spacings spacings and 1.5 × `neighbour_radius` (RegionSpacing).
std::vector<PolygonWithHoles2> Outlines(const std::vector<Vec3>& points, const PlaneSurface& surface,
                                        double spacing, double neighbour_radius,
                                        const SceneFromPointsOptions& options) {
  // Sparse rows (a grazing view) make the alpha shape's boundary zig-zag by about the rows' gap.
  const double tolerance = std::max(options.outline_tolerance, 0.5 * neighbour_radius);
  // Points on a camera's rays, on a plane where the camera's pixel columns lie farther apart than
  // twice `tolerance` (a grazing view): each point is taken where its ray meets the plane, and the
  // outline is also simplified as the camera sees it (below), within kSeenTolerance of its pixels,
  // α rad each. α from `spacing`, the mean spacing, α r / √cos θ at distance r and incidence θ; the
  // columns' gap is α r / cos θ. Elsewhere both are left as they were: on a plane seen nearly face
  // on they change little, and which corners the simplification keeps changes with any change.
  const Vec3& viewpoint = options.viewpoint;
  const double viewpoint_distance = surface.plane.Distance(viewpoint);
  double pixel_rad = 0.0;
  if (options.points_on_viewpoint_rays && std::abs(viewpoint_distance) > 1e-3) {
    double sum_spacing = 0.0, sum_gap = 0.0;
    for (int i : surface.indices) {
      const Vec3 ray = points[i] - viewpoint;
      const double r = ray.norm();
      const double cos_incidence = std::max(std::abs(surface.plane.normal.dot(ray)) / r, 0.02);
      sum_spacing += r / std::sqrt(cos_incidence);
      sum_gap += r / cos_incidence;
    }
    pixel_rad = spacing * surface.indices.size() / sum_spacing;
    if (pixel_rad * sum_gap / surface.indices.size() <= 2 * tolerance) pixel_rad = 0.0;
  }
  std::vector<Point2> uv;
  uv.reserve(surface.indices.size());
  for (int i : surface.indices) {
    const Vec2 p = surface.plane.ToPlane(pixel_rad > 0 ? surface.plane.SeenAt(viewpoint, points[i]) : points[i]);
    uv.emplace_back(p.x(), p.y());
  }
  std::vector<Polygon2> outers, holes;
  const double alpha = std::max(options.outline_alpha_spacings * spacing, 1.5 * neighbour_radius);
  for (Polygon2& cycle : AlphaShapeCycles(uv, alpha)) {
    const double area = CGAL::to_double(cycle.area());
    if (area >= options.min_surface_area) outers.push_back(std::move(cycle));
    else if (-area >= options.min_hole_area) holes.push_back(std::move(cycle));
  }
  std::vector<PolygonWithHoles2> polygons;
  for (const Polygon2& outer : outers) polygons.emplace_back(outer);
  for (const Polygon2& hole : holes) {
    for (PolygonWithHoles2& polygon : polygons) {
      if (polygon.outer_boundary().bounded_side(hole.vertex(0)) == CGAL::ON_BOUNDED_SIDE) {
        polygon.add_hole(hole);
        break;
      }
    }
  }
  namespace simplification = CGAL::Polyline_simplification_2;
  const double tolerance2 = tolerance * tolerance;
  const double density = 1.0 / (spacing * spacing);
  for (PolygonWithHoles2& polygon : polygons) {
    polygon = simplification::simplify(polygon, simplification::Squared_distance_cost(),
                                       simplification::Stop_above_cost_threshold(tolerance2));
    if (pixel_rad > 0) SimplifyAsSeen(surface.plane, viewpoint, kSeenTolerance * pixel_rad, &polygon);
    PlaceEdges(uv, density, spacing, &polygon.outer_boundary());
    for (auto hole = polygon.holes_begin(); hole != polygon.holes_end(); ++hole) {
      PlaceEdges(uv, density, spacing, &*hole);
    }
  }
  return polygons;
}

// Notch filling (step 5): where the points of a plane stop short of the edge it shares with a
// neighbour (camera pixels that decoded nothing beside the corner of two walls, seen at a grazing
// angle so that each spans centimetres to decimetres of wall), its outline retreats from the edge
// line in a notch a degree or two wide in the camera's image. Both planes run on to their shared
// edge; what the camera cannot resolve is filled, unless it saw something else there: points
// through it (a hole) or in front of it (the notch hidden behind another surface).
struct NotchFilling {
  Vec3 viewpoint = Vec3::Zero();
  double max_angle = 0.0;  // a notch is at most this wide seen from the viewpoint, rad (0: none)
  // Points beyond the plane or in front of it by more than this, seen where a notch is, keep it
  // open, m (triangulated points where a surface is seen and lit at grazing angles lie
  // centimetres off it).
  double beyond = 0.05;
  const std::vector<Vec3>* points = nullptr;
};

constexpr int kSeenInstead = 3;  // points seen where a notch is that keep it open

struct NotchLine {
  Vec3 point, direction;  // unit direction
  const Plane* other;     // the neighbour the line is shared with
};

// The angle, seen from `viewpoint`, between p and the line (in the image: p's distance from the
// line's image).
double AngleToLine(const Vec3& viewpoint, const NotchLine& line, const Vec3& p) {
  const Vec3 normal = line.direction.cross(line.point - viewpoint);
  const Vec3 ray = p - viewpoint;
  if (normal.norm() < 1e-12 || ray.norm() < 1e-12) return 0.0;
  return std::asin(std::min(1.0, std::abs(normal.normalized().dot(ray.normalized()))));
}

// Whether `at` lies inside `ring` by the even-odd rule (the ring need not be simple).
bool InsideEvenOdd(const std::vector<Point2>& ring, const Point2& at) {
  bool inside = false;
  for (size_t k = 0, prev = ring.size() - 1; k < ring.size(); prev = k++) {
    const Point2 &a = ring[k], &b = ring[prev];
    if ((a.y() > at.y()) != (b.y() > at.y()) &&
        at.x() < a.x() + (b.x() - a.x()) * (at.y() - a.y()) / (b.y() - a.y()))
      inside = !inside;
  }
  return inside;
}

// How many cloud points lie off `plane` by more than notches.beyond, beyond it (seen through it)
// or in front of it (hiding it), on a ray from the viewpoint that crosses the plane inside
// `larger` but not inside `smaller` (rings in the plane's (u, v)).
int PointsSeenInstead(const Plane& plane, const std::vector<Point2>& larger, const std::vector<Point2>& smaller,
                      const NotchFilling& notches) {
  const CGAL::Bbox_2 box = CGAL::bbox_2(larger.begin(), larger.end());
  const Vec3& v = notches.viewpoint;
  const double from = plane.Distance(v);
  int seen = 0;
  for (const Vec3& q : *notches.points) {
    const double to = plane.Distance(q);
    const bool through = to < -notches.beyond, hiding = to > notches.beyond && to < from;
    if (!(through || hiding) || from <= 0) continue;
    const Vec2 uv = plane.ToPlane(plane.SeenAt(v, q));
    if (uv.x() < box.xmin() || uv.x() > box.xmax() || uv.y() < box.ymin() || uv.y() > box.ymax()) continue;
    const Point2 at(uv.x(), uv.y());
    if (InsideEvenOdd(larger, at) && !InsideEvenOdd(smaller, at)) ++seen;
  }
  return seen;
}

// Finds the notches of one snapped ring beside the points where three planes meet. For a corner
// j on edge line L2, another edge line L1 and their meeting point T, walking back from j through
// corners each within notches.max_angle of L1 or L2 (seen from the viewpoint):
//  - to the farthest corner i on L1: the corners between i and j go, and T comes between them;
//  - to the farthest corner i on L2, where T is within notches.max_angle of i or j: the corners
//    between them go, the edge runs straight along L2 (a pocket opening onto one edge beside the
//    corner).
// Only beside such points: along a single edge line far from any, a retreat is as likely a part
// of the surface no projector lights (the floor between two partitions' shadows, which the camera
// may see within a few degrees of the edge) as one that did not decode.
// A notch is taken when the ring stays simple and gains area, and no points are seen through the
// area it gains or in front of it. `on_line[k]`: the lines (indices into `lines`) corner k lies on. `ring_of`: the
// ring SnapRing makes of the corners with some dropped and some added. Marks the corners that go
// in `dropped` and the corner added after corner k in `added[k]`.
using RingOf = std::function<std::vector<Point2>(const std::vector<bool>& dropped,
                                                  const std::vector<std::vector<Point2>>& added)>;
void FillNotches(const Plane& plane, const std::vector<NotchLine>& lines, const std::vector<Point2>& corners,
                 const std::vector<std::vector<int>>& on_line, const NotchFilling& notches, const RingOf& ring_of,
                 std::vector<bool>* dropped, std::vector<std::vector<Point2>>* added) {
  const int n = static_cast<int>(corners.size());
  if (notches.max_angle <= 0 || n < 4) return;
  const Vec3& v = notches.viewpoint;
  const auto at = [&](int k) { return plane.FromPlane(Vec2(corners[k].x(), corners[k].y())); };
  const auto on = [&](int k, int line) {
    return std::find(on_line[k].begin(), on_line[k].end(), line) != on_line[k].end();
  };
  const auto near = [&](int k, int line) {
    return on(k, line) || AngleToLine(v, lines[line], at(k)) <= notches.max_angle;
  };
  const auto apart = [&](const Vec3& a, const Vec3& b) {  // the angle between a and b seen from v
    const Vec3 ra = a - v, rb = b - v;
    return std::atan2(ra.cross(rb).norm(), ra.dot(rb));
  };
  struct Notch {
    int i, j, run;
    bool meet;  // T comes in after i
    Point2 corner;
  };
  std::vector<Notch> found;
  for (int j = 0; j < n; ++j) {
    for (int second : on_line[j]) {
      for (int first = 0; first < static_cast<int>(lines.size()); ++first) {
        Vec3 meet;
        if (first == second || !ThreePlanePoint(plane, *lines[first].other, *lines[second].other, &meet)) continue;
        const Vec2 uv = plane.ToPlane(meet);
        Notch to_first{-1, j, 0, true, Point2(uv.x(), uv.y())}, along{-1, j, 0, false, Point2(0, 0)};
        bool off_second = false;  // a corner between j and along.i off L2
        for (int steps = 1, k = (j + n - 1) % n; steps < n / 2; ++steps, k = (k + n - 1) % n) {
          if (on(k, first)) to_first.i = k, to_first.run = steps - 1;
          if (on(k, second) && off_second) along.i = k, along.run = steps - 1;
          if (!near(k, first) && !near(k, second)) break;
          off_second = off_second || !on(k, second);
        }
        // to_first: something to gain where T is not yet a corner between i and j.
        bool there = to_first.i < 0;
        for (int k = to_first.i; !there && k != (j + 1) % n; k = (k + 1) % n) there = on(k, first) && on(k, second);
        if (!there) found.push_back(to_first);
        if (along.i >= 0 && std::min(apart(meet, at(along.i)), apart(meet, at(j))) <= notches.max_angle)
          found.push_back(along);
      }
    }
  }
  // Widest first; each checked on the ring with the notches taken so far.
  std::sort(found.begin(), found.end(), [](const Notch& a, const Notch& b) { return a.run > b.run; });
  static const Kernel traits;  // (as in SnapRing)
  std::vector<Point2> before = ring_of(*dropped, *added);
  double area = CGAL::to_double(CGAL::polygon_area_2(before.begin(), before.end(), traits));
  for (const Notch& notch : found) {
    if ((*dropped)[notch.i] || (*dropped)[notch.j] || !(*added)[notch.i].empty()) continue;
    std::vector<bool> drop = *dropped;
    std::vector<std::vector<Point2>> add = *added;
    bool free = true;
    for (int k = (notch.i + 1) % n; k != notch.j; k = (k + 1) % n) free = free && !drop[k] && add[k].empty(), drop[k] = true;
    if (!free) continue;
    if (notch.meet) add[notch.i].push_back(notch.corner);
    std::vector<Point2> ring = ring_of(drop, add);
    if (ring.size() < 3 || !CGAL::is_simple_2(ring.begin(), ring.end(), traits)) continue;
    const double larger = CGAL::to_double(CGAL::polygon_area_2(ring.begin(), ring.end(), traits));
    if (std::abs(larger) <= std::abs(area) || (larger > 0) != (area > 0)) continue;
    if (notches.points && PointsSeenInstead(plane, ring, before, notches) >= kSeenInstead) continue;
    *dropped = drop, *added = add, area = larger, before = std::move(ring);
  }
}

// Step 5 for one ring: moves corners near the edge lines with neighbouring planes onto them.
// Returns how many moved.
int SnapRing(const Plane& plane, const std::vector<const Plane*>& neighbours, double snap_distance,
             const NotchFilling& notches, Polygon2* ring) {
  using Line = NotchLine;
  std::vector<Line> lines;
  for (const Plane* other : neighbours) {
    Line line{Vec3::Zero(), Vec3::Zero(), other};
    if (PlaneIntersection(plane, *other, &line.point, &line.direction)) lines.push_back(line);
  }
  int moved = 0;
  Polygon2 snapped;
  // Per corner: the lines (indices into `lines`) it now lies on, two where it moved onto the
  // point where three planes meet.
  std::vector<std::vector<int>> on_line;
  const auto index = [&](const Line* line) { return static_cast<int>(line - lines.data()); };
  for (const Point2& corner : ring->vertices()) {
    const Vec3 p = plane.FromPlane(Vec2(corner.x(), corner.y()));
    std::vector<std::pair<double, const Line*>> near;
    for (const Line& line : lines) {
      const Vec3 on_line = line.point + (p - line.point).dot(line.direction) * line.direction;
      const double distance = (p - on_line).norm();
      if (distance <= snap_distance) near.emplace_back(distance, &line);
    }
    std::sort(near.begin(), near.end(), [](const auto& a, const auto& b) { return a.first < b.first; });
    Vec3 q = p;
    bool done = false;
    if (near.size() >= 2) {
      Vec3 corner3;
      if (ThreePlanePoint(plane, *near[0].second->other, *near[1].second->other, &corner3) &&
          (corner3 - p).norm() <= 2 * snap_distance) {
        q = corner3, done = true;
        on_line.push_back({index(near[0].second), index(near[1].second)});
      }
    }
    if (!done && !near.empty()) {
      const Line& line = *near[0].second;
      q = line.point + (p - line.point).dot(line.direction) * line.direction;
      done = true;
      on_line.push_back({index(&line)});
    }
    if (done) ++moved;
    else on_line.emplace_back();
    const Vec2 uv = plane.ToPlane(q);
    snapped.push_back(Point2(uv.x(), uv.y()));
  }
  std::vector<Point2> corners(snapped.vertices_begin(), snapped.vertices_end());
  // Of a run of corners snapped onto one edge line, only the run's ends stay: the edge runs
  // straight between them. (An outline that zig-zags across the line, as where points of two
  // planes interleave along their edge, would otherwise double back along it and not be simple.)
  // Corners in notches go (`dropped`), meeting points come in (`added`; FillNotches).
  // The one line corner k moved onto, −1 for none or for the point where three planes meet.
  const auto onto = [&](size_t k) { return on_line[k].size() == 1 ? on_line[k][0] : -1; };
  const RingOf clean = [&](const std::vector<bool>& dropped, const std::vector<std::vector<Point2>>& added) {
    std::vector<Point2> cleaned;
    const size_t count = on_line.size();
    for (size_t k = 0; k < count; ++k) {
      if (dropped[k]) continue;
      const int at = onto(k);
      if (!(at >= 0 && onto((k + count - 1) % count) == at && onto((k + 1) % count) == at))
        cleaned.push_back(snapped[k]);
      cleaned.insert(cleaned.end(), added[k].begin(), added[k].end());
    }
    if (cleaned.size() < 3) cleaned.assign(snapped.vertices_begin(), snapped.vertices_end());
    // Corners that snapped onto one point, or onto a straight line between their neighbours, go.
    for (bool removed = true; removed && cleaned.size() > 3;) {
      removed = false;
      for (size_t k = 0; k < cleaned.size() && cleaned.size() > 3; ++k) {
        const size_t count = cleaned.size();
        const Vec2 prev(cleaned[(k + count - 1) % count].x(), cleaned[(k + count - 1) % count].y());
        const Vec2 at(cleaned[k].x(), cleaned[k].y());
        const Vec2 next(cleaned[(k + 1) % count].x(), cleaned[(k + 1) % count].y());
        const Vec2 base = next - prev;
        const double along = base.squaredNorm() > 0 ? (at - prev).dot(base) / base.squaredNorm() : -1;
        const double off_line = base.norm() > 0 ? std::abs(base.x() * (at - prev).y() - base.y() * (at - prev).x()) / base.norm() : 0;
        if ((at - prev).norm() < 2e-3 || (along > 0 && along < 1 && off_line < 5e-4)) {
          cleaned.erase(cleaned.begin() + k);
          removed = true;
        }
      }
    }
    return cleaned;
  };
  std::vector<bool> dropped(corners.size(), false);
  std::vector<std::vector<Point2>> added(corners.size());
  FillNotches(plane, lines, corners, on_line, notches, clean, &dropped, &added);
  const std::vector<Point2> cleaned = clean(dropped, added);
  // (A named traits object: GCC 12 takes the empty temporary Polygon_2::is_simple passes for
  // uninitialised.)
  static const Kernel traits;
  if (cleaned.size() >= 3 && CGAL::is_simple_2(cleaned.begin(), cleaned.end(), traits)) {
    *ring = Polygon2(cleaned.begin(), cleaned.end());
  }
  return moved;
}

// Step 6b for one ring: moves corners within snap_distance of a mesh surface to the mesh's nearest
// point, seen along the plane's normal. Where a plane meets a curved surface (a floor under a
// curved wall, around a column) nothing else places its outline: its free edge lies wherever
// the plane's points stopped, up to a few centimetres beyond the surface it meets. Returns how
// many moved; the ring stays as it was if moving them would make it not simple.
int SnapRingToMeshes(const Plane& plane, const TriangleTree& meshes, double snap_distance, Polygon2* ring) {
  std::vector<Point2> moved_ring;
  int moved = 0;
  for (const Point2& corner : ring->vertices()) {
    const Vec3 p = plane.FromPlane(Vec2(corner.x(), corner.y()));
    const Point3 query(p.x(), p.y(), p.z());
    const Point3 nearest = meshes.closest_point(query);
    const Vec3 q(nearest.x(), nearest.y(), nearest.z());
    if ((q - p).norm() <= snap_distance) {
      const Vec2 uv = plane.ToPlane(q);
      moved_ring.push_back(Point2(uv.x(), uv.y()));
      ++moved;
    } else {
      moved_ring.push_back(corner);
    }
  }
  static const Kernel traits;  // (as in SnapRing)
  if (moved == 0 || !CGAL::is_simple_2(moved_ring.begin(), moved_ring.end(), traits)) return 0;
  *ring = Polygon2(moved_ring.begin(), moved_ring.end());
  return moved;
}

// Quad when the outline is one convex 4-corner polygon; otherwise a mesh of its constrained
// Delaunay triangles.
Surface ToSurface(const PlaneSurface& plane_surface, const SceneFromPointsOptions& options, double weld) {
  Surface surface;
  surface.reflectance = options.reflectance;
  surface.desired.srgb = options.desired_srgb;
  const Plane& plane = plane_surface.plane;
  auto to3 = [&](const Point2& p) { return plane.FromPlane(Vec2(p.x(), p.y())); };
  if (plane_surface.polygons.size() == 1 && !plane_surface.polygons[0].has_holes() &&
      plane_surface.polygons[0].outer_boundary().size() == 4) {
    const Polygon2& outer = plane_surface.polygons[0].outer_boundary();
    for (int k = 0; k < 4; ++k) surface.quad[k] = to3(outer[k]);
    std::string why;
    if (CheckPlanarConvexPolygon(surface.quad.data(), 4, weld, &why)) return surface;
  }
  surface.kind = Surface::Kind::kMesh;
  PointWelder welder(weld);
  double u_min = 1e300, u_max = -1e300, v_min = 1e300, v_max = -1e300;
  for (const PolygonWithHoles2& polygon : plane_surface.polygons) {
    for (const Point2& p : polygon.outer_boundary().vertices()) {
      u_min = std::min(u_min, p.x()), u_max = std::max(u_max, p.x());
      v_min = std::min(v_min, p.y()), v_max = std::max(v_max, p.y());
    }
  }
  auto uv_of = [&](const Point2& p) {
    return Vec2((p.x() - u_min) / std::max(u_max - u_min, 1e-9), (p.y() - v_min) / std::max(v_max - v_min, 1e-9));
  };
  CGAL::Polygon_triangulation_decomposition_2<Kernel> triangulate;
  for (const PolygonWithHoles2& polygon : plane_surface.polygons) {
    std::vector<Polygon2> triangles;
    triangulate(polygon, std::back_inserter(triangles));
    for (const Polygon2& triangle : triangles) {
      MeshTriangle mesh_triangle;
      std::array<Vec3, 3> corners;
      for (int k = 0; k < 3; ++k) {
        corners[k] = to3(triangle[k]);
        mesh_triangle.vertex[k] = welder.Weld(corners[k]);
        mesh_triangle.uv[k] = uv_of(triangle[k]);
      }
      std::string why;
      if (!CheckPlanarConvexPolygon(corners.data(), 3, weld, &why)) continue;  // a sliver
      surface.mesh_triangles.push_back(mesh_triangle);
    }
  }
  surface.mesh_vertices = welder.points();
  return surface;
}

// Labels every point with its planar region (−1: none), steps 1–2.
std::vector<int> GrowPlanarRegions(const std::vector<Vec3>& points, const SceneFromPointsOptions& options,
                                   double* mean_spacing, std::vector<std::vector<int>>* neighbours) {
  Cloud cloud;
  cloud.reserve(points.size());
  for (const Vec3& p : points) cloud.emplace_back(Point3(p.x(), p.y(), p.z()), Vector3(0, 0, 1));
  CGAL::pca_estimate_normals<CGAL::Sequential_tag>(
      cloud, options.normal_neighbors, CGAL::parameters::point_map(PointMap()).normal_map(NormalMap()));
  *mean_spacing = CGAL::compute_average_spacing<CGAL::Sequential_tag>(
      cloud, 6, CGAL::parameters::point_map(PointMap()));
  NeighborQuery neighbor_query(cloud, options.growing_neighbors, PointMap());
  PlaneRegion region_type(cloud, options.plane_distance, options.plane_angle_deg, options.min_plane_points,
                          PointMap(), NormalMap());
  PlaneSorting sorting(cloud, neighbor_query, PointMap());
  sorting.sort();
  RegionGrowing growing(cloud, neighbor_query, region_type, sorting.seed_map());
  std::vector<std::vector<std::size_t>> regions;
  growing.detect(std::back_inserter(regions));
  std::vector<int> label(points.size(), -1);
  for (size_t r = 0; r < regions.size(); ++r)
    for (std::size_t i : regions[r]) label[i] = static_cast<int>(r);
  neighbours->assign(points.size(), {});
  std::vector<std::size_t> found;
  for (size_t i = 0; i < points.size(); ++i) {
    neighbor_query(i, found);
    for (std::size_t j : found)
      if (j != i) (*neighbours)[i].push_back(static_cast<int>(j));
  }
  return label;
}

// The typical spacing 1/√ρ of a region's points, ρ (points per m²) the median over its points of
// k / (π r²), r the distance to the k-th nearest neighbour: right where the camera samples a
// surface at a grazing angle (rows far apart, points close along them), where the nearest
// neighbour's distance is not.
// `radius`: that median r (the neighbourhood's reach: along the far-apart rows of a grazing view it
// spans the gap between rows, which the mean spacing does not).
double RegionSpacing(const std::vector<Vec3>& points, const std::vector<int>& indices,
                     const std::vector<std::vector<int>>& neighbours, double* radius) {
  std::vector<double> r2s;
  r2s.reserve(indices.size());
  for (int i : indices) {
    double r2 = 0;
    for (int j : neighbours[i]) r2 = std::max(r2, (points[j] - points[i]).squaredNorm());
    if (r2 > 0) r2s.push_back(r2);
  }
  if (r2s.empty()) return *radius = 0.01;
  std::nth_element(r2s.begin(), r2s.begin() + r2s.size() / 2, r2s.end());
  *radius = std::sqrt(r2s[r2s.size() / 2]);
  const double density = neighbours[indices[0]].size() / (kPi * r2s[r2s.size() / 2]);
  return 1.0 / std::sqrt(density);
}

std::vector<std::vector<int>> Members(const std::vector<int>& label, int regions) {
  std::vector<std::vector<int>> members(regions);
  for (size_t i = 0; i < label.size(); ++i)
    if (label[i] >= 0) members[label[i]].push_back(static_cast<int>(i));
  return members;
}

// Joins k-nearest-neighbour edges by region pair: how many join regions a < b.
std::map<std::pair<int, int>, int> Adjacency(const std::vector<int>& label,
                                             const std::vector<std::vector<int>>& neighbours) {
  std::map<std::pair<int, int>, int> count;
  for (size_t i = 0; i < label.size(); ++i) {
    for (int j : neighbours[i]) {
      if (label[i] < 0 || label[j] < 0 || label[i] == label[j]) continue;
      ++count[{std::min(label[i], label[j]), std::max(label[i], label[j])}];
    }
  }
  return count;
}

// Points left between regions (at edges, where the normals blend two planes) join a neighbouring
// region whose plane they lie on; a few passes close gaps of a few spacings.
void AbsorbEdgePoints(const std::vector<Vec3>& points, const std::vector<std::vector<int>>& neighbours,
                      const std::vector<Plane>& planes, double plane_distance, std::vector<int>* label) {
  for (int pass = 0; pass < 4; ++pass) {
    std::vector<int> next = *label;
    for (size_t i = 0; i < points.size(); ++i) {
      if ((*label)[i] >= 0) continue;
      double best = plane_distance;
      for (int j : neighbours[i]) {
        if ((*label)[j] < 0) continue;
        const double distance = std::abs(planes[(*label)[j]].Distance(points[i]));
        if (distance <= best) best = distance, next[i] = (*label)[j];
      }
    }
    label->swap(next);
  }
}

// Step 3: merges coplanar neighbouring regions (renumbering `label`, refitting `planes`), then
// sorts curved from planar. Returns whether each region is curved.
std::vector<bool> MergeAndClassify(const std::vector<Vec3>& points, const std::vector<std::vector<int>>& neighbours,
                                   const Vec3& viewpoint, const SceneFromPointsOptions& options,
                                   std::vector<int>* label, std::vector<Plane>* planes) {
  int regions = static_cast<int>(planes->size());
  std::map<std::pair<int, int>, int> adjacency = Adjacency(*label, neighbours);
  std::vector<int> parent(regions);
  std::iota(parent.begin(), parent.end(), 0);
  for (const auto& [pair, count] : adjacency) {
    const Plane& a = (*planes)[pair.first];
    const Plane& b = (*planes)[pair.second];
    if (count >= kMinAdjacentEdges && AngleDeg(a.normal, b.normal) <= options.coplanar_angle_deg &&
        std::abs(a.Distance(b.origin)) <= options.plane_distance && std::abs(b.Distance(a.origin)) <= options.plane_distance) {
      parent[Find(parent, pair.first)] = Find(parent, pair.second);
    }
  }
  std::vector<int> renumber(regions, -1);
  int merged = 0;
  for (int r = 0; r < regions; ++r)
    if (Find(parent, r) == r) renumber[r] = merged++;
  for (int& l : *label)
    if (l >= 0) l = renumber[Find(parent, l)];
  regions = merged;
  const std::vector<std::vector<int>> members = Members(*label, regions);
  planes->assign(regions, Plane());
  std::vector<bool> curved(regions, false);
  for (int r = 0; r < regions; ++r) {
    (*planes)[r] = FitPlane(points, members[r], viewpoint);
    double plane_rms = 0, quadratic_rms = 0;
    PlaneAndQuadraticRms(points, members[r], (*planes)[r], &plane_rms, &quadratic_rms);
    curved[r] = std::sqrt(std::max(0.0, plane_rms * plane_rms - quadratic_rms * quadratic_rms)) >
                options.curvature_tolerance;
  }
  adjacency = Adjacency(*label, neighbours);
  for (bool changed = true; changed;) {
    changed = false;
    for (const auto& [pair, count] : adjacency) {
      if (count < kMinAdjacentEdges) continue;
      if (AngleDeg((*planes)[pair.first].normal, (*planes)[pair.second].normal) >= options.smooth_angle_deg) continue;
      // A smooth join: both are one curved surface (two planes here would have merged above).
      if (!curved[pair.first] || !curved[pair.second]) {
        curved[pair.first] = curved[pair.second] = true;
        changed = true;
      }
    }
  }
  return curved;
}

// Step 5b: what region growing left unplanar, in connected groups; a group flat within its own
// noise (a quadratic fit no better than curvature_tolerance, its RMS to the plane at most
// noisy_plane_rms) is a plane measured with more noise than plane_distance allows for (a far wall
// triangulated along its normal): it becomes a planar region of its own.
void PromoteNoisyPlanes(const std::vector<Vec3>& points, const std::vector<std::vector<int>>& neighbours,
                        const Vec3& viewpoint, const SceneFromPointsOptions& options, std::vector<int>* label,
                        std::vector<Plane>* planes, std::vector<bool>* curved) {
  if (!(options.noisy_plane_rms > 0)) return;
  const auto unplanar = [&](int i) { return (*label)[i] < 0 || (*curved)[(*label)[i]]; };
  std::vector<bool> visited(points.size(), false);
  for (size_t seed = 0; seed < points.size(); ++seed) {
    if (visited[seed] || !unplanar(static_cast<int>(seed))) continue;
    std::vector<int> group = {static_cast<int>(seed)};
    visited[seed] = true;
    for (size_t k = 0; k < group.size(); ++k)
      for (int j : neighbours[group[k]])
        if (!visited[j] && unplanar(j)) visited[j] = true, group.push_back(j);
    if (static_cast<int>(group.size()) < options.min_plane_points) continue;
    const Plane plane = FitPlane(points, group, viewpoint);
    double plane_rms = 0, quadratic_rms = 0;
    PlaneAndQuadraticRms(points, group, plane, &plane_rms, &quadratic_rms);
    const double curvature = std::sqrt(std::max(0.0, plane_rms * plane_rms - quadratic_rms * quadratic_rms));
    if (curvature > options.curvature_tolerance || plane_rms > options.noisy_plane_rms) continue;
    const int region = static_cast<int>(planes->size());
    planes->push_back(plane);
    curved->push_back(false);
    for (int i : group) (*label)[i] = region;
  }
}

// Steps 4–5: outlines of the planar regions, snapped to their neighbours' edge lines.
// `surface_of_region`: the index of each region's surface, −1 for none.
std::vector<PlaneSurface> PlaneSurfaces(const std::vector<Vec3>& points, const std::vector<std::vector<int>>& neighbours,
                                        const std::vector<int>& label, const std::vector<Plane>& planes,
                                        const std::vector<bool>& curved, const SceneFromPointsOptions& options,
                                        std::vector<int>* surface_of_region) {
  const int regions = static_cast<int>(planes.size());
  const std::vector<std::vector<int>> members = Members(label, regions);
  std::vector<PlaneSurface> plane_surfaces;
  surface_of_region->assign(regions, -1);
  for (int r = 0; r < regions; ++r) {
    if (curved[r] || static_cast<int>(members[r].size()) < options.min_plane_points) continue;
    PlaneSurface surface;
    surface.plane = planes[r];
    surface.indices = members[r];
    double radius = 0;
    const double spacing = RegionSpacing(points, members[r], neighbours, &radius);
    surface.polygons = Outlines(points, surface, spacing, radius, options);
    if (surface.polygons.empty()) continue;
    (*surface_of_region)[r] = static_cast<int>(plane_surfaces.size());
    plane_surfaces.push_back(std::move(surface));
  }
  return plane_surfaces;
}

// Steps 5 and 6b: each plane's outline corners near a mesh surface (`meshes`: the scan's mesh
// surfaces) onto it, then those near the edge lines with neighbouring planes onto those lines (so
// that where a plane, a neighbouring plane and a mesh meet, the planes' shared edge wins).
// `notches`: what fills notches along the edge lines (SnapRing).
void SnapOutlines(const std::vector<int>& label, const std::vector<std::vector<int>>& neighbours,
                  const std::vector<int>& surface_of_region, const std::vector<Surface>& meshes,
                  const NotchFilling& notches, const SceneFromPointsOptions& options,
                  std::vector<PlaneSurface>* plane_surfaces) {
  std::vector<Triangle3> mesh_triangles;
  for (const Surface& mesh : meshes) {
    for (const MeshTriangle& triangle : mesh.mesh_triangles) {
      std::array<Point3, 3> corner;
      for (int k = 0; k < 3; ++k) {
        const Vec3& v = mesh.mesh_vertices[triangle.vertex[k]];
        corner[k] = Point3(v.x(), v.y(), v.z());
      }
      mesh_triangles.emplace_back(corner[0], corner[1], corner[2]);
    }
  }
  TriangleTree mesh_tree(mesh_triangles.begin(), mesh_triangles.end());
  if (!mesh_triangles.empty()) mesh_tree.accelerate_distance_queries();
  std::vector<std::vector<const Plane*>> plane_neighbours(plane_surfaces->size());
  for (const auto& [pair, count] : Adjacency(label, neighbours)) {
    const int a = surface_of_region[pair.first], b = surface_of_region[pair.second];
    if (count < kMinAdjacentEdges || a < 0 || b < 0) continue;
    plane_neighbours[a].push_back(&(*plane_surfaces)[b].plane);
    plane_neighbours[b].push_back(&(*plane_surfaces)[a].plane);
  }
  for (size_t s = 0; s < plane_surfaces->size(); ++s) {
    PlaneSurface& surface = (*plane_surfaces)[s];
    const auto snap = [&](Polygon2* ring) {
      if (!mesh_triangles.empty())
        surface.snapped += SnapRingToMeshes(surface.plane, mesh_tree, options.snap_distance, ring);
      surface.snapped += SnapRing(surface.plane, plane_neighbours[s], options.snap_distance, notches, ring);
    };
    for (PolygonWithHoles2& polygon : surface.polygons) {
      snap(&polygon.outer_boundary());
      for (auto hole = polygon.holes_begin(); hole != polygon.holes_end(); ++hole) snap(&*hole);
    }
  }
}

// The planar surfaces into `result`, named by their orientation; marks their points. `names` gets
// each plane surface's name, "" for one too small to keep.
void AddPlaneSurfaces(const std::vector<Vec3>& points, const std::vector<PlaneSurface>& plane_surfaces,
                      const SceneFromPointsOptions& options, ScannedScene* result, std::vector<bool>* on_surface,
                      std::vector<std::string>* names) {
  names->assign(plane_surfaces.size(), "");
  const double weld = result->scene.weld_tolerance;
  double floor_z = 1e300, ceiling_z = -1e300;
  int floor = -1, ceiling = -1;
  const double vertical_cos = std::cos((90.0 - options.smooth_angle_deg) * kPi / 180.0);
  const double level_cos = std::cos(options.smooth_angle_deg * kPi / 180.0);
  for (size_t s = 0; s < plane_surfaces.size(); ++s) {
    const Plane& plane = plane_surfaces[s].plane;
    if (plane.normal.z() > level_cos && plane.origin.z() < floor_z) floor_z = plane.origin.z(), floor = int(s);
    if (plane.normal.z() < -level_cos && plane.origin.z() > ceiling_z) ceiling_z = plane.origin.z(), ceiling = int(s);
  }
  int walls = 0, others = 0;
  for (size_t s = 0; s < plane_surfaces.size(); ++s) {
    const PlaneSurface& plane_surface = plane_surfaces[s];
    Surface surface = ToSurface(plane_surface, options, weld);
    if (surface.kind == Surface::Kind::kMesh && surface.mesh_triangles.empty()) continue;
    const double area = surface.Area();
    if (area < options.min_surface_area) continue;
    if (int(s) == floor) surface.name = "floor";
    else if (int(s) == ceiling) surface.name = "ceiling";
    else if (std::abs(plane_surface.plane.normal.z()) < vertical_cos) surface.name = fmt::format("wall_{}", walls++);
    else surface.name = fmt::format("plane_{}", others++);
    if (surface.kind == Surface::Kind::kMesh) surface.mesh_path = surface.name + ".obj";
    ScannedSurfaceStats stats;
    stats.kind = ScannedSurfaceStats::kPlane;
    stats.points = static_cast<int>(plane_surface.indices.size());
    double sum_squares = 0;
    for (int i : plane_surface.indices) {
      sum_squares += std::pow(plane_surface.plane.Distance(points[i]), 2);
      (*on_surface)[i] = true;
    }
    stats.rms_mm = 1000 * std::sqrt(sum_squares / plane_surface.indices.size());
    stats.area_m2 = area;
    for (const PolygonWithHoles2& polygon : plane_surface.polygons) {
      stats.outline_vertices += static_cast<int>(polygon.outer_boundary().size());
      for (auto hole = polygon.holes_begin(); hole != polygon.holes_end(); ++hole) {
        stats.outline_vertices += static_cast<int>(hole->size());
        ++stats.holes;
      }
    }
    stats.snapped_vertices = plane_surface.snapped;
    (*names)[s] = surface.name;
    result->scene.surfaces.push_back(std::move(surface));
    result->stats.push_back(stats);
  }

}

// A group of points too small for a surface: its centroid and the area of its points' convex
// hull in their best-fit plane (FitPlane, CGAL convex_hull_2).
LeftOutGroup DescribeLeftOut(const std::vector<Vec3>& points, const std::vector<int>& indices,
                             const Vec3& viewpoint) {
  const Plane plane = FitPlane(points, indices, viewpoint);
  LeftOutGroup group;
  group.points = static_cast<int>(indices.size());
  group.centroid = plane.origin;
  std::vector<Kernel::Point_2> in_plane, hull;
  for (int i : indices) {
    const Vec2 uv = plane.ToPlane(points[i]);
    in_plane.emplace_back(uv.x(), uv.y());
  }
  CGAL::convex_hull_2(in_plane.begin(), in_plane.end(), std::back_inserter(hull));
  if (hull.size() >= 3) group.area_m2 = std::abs(CGAL::polygon_area_2(hull.begin(), hull.end(), Kernel()));
  return group;
}

// The plane surface under each left-out group: the one that more than half of its points lie on,
// within snap_distance of the plane and inside its outer outline; -1 for none. A hole of that
// surface holding more than half of the group's points is closed: the group's own points, measured
// off the plane, cut it, not a gap in the surface.
std::vector<int> FindSurfacesUnderLeftOut(const std::vector<Vec3>& points,
                                          const std::vector<std::vector<int>>& members, double snap_distance,
                                          std::vector<PlaneSurface>* plane_surfaces) {
  std::vector<int> under(members.size(), -1);
  for (size_t g = 0; g < members.size(); ++g) {
    for (size_t s = 0; s < plane_surfaces->size() && under[g] < 0; ++s) {
      PlaneSurface& surface = (*plane_surfaces)[s];
      std::vector<Point2> near;
      for (int i : members[g]) {
        if (std::abs(surface.plane.Distance(points[i])) > snap_distance) continue;
        const Vec2 uv = surface.plane.ToPlane(points[i]);
        near.emplace_back(uv.x(), uv.y());
      }
      const auto count_inside = [&](const Polygon2& ring) {
        return std::count_if(near.begin(), near.end(),
                             [&](const Point2& at) { return InsideEvenOdd(ring.container(), at); });
      };
      for (PolygonWithHoles2& polygon : surface.polygons) {
        if (2 * count_inside(polygon.outer_boundary()) <= static_cast<long>(members[g].size())) continue;
        under[g] = static_cast<int>(s);
        PolygonWithHoles2 kept(polygon.outer_boundary());
        for (auto hole = polygon.holes_begin(); hole != polygon.holes_end(); ++hole) {
          if (2 * count_inside(*hole) <= static_cast<long>(members[g].size())) kept.add_hole(*hole);
        }
        polygon = std::move(kept);
        break;
      }
    }
  }
  return under;
}

// Step 6: the points marked `for_mesh`, in connected groups, as mesh surfaces into `result`.
// `left_out_members` gets each left-out group's points, in result->left_out's order.
void AddMeshSurfaces(const std::vector<Vec3>& points, const std::vector<std::vector<int>>& neighbours,
                     const std::vector<bool>& for_mesh, const Vec3& viewpoint, const SceneFromPointsOptions& options,
                     ScannedScene* result, std::vector<bool>* on_surface,
                     std::vector<std::vector<int>>* left_out_members) {
  const double weld = result->scene.weld_tolerance;
  std::vector<int> group(points.size(), -1);
  int meshes = 0;
  for (size_t seed = 0; seed < points.size(); ++seed) {
    if (!for_mesh[seed] || group[seed] >= 0) continue;
    std::vector<int> indices = {static_cast<int>(seed)};
    group[seed] = static_cast<int>(seed);
    for (size_t k = 0; k < indices.size(); ++k) {
      for (int j : neighbours[indices[k]]) {
        if (for_mesh[j] && group[j] < 0) group[j] = static_cast<int>(seed), indices.push_back(j);
      }
    }
    if (static_cast<int>(indices.size()) < options.min_mesh_points) {
      if (indices.size() >= 3) {
        result->left_out.push_back(DescribeLeftOut(points, indices, viewpoint));
        left_out_members->push_back(std::move(indices));
      }
      continue;
    }
    std::vector<Vec3> group_points;
    for (int i : indices) group_points.push_back(points[i]);
    std::vector<Vec3> vertices;
    std::vector<std::array<int, 3>> triangles;
    double smoothing_rms = 0;
    ReconstructMesh(group_points, viewpoint, options.smoothing_neighbors, options.mesh_vertex_spacing, options.mesh_tolerance,
                    options.max_mesh_edges > 0 ? options.max_mesh_edges : options.target_patches, &vertices,
                    &triangles, &smoothing_rms);
    Surface surface;
    surface.kind = Surface::Kind::kMesh;
    surface.reflectance = options.reflectance;
    surface.desired.srgb = options.desired_srgb;
    // Keep the vertices the triangles use, and no sliver the scene reader would refuse.
    std::vector<int> new_index(vertices.size(), -1);
    for (const std::array<int, 3>& t : triangles) {
      std::array<Vec3, 3> corners = {vertices[t[0]], vertices[t[1]], vertices[t[2]]};
      std::string sliver;
      if (!CheckPlanarConvexPolygon(corners.data(), 3, 2 * weld, &sliver)) continue;
      MeshTriangle mesh_triangle;
      for (int k = 0; k < 3; ++k) {
        if (new_index[t[k]] < 0) {
          new_index[t[k]] = static_cast<int>(surface.mesh_vertices.size());
          surface.mesh_vertices.push_back(vertices[t[k]]);
        }
        mesh_triangle.vertex[k] = new_index[t[k]];
      }
      surface.mesh_triangles.push_back(mesh_triangle);
    }
    if (surface.mesh_triangles.empty() || surface.Area() < options.min_surface_area) continue;
    // Texture coordinates: the vertices projected on the mesh's two main directions (PCA),
    // scaled to [0, 1] over its extent (a curved wall's texture lies along its chord).
    Vec3 mean = Vec3::Zero();
    for (const Vec3& v : surface.mesh_vertices) mean += v / surface.mesh_vertices.size();
    Eigen::Matrix3d spread = Eigen::Matrix3d::Zero();
    for (const Vec3& v : surface.mesh_vertices) spread += (v - mean) * (v - mean).transpose();
    const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> axes(spread);
    const Vec3 u_axis = axes.eigenvectors().col(2), v_axis = axes.eigenvectors().col(1);
    Vec2 low = Vec2::Constant(1e300), high = Vec2::Constant(-1e300);
    for (const Vec3& v : surface.mesh_vertices) {
      const Vec2 uv((v - mean).dot(u_axis), (v - mean).dot(v_axis));
      low = low.cwiseMin(uv), high = high.cwiseMax(uv);
    }
    const Vec2 size = (high - low).cwiseMax(Vec2::Constant(1e-9));
    for (MeshTriangle& triangle : surface.mesh_triangles)
      for (int k = 0; k < 3; ++k) {
        const Vec3& v = surface.mesh_vertices[triangle.vertex[k]];
        const Vec2 uv((v - mean).dot(u_axis), (v - mean).dot(v_axis));
        triangle.uv[k] = ((uv - low).cwiseQuotient(size)).cwiseMax(0.0).cwiseMin(1.0);
      }
    surface.name = fmt::format("mesh_{}", meshes++);
    surface.mesh_path = surface.name + ".obj";
    ScannedSurfaceStats stats;
    stats.kind = ScannedSurfaceStats::kMesh;
    stats.points = static_cast<int>(indices.size());
    for (int i : indices) (*on_surface)[i] = true;
    stats.rms_mm = 1000 * smoothing_rms;
    stats.area_m2 = surface.Area();
    stats.outline_vertices = static_cast<int>(surface.mesh_triangles.size());
    result->scene.surfaces.push_back(std::move(surface));
    result->stats.push_back(stats);
  }
}

}  // namespace

bool SceneFromPointsOptions::Check(std::string* why) const {
  auto fail = [&](const std::string& text) {
    if (why) *why = text;
    return false;
  };
  if (!viewpoint.allFinite() && !viewpoint.hasNaN()) return fail("viewpoint must be finite (or NaN: automatic)");
  if (normal_neighbors < 6) return fail("normal_neighbors must be ≥ 6");
  if (growing_neighbors < 4) return fail("growing_neighbors must be ≥ 4");
  if (!(plane_distance > 0)) return fail("plane_distance must be > 0");
  if (!(noisy_plane_rms >= 0)) return fail("noisy_plane_rms must be ≥ 0");
  if (!(plane_angle_deg > 0 && plane_angle_deg < 90)) return fail("plane_angle_deg must be in (0, 90)");
  if (min_plane_points < 3) return fail("min_plane_points must be ≥ 3");
  if (!(curvature_tolerance > 0)) return fail("curvature_tolerance must be > 0");
  if (!(smooth_angle_deg > 0 && smooth_angle_deg < 90)) return fail("smooth_angle_deg must be in (0, 90)");
  if (!(coplanar_angle_deg >= 0 && coplanar_angle_deg < smooth_angle_deg))
    return fail("coplanar_angle_deg must be in [0, smooth_angle_deg)");
  if (!(outline_alpha_spacings > 0.5)) return fail("outline_alpha_spacings must be > 0.5");
  if (!(outline_tolerance > 0)) return fail("outline_tolerance must be > 0");
  if (!(snap_distance >= 0)) return fail("snap_distance must be ≥ 0");
  if (!(max_notch_deg >= 0 && max_notch_deg < 90)) return fail("max_notch_deg must be in [0, 90)");
  if (!(min_hole_area >= 0) || !(min_surface_area >= 0)) return fail("min_hole_area and min_surface_area must be ≥ 0");
  if (min_mesh_points < 3) return fail("min_mesh_points must be ≥ 3");
  if (points_on_viewpoint_rays && !viewpoint.allFinite())
    return fail("points_on_viewpoint_rays needs a viewpoint");
  if (smoothing_neighbors != 0 && smoothing_neighbors < 6) return fail("smoothing_neighbors must be 0 or ≥ 6");
  if (!(mesh_vertex_spacing >= 0)) return fail("mesh_vertex_spacing must be ≥ 0");
  if (!(mesh_tolerance >= 0)) return fail("mesh_tolerance must be ≥ 0");
  if (max_mesh_edges < 0) return fail("max_mesh_edges must be ≥ 0");
  if (!((reflectance.array() >= 0).all() && (reflectance.array() < 1).all()))
    return fail("reflectance: each value must be in [0, 1)");
  if (!((desired_srgb.array() >= 0).all() && (desired_srgb.array() <= 1).all()))
    return fail("desired_srgb: each value must be in [0, 1]");
  if (target_patches < 1) return fail("target_patches must be ≥ 1");
  return true;
}

std::string ScannedScene::Report() const {
  std::string text;
  for (size_t s = 0; s < scene.surfaces.size() && s < stats.size(); ++s) {
    const ScannedSurfaceStats& st = stats[s];
    if (st.kind == ScannedSurfaceStats::kPlane) {
      text += fmt::format("{}: plane, {} points, RMS {:.1f} mm, {:.3f} m², {} corners, {} holes, {} snapped\n",
                          scene.surfaces[s].name, st.points, st.rms_mm, st.area_m2, st.outline_vertices,
                          st.holes, st.snapped_vertices);
    } else {
      text += fmt::format("{}: mesh, {} points, RMS {:.1f} mm, {:.3f} m², {} triangles\n", scene.surfaces[s].name,
                          st.points, st.rms_mm, st.area_m2, st.outline_vertices);
    }
  }
  text += fmt::format("{} surfaces from {} points ({} on none), spacing {:.1f} mm, {:.2f} s\n",
                      scene.surfaces.size(), points, unassigned, 1000 * mean_spacing, time_s);
  if (!left_out.empty()) {
    const LeftOutGroup& group = left_out.front();
    text += fmt::format("largest group on none: {} points over {:.3f} m² around ({:.2f}, {:.2f}, {:.2f}) m{}\n",
                        group.points, group.area_m2, group.centroid.x(), group.centroid.y(), group.centroid.z(),
                        group.on_surface.empty() ? "" : ", within " + group.on_surface + "'s outline");
  }
  return text;
}

std::string LeftOutSurfaceError(const ScannedScene& scanned, const SceneFromPointsOptions& options,
                                double max_fraction, double min_area_m2) {
  double scanned_area = 0.0;
  for (const ScannedSurfaceStats& stats : scanned.stats) scanned_area += stats.area_m2;
  const double limit = std::max(min_area_m2, max_fraction * scanned_area);
  const auto missed = std::find_if(scanned.left_out.begin(), scanned.left_out.end(),
                                   [](const LeftOutGroup& group) { return group.on_surface.empty(); });
  if (missed == scanned.left_out.end() || !(missed->area_m2 > limit)) return "";
  const LeftOutGroup& group = *missed;
  return fmt::format(
      "{} points spread over {:.2f} m² around ({:.2f}, {:.2f}, {:.2f}) m are too few for a surface "
      "(a plane needs {}, a curved surface {}): decoding failed over part of the room there (a "
      "dark, glossy or out-of-focus surface, or a grazing view)",
      group.points, group.area_m2, group.centroid.x(), group.centroid.y(), group.centroid.z(),
      options.min_plane_points, options.min_mesh_points);
}

ScannedScene SceneFromPoints(const std::vector<Vec3>& points, const SceneFromPointsOptions& options) {
  const Clock::time_point start = Clock::now();
  std::string why;
  if (!options.Check(&why)) throw std::invalid_argument("SceneFromPoints: " + why);
  if (static_cast<int>(points.size()) < std::max(options.min_plane_points, options.normal_neighbors + 1)) {
    throw std::invalid_argument(fmt::format("SceneFromPoints: {} points are too few (at least {})", points.size(),
                                            std::max(options.min_plane_points, options.normal_neighbors + 1)));
  }
  Vec3 lower = points[0], upper = points[0];
  for (size_t i = 0; i < points.size(); ++i) {
    if (!points[i].allFinite()) throw std::invalid_argument(fmt::format("SceneFromPoints: point {} is not finite", i));
    lower = lower.cwiseMin(points[i]), upper = upper.cwiseMax(points[i]);
  }
  const Vec3 viewpoint = options.viewpoint.allFinite() ? options.viewpoint : Vec3(0.5 * (lower + upper));

  ScannedScene result;
  result.points = static_cast<int>(points.size());
  std::vector<std::vector<int>> neighbours;
  std::vector<int> label = GrowPlanarRegions(points, options, &result.mean_spacing, &neighbours);
  const int regions = 1 + *std::max_element(label.begin(), label.end());

  std::vector<Plane> planes(regions);
  const std::vector<std::vector<int>> members = Members(label, regions);
  for (int r = 0; r < regions; ++r) planes[r] = FitPlane(points, members[r], viewpoint);
  AbsorbEdgePoints(points, neighbours, planes, options.plane_distance, &label);
  std::vector<bool> curved = MergeAndClassify(points, neighbours, viewpoint, options, &label, &planes);
  PromoteNoisyPlanes(points, neighbours, viewpoint, options, &label, &planes, &curved);
  std::vector<int> surface_of_region;
  std::vector<PlaneSurface> plane_surfaces =
      PlaneSurfaces(points, neighbours, label, planes, curved, options, &surface_of_region);
  // Step 6: what no plane took, in connected groups, as meshes (listed after the planes).
  std::vector<bool> for_mesh(points.size(), false);
  for (size_t i = 0; i < points.size(); ++i) {
    for_mesh[i] = label[i] < 0 ? true : curved[label[i]] || surface_of_region[label[i]] < 0;
  }
  std::vector<bool> on_surface(points.size(), false);
  ScannedScene meshes;
  std::vector<std::vector<int>> left_out_members;
  AddMeshSurfaces(points, neighbours, for_mesh, viewpoint, options, &meshes, &on_surface, &left_out_members);
  NotchFilling notches;
  notches.viewpoint = viewpoint;
  notches.max_angle = options.max_notch_deg * kPi / 180.0;
  notches.points = &points;
  SnapOutlines(label, neighbours, surface_of_region, meshes.scene.surfaces, notches, options, &plane_surfaces);
  const std::vector<int> under_left_out =
      FindSurfacesUnderLeftOut(points, left_out_members, options.snap_distance, &plane_surfaces);
  std::vector<std::string> plane_names;
  AddPlaneSurfaces(points, plane_surfaces, options, &result, &on_surface, &plane_names);
  for (size_t g = 0; g < meshes.left_out.size(); ++g) {
    if (under_left_out[g] >= 0) meshes.left_out[g].on_surface = plane_names[under_left_out[g]];
  }
  for (Surface& mesh : meshes.scene.surfaces) result.scene.surfaces.push_back(std::move(mesh));
  result.stats.insert(result.stats.end(), meshes.stats.begin(), meshes.stats.end());
  result.left_out.insert(result.left_out.end(), meshes.left_out.begin(), meshes.left_out.end());
  result.unassigned = static_cast<int>(std::count(on_surface.begin(), on_surface.end(), false));
  std::sort(result.left_out.begin(), result.left_out.end(),
            [](const LeftOutGroup& a, const LeftOutGroup& b) { return a.area_m2 > b.area_m2; });
  result.scene.name = "scan";
  result.scene.target_patches = options.target_patches;
  result.time_s = SecondsSince(start);
  return result;
}

std::filesystem::path WriteScannedScene(const std::filesystem::path& dir, const ScannedScene& scanned) {
  std::error_code error;
  std::filesystem::create_directories(dir, error);
  if (error) throw IoError(dir.string() + ": cannot create the directory: " + error.message());
  using json = nlohmann::ordered_json;
  auto triple = [](const Vec3& v) { return json::array({v.x(), v.y(), v.z()}); };
  json surfaces = json::array();
  for (const Surface& surface : scanned.scene.surfaces) {
    json entry = {{"name", surface.name}};
    if (surface.kind == Surface::Kind::kQuad) {
      entry["quad"] = json::array();
      for (const Vec3& corner : surface.quad) entry["quad"].push_back(triple(corner));
    } else {
      WriteFileAtomically(dir / surface.mesh_path, ObjMeshText(surface, "written by procam (scene from points)"));
      entry["mesh"] = surface.mesh_path;
    }
    entry["reflectance"] = triple(surface.reflectance);
    entry["desired"] = triple(surface.desired.srgb);
    surfaces.push_back(entry);
  }
  const json file = {{"name", scanned.scene.name},
                     {"description", "built from a scanned point cloud by procam"},
                     {"patches", scanned.scene.target_patches},
                     {"weld_tolerance", scanned.scene.weld_tolerance},
                     {"surfaces", surfaces}};
  const std::filesystem::path path = dir / "room.json";
  WriteFileAtomically(path, file.dump(2) + "\n");  // last: the OBJs it names are complete
  return path;
}

}  // namespace procam
