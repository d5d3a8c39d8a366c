#include "geometry/patches.h"

#include <algorithm>
#include <cmath>
#include <map>
#include <numbers>
#include <set>
#include <unordered_map>

#include "geometry/polygon.h"

namespace procam {
namespace {

void FinishPatch(Patch* patch) {
  patch->area = PolygonArea(patch->corners.data(), patch->corner_count);
  patch->centroid = PolygonCentroid(patch->corners.data(), patch->corner_count);
  patch->normal = NewellNormal(patch->corners.data(), patch->corner_count).normalized();
}

Vec3 Bilinear(const std::array<Vec3, 4>& c, double u, double v) {
  return (1 - u) * (1 - v) * c[0] + u * (1 - v) * c[1] + u * v * c[2] + (1 - u) * v * c[3];
}

// Grid cell (a, b) of an nu × nv subdivision of a quad surface.
Patch QuadCell(const Surface& surface, int surface_index, int nu, int nv, int a, int b) {
  Patch patch;
  patch.surface = surface_index;
  patch.corner_count = 4;
  const double u0 = double(a) / nu, u1 = double(a + 1) / nu;
  const double v0 = double(b) / nv, v1 = double(b + 1) / nv;
  const double us[4] = {u0, u1, u1, u0};
  const double vs[4] = {v0, v0, v1, v1};
  for (int k = 0; k < 4; ++k) {
    patch.corners[k] = Bilinear(surface.quad, us[k], vs[k]);
    patch.uv[k] = Vec2(us[k], vs[k]);
  }
  FinishPatch(&patch);
  return patch;
}

// Triangle of a uniform midpoint split: level L splits each triangle into 4^L.
void SplitTriangle(const Patch& triangle, int levels, std::vector<Patch>* out) {
  if (levels == 0) {
    out->push_back(triangle);
    return;
  }
  const auto& p = triangle.corners;
  const auto& t = triangle.uv;
  const Vec3 m01 = 0.5 * (p[0] + p[1]), m12 = 0.5 * (p[1] + p[2]), m20 = 0.5 * (p[2] + p[0]);
  const Vec2 n01 = 0.5 * (t[0] + t[1]), n12 = 0.5 * (t[1] + t[2]), n20 = 0.5 * (t[2] + t[0]);
  const std::array<std::array<Vec3, 3>, 4> points = {{{p[0], m01, m20}, {m01, p[1], m12},
                                                     {m20, m12, p[2]}, {m01, m12, m20}}};
  const std::array<std::array<Vec2, 3>, 4> uvs = {{{t[0], n01, n20}, {n01, t[1], n12},
                                                  {n20, n12, t[2]}, {n01, n12, n20}}};
  for (int child = 0; child < 4; ++child) {
    Patch sub = triangle;
    for (int k = 0; k < 3; ++k) {
      sub.corners[k] = points[child][k];
      sub.uv[k] = uvs[child][k];
    }
    FinishPatch(&sub);
    SplitTriangle(sub, levels - 1, out);
  }
}

void FillAttributes(const Scene& scene, int texture_samples, PatchLevel* level) {
  const int n = level->size();
  level->reflectance.resize(n, 3);
  level->desired_linear.resize(n, 3);
  std::vector<PatchSample> samples;
  for (int i = 0; i < n; ++i) {
    const Patch& patch = level->patches[i];
    const Surface& surface = scene.surfaces[patch.surface];
    if (surface.reflectance_texture.HasTexture()) {
      // A printed surface: the patch's reflectance is the texture's area-weighted mean over the
      // patch, by the same quadrature as the desired texture's.
      SamplePatch(patch, texture_samples, &samples);
      Vec3 reflectance = Vec3::Zero();
      for (const PatchSample& sample : samples)
        reflectance += sample.weight * surface.reflectance_texture.At(sample.uv);
      level->reflectance.row(i) = (reflectance / patch.area).transpose();
    } else {
      level->reflectance.row(i) = surface.reflectance.transpose();
    }
    Vec3 desired = Vec3::Zero();
    if (surface.desired.HasTexture()) {
      SamplePatch(patch, texture_samples, &samples);
      for (const PatchSample& sample : samples) desired += sample.weight * surface.desired.LinearAt(sample.uv);
      desired /= patch.area;
    } else {
      desired = surface.desired.LinearAt(Vec2::Zero());
    }
    level->desired_linear.row(i) = scene.white * desired.transpose();
  }
}

}  // namespace

Eigen::VectorXd PatchLevel::Areas() const {
  Eigen::VectorXd areas(size());
  for (int i = 0; i < size(); ++i) areas[i] = patches[i].area;
  return areas;
}

bool SubdivisionOptions::Check(std::string* why) const {
  if (target_patches < 1) {
    *why = "target_patches must be >= 1";
    return false;
  }
  if (texture_samples < 1 || texture_samples > 64) {
    *why = "texture_samples must be in [1, 64]";
    return false;
  }
  return true;
}

void SamplePatch(const Patch& patch, int k, std::vector<PatchSample>* samples) {
  samples->clear();
  const GaussLegendreRule& rule = GaussLegendre(k);
  const auto& c = patch.corners;
  const auto& t = patch.uv;
  for (int a = 0; a < k; ++a) {
    for (int b = 0; b < k; ++b) {
      const double u = rule.nodes[a], v = rule.nodes[b];
      if (patch.corner_count == 4) {
        // Bilinear map of the unit square; |∂P/∂u × ∂P/∂v| is bilinear for a planar quad.
        const Vec3 du = (1 - v) * (c[1] - c[0]) + v * (c[2] - c[3]);
        const Vec3 dv = (1 - u) * (c[3] - c[0]) + u * (c[2] - c[1]);
        const Vec2 uv = (1 - u) * (1 - v) * t[0] + u * (1 - v) * t[1] + u * v * t[2] + (1 - u) * v * t[3];
        samples->push_back({Bilinear(c, u, v), uv, rule.weights[a] * rule.weights[b] * du.cross(dv).norm()});
      } else {
        // Duffy's collapsed square: P = c0 + u((c1 − c0) + v(c2 − c1)), Jacobian 2A·u.
        const Vec3 point = c[0] + u * ((c[1] - c[0]) + v * (c[2] - c[1]));
        const Vec2 uv = t[0] + u * ((t[1] - t[0]) + v * (t[2] - t[1]));
        samples->push_back({point, uv, rule.weights[a] * rule.weights[b] * 2.0 * patch.area * u});
      }
    }
  }
}

const GaussLegendreRule& GaussLegendre(int k) {
  static const std::vector<GaussLegendreRule> rules = [] {
    std::vector<GaussLegendreRule> table(kMaxQuadratureOrder + 1);
    for (int n = 1; n <= kMaxQuadratureOrder; ++n) {
      GaussLegendreRule& rule = table[n];
      rule.nodes.resize(n);
      rule.weights.resize(n);
      for (int i = 0; i < n; ++i) {
        // Newton's method on P_n from the Chebyshev-like first guess, on [-1, 1].
        double x = std::cos(std::numbers::pi * (i + 0.75) / (n + 0.5)), derivative = 1.0;
        for (int iteration = 0; iteration < 100; ++iteration) {
          double p0 = 1.0, p1 = x;
          for (int order = 2; order <= n; ++order) {
            const double p2 = ((2 * order - 1) * x * p1 - (order - 1) * p0) / order;
            p0 = p1;
            p1 = p2;
          }
          derivative = n * (x * p1 - p0) / (x * x - 1.0);
          const double step = p1 / derivative;
          x -= step;
          if (std::abs(step) < 1e-16) break;
        }
        rule.nodes[i] = 0.5 * (1.0 - x);  // map to [0, 1], ascending
        rule.weights[i] = 1.0 / ((1.0 - x * x) * derivative * derivative);  // (2/((1−x²)P'²))/2
      }
    }
    return table;
  }();
  return rules.at(std::clamp(k, 1, kMaxQuadratureOrder));
}

std::vector<std::array<int, 2>> FindAdjacency(const std::vector<Patch>& patches, double tolerance) {
  // Exact pass: weld corners, then edges with the same two corner indices are shared.
  PointWelder welder(tolerance);
  std::map<std::pair<int, int>, std::vector<int>> owners;
  struct Edge {
    Vec3 a, b;
    int patch;
  };
  for (int i = 0; i < static_cast<int>(patches.size()); ++i) {
    const Patch& patch = patches[i];
    for (int k = 0; k < patch.corner_count; ++k) {
      const int a = welder.Weld(patch.corners[k]);
      const int b = welder.Weld(patch.corners[(k + 1) % patch.corner_count]);
      owners[{std::min(a, b), std::max(a, b)}].push_back(i);
    }
  }
  std::set<std::pair<int, int>> pairs;
  std::vector<Edge> boundary;
  for (const auto& [edge, list] : owners) {
    for (size_t x = 0; x < list.size(); ++x) {
      for (size_t y = x + 1; y < list.size(); ++y) {
        if (list[x] != list[y]) pairs.insert({std::min(list[x], list[y]), std::max(list[x], list[y])});
      }
    }
    if (list.size() == 1) boundary.push_back({welder.points()[edge.first], welder.points()[edge.second], list[0]});
  }
  // Overlap pass for boundary edges (surfaces meeting with different subdivisions): bucket
  // edges in a grid of cells about one edge long, compare edges sharing a cell.
  if (!boundary.empty()) {
    double mean_length = 0.0;
    for (const Edge& edge : boundary) mean_length += (edge.b - edge.a).norm();
    const double cell = std::max(mean_length / boundary.size(), 4 * tolerance);
    std::unordered_map<int64_t, std::vector<int>> buckets;
    auto key = [](int64_t x, int64_t y, int64_t z) { return (x * 73856093) ^ (y * 19349663) ^ (z * 83492791); };
    for (int e = 0; e < static_cast<int>(boundary.size()); ++e) {
      const Vec3 low = boundary[e].a.cwiseMin(boundary[e].b).array() - tolerance;
      const Vec3 high = boundary[e].a.cwiseMax(boundary[e].b).array() + tolerance;
      for (int64_t x = std::floor(low.x() / cell); x <= std::floor(high.x() / cell); ++x)
        for (int64_t y = std::floor(low.y() / cell); y <= std::floor(high.y() / cell); ++y)
          for (int64_t z = std::floor(low.z() / cell); z <= std::floor(high.z() / cell); ++z)
            buckets[key(x, y, z)].push_back(e);
    }
    auto overlap = [&](const Edge& p, const Edge& q) {
      const double length = (p.b - p.a).norm();
      const Vec3 direction = (p.b - p.a) / length;
      auto off_line = [&](const Vec3& x) { return (x - p.a - direction.dot(x - p.a) * direction).norm(); };
      if (off_line(q.a) > tolerance || off_line(q.b) > tolerance) return false;
      const double ta = direction.dot(q.a - p.a), tb = direction.dot(q.b - p.a);
      return std::min(length, std::max(ta, tb)) - std::max(0.0, std::min(ta, tb)) > tolerance;
    };
    for (const auto& [cell_key, list] : buckets) {
      for (size_t x = 0; x < list.size(); ++x) {
        for (size_t y = x + 1; y < list.size(); ++y) {
          const Edge& p = boundary[list[x]];
          const Edge& q = boundary[list[y]];
          if (p.patch == q.patch) continue;
          const std::pair<int, int> pair{std::min(p.patch, q.patch), std::max(p.patch, q.patch)};
          if (pairs.count(pair) == 0 && overlap(p, q)) pairs.insert(pair);
        }
      }
    }
  }
  std::vector<std::array<int, 2>> adjacency;
  adjacency.reserve(pairs.size());
  for (const auto& [i, j] : pairs) adjacency.push_back({i, j});
  return adjacency;
}

Eigen::MatrixX3d CoarsenPatchValues(const Eigen::MatrixX3d& fine_values,
                               const Eigen::VectorXd& fine_area,
                               const std::vector<int>& coarse_of_fine, int coarse_count) {
  Eigen::MatrixX3d flux = Eigen::MatrixX3d::Zero(coarse_count, 3);
  Eigen::VectorXd area = Eigen::VectorXd::Zero(coarse_count);
  for (int i = 0; i < static_cast<int>(coarse_of_fine.size()); ++i) {
    flux.row(coarse_of_fine[i]) += fine_area[i] * fine_values.row(i);
    area[coarse_of_fine[i]] += fine_area[i];
  }
  for (int i = 0; i < coarse_count; ++i) {
    if (area[i] > 0.0) flux.row(i) /= area[i];
  }
  return flux;
}

PatchHierarchy SubdividePatches(const Scene& scene, const SubdivisionOptions& options) {
  PatchHierarchy hierarchy;
  const double total_area = scene.Area();
  const double coarse_target = std::max(1.0, options.target_patches / 4.0);
  for (int s = 0; s < static_cast<int>(scene.surfaces.size()); ++s) {
    const Surface& surface = scene.surfaces[s];
    const double share = std::max(1.0, coarse_target * surface.Area() / total_area);
    if (surface.kind == Surface::Kind::kQuad) {
      // Cells of about the mean coarse patch's side keep patches near-square and of similar area.
      const double side = std::sqrt(total_area / coarse_target);
      const auto& q = surface.quad;
      const double length_u = 0.5 * ((q[1] - q[0]).norm() + (q[2] - q[3]).norm());
      const double length_v = 0.5 * ((q[3] - q[0]).norm() + (q[2] - q[1]).norm());
      const int nu = std::max(1, static_cast<int>(std::lround(length_u / side)));
      const int nv = std::max(1, static_cast<int>(std::lround(length_v / side)));
      for (int a = 0; a < nu; ++a) {
        for (int b = 0; b < nv; ++b) {
          const int parent = hierarchy.coarse.size();
          hierarchy.coarse.patches.push_back(QuadCell(surface, s, nu, nv, a, b));
          for (int da = 0; da < 2; ++da) {
            for (int db = 0; db < 2; ++db) {
              hierarchy.fine.patches.push_back(QuadCell(surface, s, 2 * nu, 2 * nv, 2 * a + da, 2 * b + db));
              hierarchy.coarse_of_fine.push_back(parent);
            }
          }
        }
      }
    } else {
      // Uniform midpoint splits: choose the level whose count is nearest (in ratio) the share.
      const double triangles = static_cast<double>(surface.mesh_triangles.size());
      const int levels = std::max(0, static_cast<int>(std::lround(std::log(share / triangles) / std::log(4.0))));
      for (const MeshTriangle& triangle : surface.mesh_triangles) {
        Patch base;
        base.surface = s;
        base.corner_count = 3;
        for (int k = 0; k < 3; ++k) {
          base.corners[k] = surface.mesh_vertices[triangle.vertex[k]];
          base.uv[k] = triangle.uv[k];
        }
        base.corners[3] = base.corners[2];
        base.uv[3] = base.uv[2];
        FinishPatch(&base);
        std::vector<Patch> coarse;
        SplitTriangle(base, levels, &coarse);
        for (const Patch& parent_patch : coarse) {
          const int parent = hierarchy.coarse.size();
          hierarchy.coarse.patches.push_back(parent_patch);
          SplitTriangle(parent_patch, 1, &hierarchy.fine.patches);
          hierarchy.coarse_of_fine.resize(hierarchy.fine.patches.size(), parent);
        }
      }
    }
  }
  for (PatchLevel* level : {&hierarchy.fine, &hierarchy.coarse}) {
    level->adjacency = FindAdjacency(level->patches, scene.weld_tolerance);
    FillAttributes(scene, options.texture_samples, level);
  }
  return hierarchy;
}

}  // namespace procam
