// OBJ meshes (the subset a room model needs: v, vt, vn and f statements), read strictly: every
// number must parse whole and make sense, every index must name an element the file defines, so
// nothing out of range reaches the welder, the patches or Embree.

#include <cerrno>
#include <cmath>
#include <cstdlib>
#include <sstream>
#include <string>
#include <unordered_map>
#include <vector>

#include <fmt/format.h>

#include "base/io.h"
#include "geometry/polygon.h"
#include "geometry/scene.h"

namespace procam {
namespace {

constexpr uintmax_t kMaxObjBytes = uintmax_t{1} << 30;  // 1 GiB of text
constexpr double kMaxCoordinate = 1e6;                  // metres from the origin, per axis
constexpr double kUvSlack = 1e-6;                       // texture coordinates: [0, 1] ± this

// One corner of a face: 0-based indices into the file's v, vt and vn lists (-1: not given).
struct ObjCorner {
  int vertex = -1, texcoord = -1, normal = -1;
};

struct ObjFace {
  int line = 0;
  std::vector<ObjCorner> corners;
};

struct ObjFile {
  std::vector<Vec3> vertices;
  std::vector<Vec2> texcoords;
  int normal_count = 0;
  std::vector<ObjFace> faces;
};

// Reads one line's statements; `where` is "FILE:LINE" for errors.
class ObjLineReader {
 public:
  ObjLineReader(const std::string& line, std::string where) : in_(line), where_(std::move(where)) {}

  IoError Error(const std::string& why) const { return IoError(where_ + ": " + why); }

  // The numbers after the keyword: between `least` and `most` of them, each finite and at most
  // `limit` in magnitude.
  std::vector<double> Numbers(size_t least, size_t most, double limit) {
    std::vector<double> values;
    for (std::string token; in_ >> token;) {
      char* end = nullptr;
      errno = 0;
      const double value = std::strtod(token.c_str(), &end);
      if (*end != '\0' || errno == ERANGE || !std::isfinite(value)) {
        throw Error("'" + token + "' is not a finite number");
      }
      if (std::abs(value) > limit) throw Error("'" + token + "' is out of range");
      values.push_back(value);
    }
    if (values.size() < least || values.size() > most) {
      throw Error("expected " + std::to_string(least) + " to " + std::to_string(most) +
                  " numbers, got " + std::to_string(values.size()));
    }
    return values;
  }

  // A face's corners, "v", "v/vt", "v//vn" or "v/vt/vn" each, resolved against the counts
  // of elements the file defines in all (`file`); negative indices count back from the
  // elements defined so far (`defined`).
  ObjFace Face(int line, const ObjFile& defined, const ObjFile& file) {
    ObjFace face;
    face.line = line;
    for (std::string token; in_ >> token;) {
      std::vector<std::string> parts;
      std::stringstream split(token);
      for (std::string part; std::getline(split, part, '/');) parts.push_back(part);
      if (token.back() == '/') parts.emplace_back();
      if (parts.empty() || parts.size() > 3 || parts[0].empty()) {
        throw Error("'" + token + "' is not a face corner (v, v/vt, v//vn or v/vt/vn)");
      }
      ObjCorner corner;
      corner.vertex = Index(parts[0], "vertex", defined.vertices.size(), file.vertices.size());
      if (parts.size() > 1 && !parts[1].empty()) {
        corner.texcoord =
            Index(parts[1], "texture coordinate", defined.texcoords.size(), file.texcoords.size());
      }
      if (parts.size() > 2) {
        corner.normal = Index(parts[2], "normal", defined.normal_count, file.normal_count);
      }
      face.corners.push_back(corner);
    }
    if (face.corners.size() < 3) {
      throw Error("face with fewer than 3 corners (" + std::to_string(face.corners.size()) + ")");
    }
    return face;
  }

 private:
  int Index(const std::string& text, const std::string& what, size_t defined, size_t total) {
    char* end = nullptr;
    errno = 0;
    const long long value = std::strtoll(text.c_str(), &end, 10);
    const std::string named = what + " index '" + text + "'";
    if (*end != '\0' || text.empty()) throw Error(named + " is not an integer");
    const long long resolved = value > 0 ? value - 1 : static_cast<long long>(defined) + value;
    if (errno == ERANGE || value == 0 || resolved < 0 ||
        resolved >= static_cast<long long>(total)) {
      throw Error(named + " is out of range (the file has " + std::to_string(total) + " " + what +
                  (total == 1 ? "" : "s") + ")");
    }
    return static_cast<int>(resolved);
  }

  std::istringstream in_;
  std::string where_;
};

std::string LineWithoutComment(std::string line) {
  const size_t hash = line.find('#');
  if (hash != std::string::npos) line.erase(hash);
  return line;
}

// Counts v, vt and vn statements (faces may name elements defined after them).
ObjFile CountElements(const std::string& text) {
  ObjFile counts;
  std::istringstream in(text);
  for (std::string line; std::getline(in, line);) {
    std::istringstream statement(LineWithoutComment(line));
    std::string keyword;
    statement >> keyword;
    if (keyword == "v") counts.vertices.emplace_back();
    if (keyword == "vt") counts.texcoords.emplace_back();
    if (keyword == "vn") ++counts.normal_count;
  }
  return counts;
}

ObjFile ParseObj(const std::string& text, const std::string& file) {
  const ObjFile counts = CountElements(text);
  if (counts.vertices.size() > static_cast<size_t>(INT32_MAX) ||
      counts.texcoords.size() > static_cast<size_t>(INT32_MAX)) {
    throw IoError(file + ": more than 2^31 vertices");
  }
  ObjFile obj;
  std::istringstream in(text);
  int number = 0;
  for (std::string line; std::getline(in, line);) {
    ++number;
    std::istringstream statement(LineWithoutComment(line));
    std::string keyword;
    statement >> keyword;
    std::string rest;
    std::getline(statement, rest);
    ObjLineReader values(rest, file + ":" + std::to_string(number));
    // Coordinates are kept in single precision, as the OBJ reader before this one (tinyobjloader)
    // kept them: the same file gives the same patches and results as before (the compressed-F
    // solve in tests/apps/cli_test.cc moves by 10% on room.json's column otherwise).
    if (keyword == "v") {  // x y z, optionally w or a colour r g b
      const std::vector<double> xyz = values.Numbers(3, 6, kMaxCoordinate);
      obj.vertices.emplace_back(float(xyz[0]), float(xyz[1]), float(xyz[2]));
    } else if (keyword == "vt") {  // u, optionally v and w; [0, 1] (no repeating textures)
      const std::vector<double> uv = values.Numbers(1, 3, 1.0 + kUvSlack);
      if (uv[0] < -kUvSlack || (uv.size() > 1 && uv[1] < -kUvSlack)) {
        throw values.Error("texture coordinates must be in [0, 1]");
      }
      obj.texcoords.emplace_back(float(uv[0]), float(uv.size() > 1 ? uv[1] : 0.0));
    } else if (keyword == "vn") {
      values.Numbers(3, 3, kMaxCoordinate);
      ++obj.normal_count;
    } else if (keyword == "f") {
      obj.faces.push_back(values.Face(number, obj, counts));
    }  // other statements (o, g, s, usemtl, mtllib, l, p) carry nothing procam uses
  }
  return obj;
}

}  // namespace

void LoadObjMesh(const std::filesystem::path& path, double weld_tolerance, Surface* surface) {
  const std::string file = path.string();
  const ObjFile obj = ParseObj(ReadFile(path, kMaxObjBytes), file);
  surface->kind = Surface::Kind::kMesh;
  surface->mesh_vertices.clear();
  surface->mesh_triangles.clear();
  // Weld vertices closer than the tolerance so that shared edges are recognised.
  PointWelder welder(weld_tolerance);
  std::unordered_map<int, int> welded_of_obj;
  auto weld = [&](int obj_index) {
    auto found = welded_of_obj.find(obj_index);
    if (found != welded_of_obj.end()) return found->second;
    const int index = welder.Weld(obj.vertices[obj_index]);
    if (index == static_cast<int>(surface->mesh_vertices.size())) {
      surface->mesh_vertices.push_back(welder.points()[index]);
    }
    welded_of_obj[obj_index] = index;
    return index;
  };
  for (const ObjFace& face : obj.faces) {
    std::vector<Vec3> corners;
    std::vector<int> vertices;
    std::vector<Vec2> uvs;
    for (const ObjCorner& corner : face.corners) {
      vertices.push_back(weld(corner.vertex));
      corners.push_back(surface->mesh_vertices[vertices.back()]);
      uvs.push_back(corner.texcoord >= 0 ? obj.texcoords[corner.texcoord] : Vec2(0.0, 0.0));
    }
    std::string why;
    if (!CheckPlanarConvexPolygon(corners.data(), static_cast<int>(corners.size()), weld_tolerance,
                                  &why)) {
      throw IoError(file + ":" + std::to_string(face.line) + ": " + why);
    }
    for (size_t k = 1; k + 1 < corners.size(); ++k) {  // fan over a convex planar face
      surface->mesh_triangles.push_back(
          {{vertices[0], vertices[k], vertices[k + 1]}, {uvs[0], uvs[k], uvs[k + 1]}});
    }
  }
  if (surface->mesh_triangles.empty()) throw IoError(file + ": mesh has no faces");
}

std::string ObjMeshText(const Surface& surface, const std::string& comment) {
  std::string text = "# " + surface.name + ", " + comment + "\n";
  for (const Vec3& v : surface.mesh_vertices) {
    text += fmt::format("v {:.17g} {:.17g} {:.17g}\n", v.x(), v.y(), v.z());
  }
  for (const MeshTriangle& triangle : surface.mesh_triangles) {
    for (const Vec2& uv : triangle.uv) text += fmt::format("vt {:.17g} {:.17g}\n", uv.x(), uv.y());
  }
  int corner = 1;
  for (const MeshTriangle& triangle : surface.mesh_triangles) {
    text += "f";
    for (int k = 0; k < 3; ++k) text += fmt::format(" {}/{}", triangle.vertex[k] + 1, corner++);
    text += "\n";
  }
  return text;
}

}  // namespace procam
