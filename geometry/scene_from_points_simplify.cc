// SimplifyMesh (scene_from_points_mesh.h): edge collapse held near the input, in its own file
// because CGAL's simplification is a slow compile.
#include <CGAL/AABB_segment_primitive.h>
#include <CGAL/AABB_traits.h>
#include <CGAL/AABB_tree.h>
#include <CGAL/AABB_triangle_primitive.h>
#include <CGAL/Exact_predicates_inexact_constructions_kernel.h>
#include <CGAL/Polygon_mesh_processing/orient_polygon_soup.h>
#include <CGAL/Polygon_mesh_processing/polygon_soup_to_polygon_mesh.h>
#include <CGAL/Surface_mesh.h>
#include <CGAL/Surface_mesh_simplification/Policies/Edge_collapse/Count_stop_predicate.h>
#include <CGAL/Surface_mesh_simplification/Policies/Edge_collapse/LindstromTurk_cost.h>
#include <CGAL/Surface_mesh_simplification/Policies/Edge_collapse/LindstromTurk_placement.h>
#include <CGAL/Surface_mesh_simplification/edge_collapse.h>

#include <algorithm>
#include <limits>

#include "geometry/scene_from_points_mesh.h"

namespace procam {
namespace {

using Kernel = CGAL::Exact_predicates_inexact_constructions_kernel;
using Point = Kernel::Point_3;
using Triangle = Kernel::Triangle_3;
using Segment = Kernel::Segment_3;
using Mesh = CGAL::Surface_mesh<Point>;
using TriangleTree = CGAL::AABB_tree<
    CGAL::AABB_traits<Kernel, CGAL::AABB_triangle_primitive<Kernel, std::vector<Triangle>::const_iterator>>>;
using SegmentTree = CGAL::AABB_tree<
    CGAL::AABB_traits<Kernel, CGAL::AABB_segment_primitive<Kernel, std::vector<Segment>::const_iterator>>>;
namespace SMS = CGAL::Surface_mesh_simplification;

// A border vertex's neighbours along the border: the source of its incoming border halfedge
// and the target of the one after it.
std::pair<Mesh::Vertex_index, Mesh::Vertex_index> BorderNeighbours(const Mesh& mesh, Mesh::Vertex_index v) {
  for (Mesh::Halfedge_index h : CGAL::halfedges_around_target(v, mesh)) {
    if (mesh.is_border(h)) return {mesh.source(h), mesh.target(mesh.next(h))};
  }
  return {Mesh::null_vertex(), Mesh::null_vertex()};
}

// Lindstrom–Turk's placement, except where the collapse touches the border: a border vertex
// keeps its place when the other end is inside, and an inner edge between two border vertices
// is not collapsed (it would pinch the surface). Only border edges move the border.
class BorderPlacement {
 public:
  template <typename Profile>
  boost::optional<typename Profile::Point> operator()(const Profile& profile) const {
    const Mesh& mesh = profile.surface_mesh();
    const bool border0 = mesh.is_border(profile.v0()), border1 = mesh.is_border(profile.v1());
    if (border0 && border1) {
      if (!profile.is_v0_v1_a_border() && !profile.is_v1_v0_a_border()) return boost::none;
      return base_(profile);
    }
    if (border0) return profile.p0();
    if (border1) return profile.p1();
    return base_(profile);
  }

 private:
  SMS::LindstromTurk_placement<Mesh> base_;
};

// Edge-collapse filter: refuses a collapse that would put the new vertex p, or a sample of the
// triangles around it (the midpoints of their edges at p and their centroids), farther than the
// tolerance from the input mesh, and for a border edge, p or the midpoints of the new border
// edges farther than it from the input's border. The edges away from p are old ones, already
// near it. Samples, not CGAL's exact polyhedral envelope: that took 3 minutes on a 93 000-
// triangle curved wall; the accuracy is measured (tests/geometry).
class StaysNearInput {
 public:
  StaysNearInput(const TriangleTree& surface, const SegmentTree& border, double tolerance)
      : surface_(surface), border_(border), tolerance2_(tolerance * tolerance) {}

  template <typename Profile>
  boost::optional<typename Profile::Point> operator()(const Profile& profile,
                                                      const boost::optional<typename Profile::Point>& p) const {
    if (!p || std::isinf(tolerance2_)) return p;
    if (!Near(surface_, *p)) return boost::none;
    for (const auto& triangle : profile.triangles()) {
      Point corner[3];
      int at_p = -1, k = 0;
      for (const auto v : {triangle.v0, triangle.v1, triangle.v2}) {
        const bool moved = v == profile.v0() || v == profile.v1();
        corner[k] = moved ? *p : get(profile.vertex_point_map(), v);
        if (moved) at_p = k;
        ++k;
      }
      if (at_p < 0) continue;
      const Point& a = corner[(at_p + 1) % 3];
      const Point& b = corner[(at_p + 2) % 3];
      if (!Near(surface_, CGAL::midpoint(*p, a)) || !Near(surface_, CGAL::midpoint(*p, b)) ||
          !Near(surface_, CGAL::centroid(*p, a, b)))
        return boost::none;
    }
    if (profile.is_v0_v1_a_border() || profile.is_v1_v0_a_border()) {
      const Mesh& mesh = profile.surface_mesh();
      if (!Near(border_, *p)) return boost::none;
      for (Mesh::Vertex_index end : {profile.v0(), profile.v1()}) {
        const auto [before, after] = BorderNeighbours(mesh, end);
        for (Mesh::Vertex_index v : {before, after}) {
          if (v == Mesh::null_vertex() || v == profile.v0() || v == profile.v1()) continue;
          if (!Near(border_, CGAL::midpoint(*p, mesh.point(v)))) return boost::none;
        }
      }
    }
    return p;
  }

 private:
  template <typename Tree>
  bool Near(const Tree& tree, const Point& q) const {
    return tree.squared_distance(q) <= tolerance2_;
  }
  const TriangleTree& surface_;
  const SegmentTree& border_;
  double tolerance2_;
};

}  // namespace

int SimplifyMesh(double tolerance, int max_edges, std::vector<Vec3>* vertices,
                 std::vector<std::array<int, 3>>* triangles) {
  namespace PMP = CGAL::Polygon_mesh_processing;
  // Triangles are fewer than edges: more triangles than max_edges means more edges too.
  const bool over = max_edges > 0 && static_cast<int>(triangles->size()) > max_edges;
  if ((!(tolerance > 0) && !over) || triangles->empty()) return 0;

  std::vector<Point> points;
  points.reserve(vertices->size());
  for (const Vec3& v : *vertices) points.emplace_back(v.x(), v.y(), v.z());
  std::vector<std::array<std::size_t, 3>> polygons;
  polygons.reserve(triangles->size());
  for (const std::array<int, 3>& t : *triangles) polygons.push_back({size_t(t[0]), size_t(t[1]), size_t(t[2])});
  // Advancing front gives a consistently oriented manifold as a rule; where it does not (a
  // non-manifold vertex), the mesh stays as it is rather than be repaired into something else.
  if (!PMP::orient_polygon_soup(points, polygons) || !PMP::is_polygon_soup_a_polygon_mesh(polygons)) return 0;
  Mesh mesh;
  PMP::polygon_soup_to_polygon_mesh(points, polygons, mesh);

  // The input's surface and border, for the distance checks.
  std::vector<Triangle> input;
  input.reserve(mesh.number_of_faces());
  for (Mesh::Face_index f : mesh.faces()) {
    const Mesh::Halfedge_index h = mesh.halfedge(f);
    input.emplace_back(mesh.point(mesh.source(h)), mesh.point(mesh.target(h)), mesh.point(mesh.target(mesh.next(h))));
  }
  std::vector<Segment> border;
  for (Mesh::Halfedge_index h : mesh.halfedges())
    if (mesh.is_border(h)) border.emplace_back(mesh.point(mesh.source(h)), mesh.point(mesh.target(h)));
  TriangleTree surface_tree(input.begin(), input.end());
  surface_tree.accelerate_distance_queries();
  SegmentTree border_tree(border.begin(), border.end());
  if (!border.empty()) border_tree.accelerate_distance_queries();

  // CGAL's Count_stop_predicate counts edges: collapsing ends below max_edges of them.
  const auto collapse = [&](double distance, int stop_at) {
    SMS::Count_stop_predicate<Mesh> stop(std::max(1, stop_at));
    return SMS::edge_collapse(mesh, stop,
                              CGAL::parameters::get_cost(SMS::LindstromTurk_cost<Mesh>())
                                  .get_placement(BorderPlacement())
                                  .filter(StaysNearInput(surface_tree, border_tree, distance)));
  };
  int collapsed = 0;
  if (tolerance > 0) collapsed += collapse(tolerance, max_edges);
  // Still more than the cap: the cheapest collapses go on, whatever the tolerance.
  if (max_edges > 0 && static_cast<int>(mesh.number_of_faces()) > max_edges)
    collapsed += collapse(std::numeric_limits<double>::infinity(), max_edges);
  mesh.collect_garbage();

  std::vector<Vec3> kept;
  kept.reserve(mesh.number_of_vertices());
  for (Mesh::Vertex_index v : mesh.vertices()) {
    const Point& p = mesh.point(v);
    kept.emplace_back(p.x(), p.y(), p.z());
  }
  std::vector<std::array<int, 3>> faces;
  faces.reserve(mesh.number_of_faces());
  for (Mesh::Face_index f : mesh.faces()) {
    const Mesh::Halfedge_index h = mesh.halfedge(f);
    faces.push_back({static_cast<int>(mesh.source(h).idx()), static_cast<int>(mesh.target(h).idx()),
                     static_cast<int>(mesh.target(mesh.next(h)).idx())});
  }
  *vertices = std::move(kept);
  *triangles = std::move(faces);
  return collapsed;
}

}  // namespace procam
