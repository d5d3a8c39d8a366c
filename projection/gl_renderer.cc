#include "projection/gl_renderer.h"

#include <epoxy/gl.h>

#include <algorithm>
#include <array>
#include <opencv2/core.hpp>
#include <stdexcept>
#include <string>
#include <vector>

#include "base/io.h"
#include "projection/render_steps.h"

namespace procam {
namespace {

constexpr const char* kVertexShader = R"(#version 330 core
// One triangle covering the viewport: corners (−1, −1), (3, −1), (−1, 3).
void main() {
  vec2 corner = vec2((gl_VertexID << 1) & 2, gl_VertexID & 2);
  gl_Position = vec4(corner * 2.0 - 1.0, 0.0, 1.0);
}
)";

// Step 3 of projector_images.h per pixel (gl_renderer.h); the names follow the CPU's. Shared by
// the fragment and the compute shader, each of which puts its #version and main() around it.
constexpr const char* kShading = R"(
uniform isampler2D pixel_patch;       // patch the pixel lights, −1: none (texel row = image row)
uniform sampler2D pixel_point;        // xyz: world point its ray hits; w: its share (w a / Ω)
uniform isampler2D pixel_nodes;       // kSmooth: the nodes j of the pixel's first four bumps (−1:
                                      // unused); x = −1: flat patch (m = 1); w = −2: more than 12
uniform sampler2D pixel_weights;      // their normalised bumps K̃_j at the pixel
uniform isampler2D pixel_nodes_more;  // bumps 5 to 8, where pixel_nodes.w ≥ 0
uniform sampler2D pixel_weights_more;
uniform isampler2D pixel_nodes_most;  // bumps 9 to 12, where pixel_nodes_more.w ≥ 0
uniform sampler2D pixel_weights_most;
uniform samplerBuffer patch_centroid; // per patch: xyz c_j, w r_j²
uniform isamplerBuffer node_begin;    // (n + 1) CSR of the seamless field's node lists
uniform isamplerBuffer node_list;
uniform samplerBuffer code_light;     // light of code q of channel c at c (max_code + 1) + q
uniform isamplerBuffer code_first;    // CodeTable's bins: channel c's bin b at c (code_bins + 1) + b
uniform samplerBuffer level;          // per patch τ (rgb); negative: +inf (full drive)
uniform samplerBuffer node_value;     // per patch v̂ (rgb)
uniform samplerBuffer patch_mean;     // per patch mean_i(v) (rgb)
uniform vec3 inverse_delta;
uniform mat3 mixing_inverse;
uniform int identity_mixing;
uniform int max_code;
uniform int code_bins;
uniform int ordered_dither;
uniform int smooth_light;
uniform int image_height;
uniform int bayer[64];

// v(x): the bumps' weighted mean of the node values, the bumps evaluated here (pixels reached by
// more than 12).
vec3 FieldValue(int i, vec3 x) {
  int begin = texelFetch(node_begin, i).r, end = texelFetch(node_begin, i + 1).r;
  float weight_sum = 0.0;
  vec3 value = vec3(0.0);
  for (int node = begin; node < end; ++node) {
    int j = texelFetch(node_list, node).r;
    vec4 bump = texelFetch(patch_centroid, j);
    vec3 d = x - bump.xyz;
    float d2 = dot(d, d);
    if (d2 >= bump.w) continue;
    float t = 1.0 - d2 / bump.w;
    weight_sum += t * t;
    value += (t * t) * texelFetch(node_value, j).rgb;
  }
  // Only where no bump reaches (a patch far outside the designed shapes): the patch's own value.
  return weight_sum > 0.0 ? value / weight_sum : texelFetch(node_value, i).rgb;
}

// Σ weight_b v̂_{nodes_b} over the texel's bumps (nodes.x ≥ 0; −1: unused).
vec3 FourBumps(ivec4 nodes, vec4 weight) {
  vec3 value = weight.x * texelFetch(node_value, nodes.x).rgb;
  if (nodes.y >= 0) value += weight.y * texelFetch(node_value, nodes.y).rgb;
  if (nodes.z >= 0) value += weight.z * texelFetch(node_value, nodes.z).rgb;
  if (nodes.w >= 0) value += weight.w * texelFetch(node_value, nodes.w).rgb;
  return value;
}

// m = v(x) / mean_i per channel, v from the pixel's precomputed bumps (up to 12).
vec3 SeamlessFactor(int i, vec3 x, ivec2 pixel) {
  ivec4 nodes = texelFetch(pixel_nodes, pixel, 0);
  if (nodes.x < 0) return vec3(1.0);
  vec3 value;
  if (nodes.w == -2) {
    value = FieldValue(i, x);
  } else {
    value = FourBumps(nodes, texelFetch(pixel_weights, pixel, 0));
    if (nodes.w >= 0) {
      ivec4 more = texelFetch(pixel_nodes_more, pixel, 0);
      if (more.x >= 0) {
        value += FourBumps(more, texelFetch(pixel_weights_more, pixel, 0));
        if (more.w >= 0) {
          ivec4 most = texelFetch(pixel_nodes_most, pixel, 0);
          if (most.x >= 0) value += FourBumps(most, texelFetch(pixel_weights_most, pixel, 0));
        }
      }
    }
  }
  vec3 mean = texelFetch(patch_mean, i).rgb;
  vec3 m = vec3(1.0);
  for (int c = 0; c < 3; ++c) {
    if (mean[c] > 0.0) m[c] = value[c] / mean[c];
  }
  return m;
}

// CodeTable::Quantise: the largest code whose light is ≤ r (from r's bin, as CodeTable::Below:
// the bin's first code, then up while the next code's light is still ≤ r: rarely a step), or the
// next one where r lies more than `threshold` of the way to it.
int Quantise(int c, float r, float threshold) {
  int base = c * (max_code + 1);
  int q = texelFetch(code_first, c * (code_bins + 1) + int(r * float(code_bins))).r;
  while (q < max_code && texelFetch(code_light, base + q + 1).r <= r) ++q;
  if (q >= max_code) return max_code;
  float below = texelFetch(code_light, base + q).r;
  float above = texelFetch(code_light, base + q + 1).r;
  return r - below > threshold * (above - below) ? q + 1 : q;
}

// The colour of image pixel (column, row), row 0 at the top.
vec4 PixelColour(ivec2 pixel) {
  int i = texelFetch(pixel_patch, pixel, 0).r;
  if (i < 0) return vec4(0.0, 0.0, 0.0, 1.0);
  vec4 point = texelFetch(pixel_point, pixel, 0);
  vec3 tau = texelFetch(level, i).rgb;
  vec3 m = smooth_light != 0 ? SeamlessFactor(i, point.xyz, pixel) : vec3(1.0);
  vec3 relative;
  for (int c = 0; c < 3; ++c)
    relative[c] = tau[c] < 0.0 ? 1.0 : min(1.0, point.w * tau[c] * inverse_delta[c] * m[c]);
  vec3 r = identity_mixing != 0 ? relative : clamp(mixing_inverse * relative, 0.0, 1.0);
  float threshold = ordered_dither != 0
                        ? (float(bayer[(pixel.y & 7) * 8 + (pixel.x & 7)]) + 0.5) / 64.0
                        : 0.5;
  vec3 code = vec3(Quantise(0, r.r, threshold), Quantise(1, r.g, threshold),
                   Quantise(2, r.b, threshold));
  return vec4(code / float(max_code), 1.0);
}
)";

constexpr const char* kFragmentMain = R"(
layout(location = 0) out vec4 colour;
void main() {
  colour = PixelColour(ivec2(int(gl_FragCoord.x), image_height - 1 - int(gl_FragCoord.y)));
}
)";

// Stores at (x, y) counted from the bottom, as the framebuffer holds it, so that the blit into
// the framebuffer is a plain copy. IMAGE_FORMAT is the image's format qualifier.
constexpr const char* kComputeMain = R"(
layout(local_size_x = 16, local_size_y = 16) in;
layout(IMAGE_FORMAT, binding = 0) writeonly uniform image2D shaded;
uniform int image_width;
void main() {
  ivec2 at = ivec2(gl_GlobalInvocationID.xy);
  if (at.x >= image_width || at.y >= image_height) return;
  imageStore(shaded, at, PixelColour(ivec2(at.x, image_height - 1 - at.y)));
}
)";

// The driver's log of a shader or program, on one line.
std::string OneLine(std::string log) {
  while (!log.empty() && (log.back() == '\n' || log.back() == '\0')) log.pop_back();
  std::replace(log.begin(), log.end(), '\n', ' ');
  return log;
}

const char* ShaderName(GLenum type) {
  return type == GL_VERTEX_SHADER ? "vertex" : type == GL_FRAGMENT_SHADER ? "fragment" : "compute";
}

GLuint CompileShader(GLenum type, const std::string& source) {
  const GLuint shader = glCreateShader(type);
  const char* text = source.c_str();
  glShaderSource(shader, 1, &text, nullptr);
  glCompileShader(shader);
  GLint ok = GL_FALSE;
  glGetShaderiv(shader, GL_COMPILE_STATUS, &ok);
  if (ok != GL_TRUE) {
    GLint length = 0;
    glGetShaderiv(shader, GL_INFO_LOG_LENGTH, &length);
    std::string log(std::max(length, 1), '\0');
    glGetShaderInfoLog(shader, length, nullptr, log.data());
    glDeleteShader(shader);
    throw IoError(std::string("GlProjectorRenderer: the ") + ShaderName(type) +
                  " shader does not compile: " + OneLine(log));
  }
  return shader;
}

// The fragment path's program (vertex + fragment shader), or the compute path's, whose image
// has the format qualifier `image_format`.
GLuint LinkProgram(GlShading shading, const std::string& image_format) {
  std::vector<GLuint> shaders;
  try {
    if (shading == GlShading::kCompute) {
      std::string main = kComputeMain;
      main.replace(main.find("IMAGE_FORMAT"), std::string("IMAGE_FORMAT").size(), image_format);
      shaders.push_back(
          CompileShader(GL_COMPUTE_SHADER, std::string("#version 430 core\n") + kShading + main));
    } else {
      shaders.push_back(CompileShader(GL_VERTEX_SHADER, kVertexShader));
      shaders.push_back(CompileShader(GL_FRAGMENT_SHADER,
                                      std::string("#version 330 core\n") + kShading + kFragmentMain));
    }
  } catch (...) {
    for (const GLuint shader : shaders) glDeleteShader(shader);
    throw;
  }
  const GLuint program = glCreateProgram();
  for (const GLuint shader : shaders) glAttachShader(program, shader);
  glLinkProgram(program);
  for (const GLuint shader : shaders) glDeleteShader(shader);
  GLint ok = GL_FALSE;
  glGetProgramiv(program, GL_LINK_STATUS, &ok);
  if (ok != GL_TRUE) {
    GLint length = 0;
    glGetProgramiv(program, GL_INFO_LOG_LENGTH, &length);
    std::string log(std::max(length, 1), '\0');
    glGetProgramInfoLog(program, length, nullptr, log.data());
    glDeleteProgram(program);
    throw IoError("GlProjectorRenderer: the shaders do not link: " + OneLine(log));
  }
  return program;
}

// The compute path's image for codes of `bits` bits, exactly: its format and the compute shader's
// format qualifier for it.
struct ImageFormat {
  GLenum format;
  const char* qualifier;
};
ImageFormat ImageFormatFor(int bits) {
  if (bits <= 8) return {GL_RGBA8, "rgba8"};
  if (bits == 10) return {GL_RGB10_A2, "rgb10_a2"};
  return {GL_RGBA16, "rgba16"};
}

// Texture units of the shader's samplers.
enum Unit : int {
  kPixelPatch,  // the 2D textures first (kLastTexture2D)
  kPixelPoint,
  kPixelNodes,
  kPixelWeights,
  kPixelNodesMore,
  kPixelWeightsMore,
  kPixelNodesMost,
  kPixelWeightsMost,
  kPatchCentroid,
  kNodeBegin,
  kNodeList,
  kCodeLight,
  kCodeFirst,
  kLevel,
  kNodeValue,
  kPatchMean,
  kUnits
};
constexpr int kLastTexture2D = kPixelWeightsMost;
constexpr std::array<const char*, kUnits> kSamplerNames = {
    "pixel_patch",      "pixel_point",        "pixel_nodes",      "pixel_weights",
    "pixel_nodes_more", "pixel_weights_more", "pixel_nodes_most", "pixel_weights_most",
    "patch_centroid",   "node_begin",         "node_list",        "code_light",
    "code_first",       "level",              "node_value",       "patch_mean"};
// The per-pixel bumps' textures, four bumps each.
constexpr std::array<Unit, 3> kBumpNodes = {kPixelNodes, kPixelNodesMore, kPixelNodesMost};
constexpr std::array<Unit, 3> kBumpWeights = {kPixelWeights, kPixelWeightsMore, kPixelWeightsMost};

}  // namespace

std::string OpenGlDescription() {
  const auto text = [](GLenum name) {
    const GLubyte* value = glGetString(name);
    return value ? std::string(reinterpret_cast<const char*>(value)) : std::string("?");
  };
  return text(GL_VERSION) + ", " + text(GL_RENDERER);
}

struct GlProjectorRenderer::State {
  int width = 0, height = 0, bits = 8, patches = 0;
  LightField light = LightField::kSmooth;
  GlShading shading = GlShading::kFragment;  // kFragment or kCompute, as chosen
  GLuint program = 0, vertex_array = 0;
  // kCompute: the image the compute shader stores into (of image_format), and a framebuffer
  // holding it (the blit's source).
  GLuint image = 0, image_framebuffer = 0;
  GLenum image_format = GL_RGBA8;
  GLuint timer_query = 0;  // while TimedDraw runs: a GL_TIME_ELAPSED query around the draw call
  std::array<GLuint, kUnits> textures = {};
  std::array<GLuint, kUnits> buffers = {};  // behind the texture buffers (0 for 2D textures)
  GLint max_texels = 0;

  // A texture buffer of `count` texels of `format` on `unit` (at least one texel).
  void MakeTextureBuffer(Unit unit, GLenum format, const void* data, size_t bytes, size_t count,
                         GLenum usage) {
    if (count > static_cast<size_t>(max_texels)) {
      throw IoError("GlProjectorRenderer: " + std::string(kSamplerNames[unit]) + " needs " +
                    std::to_string(count) + " texels, the driver's texture buffers hold " +
                    std::to_string(max_texels));
    }
    glGenBuffers(1, &buffers[unit]);
    glBindBuffer(GL_TEXTURE_BUFFER, buffers[unit]);
    const std::array<float, 4> zero = {0, 0, 0, 0};
    glBufferData(GL_TEXTURE_BUFFER, bytes > 0 ? bytes : sizeof(zero),
                 bytes > 0 ? data : zero.data(), usage);
    glGenTextures(1, &textures[unit]);
    glBindTexture(GL_TEXTURE_BUFFER, textures[unit]);
    glTexBuffer(GL_TEXTURE_BUFFER, format, buffers[unit]);
    glBindTexture(GL_TEXTURE_BUFFER, 0);
    glBindBuffer(GL_TEXTURE_BUFFER, 0);
  }

  // A texture of the image's size, or 1 × 1 with `single` (a sampler the shader does not read).
  void MakeTexture2D(Unit unit, GLenum internal_format, GLenum format, GLenum type,
                     const void* data, bool single = false) {
    glGenTextures(1, &textures[unit]);
    glBindTexture(GL_TEXTURE_2D, textures[unit]);
    glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MIN_FILTER, GL_NEAREST);
    glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MAG_FILTER, GL_NEAREST);
    glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MAX_LEVEL, 0);
    glPixelStorei(GL_UNPACK_ALIGNMENT, 4);
    glPixelStorei(GL_UNPACK_ROW_LENGTH, 0);
    glTexImage2D(GL_TEXTURE_2D, 0, internal_format, single ? 1 : width, single ? 1 : height, 0,
                 format, type, data);
    glBindTexture(GL_TEXTURE_2D, 0);
  }

  // Replaces a per-patch texture buffer's contents (rgb of (n,3) as rgba floats).
  void Upload(Unit unit, const Eigen::MatrixX3d& values, bool infinity_negative) {
    std::vector<float> texels(4 * static_cast<size_t>(std::max(patches, 1)), 0.0f);
    for (int i = 0; i < patches; ++i) {
      for (int c = 0; c < 3; ++c) {
        const double value = values(i, c);
        texels[4 * i + c] =
            infinity_negative && value == internal::kInfinity ? -1.0f : static_cast<float>(value);
      }
    }
    glBindBuffer(GL_TEXTURE_BUFFER, buffers[unit]);
    // Orphaning: the driver may keep the previous frame's contents for a draw still in flight.
    glBufferData(GL_TEXTURE_BUFFER, texels.size() * sizeof(float), texels.data(), GL_STREAM_DRAW);
    glBindBuffer(GL_TEXTURE_BUFFER, 0);
  }

  ~State() {
    glDeleteTextures(kUnits, textures.data());
    glDeleteBuffers(kUnits, buffers.data());
    if (vertex_array != 0) glDeleteVertexArrays(1, &vertex_array);
    if (image_framebuffer != 0) glDeleteFramebuffers(1, &image_framebuffer);
    if (image != 0) glDeleteTextures(1, &image);
    if (program != 0) glDeleteProgram(program);
  }
};

bool GlComputeShading() {
  return epoxy_is_desktop_gl() && epoxy_gl_version() >= 43;
}

const char* GlShadingName(GlShading shading) {
  switch (shading) {
    case GlShading::kAuto: return "auto";
    case GlShading::kFragment: return "fragment";
    case GlShading::kCompute: return "compute";
  }
  return "?";
}

GlProjectorRenderer::GlProjectorRenderer(const FramePlanner& planner, int projector,
                                         GlShading shading) {
  const ProjectionRig& rig = planner.rig();
  const RenderOptions& options = planner.options();
  if (projector < 0 || projector >= static_cast<int>(rig.projectors.size())) {
    throw std::invalid_argument("GlProjectorRenderer: no projector " + std::to_string(projector) +
                                " in a rig of " + std::to_string(rig.projectors.size()));
  }
  if (options.dither == DitherMethod::kErrorDiffusion) {
    throw std::invalid_argument(
        "GlProjectorRenderer: error diffusion is sequential per image and renders on the CPU only "
        "(ShadeProjectorImages)");
  }
  if (!epoxy_is_desktop_gl() || epoxy_gl_version() < 33) {
    throw IoError("GlProjectorRenderer: needs OpenGL 3.3, the context has " +
                  std::string(epoxy_is_desktop_gl() ? "" : "OpenGL ES ") +
                  std::to_string(epoxy_gl_version() / 10) + "." +
                  std::to_string(epoxy_gl_version() % 10));
  }
  state_ = std::make_unique<State>();
  State& state = *state_;
  const ProjectorMap& map = rig.maps[projector];
  const internal::ProjectorTables& tables = planner.tables()[projector];
  state.width = map.width;
  state.height = map.height;
  state.bits = rig.projectors[projector].photometry.bits;
  state.patches = rig.size();
  state.light = options.light;
  glGetIntegerv(GL_MAX_TEXTURE_BUFFER_SIZE, &state.max_texels);
  if (shading == GlShading::kCompute && !GlComputeShading()) {
    throw IoError("GlProjectorRenderer: compute shading needs OpenGL 4.3, the context has " +
                  std::to_string(epoxy_gl_version() / 10) + "." +
                  std::to_string(epoxy_gl_version() % 10));
  }
  state.shading = shading == GlShading::kAuto
                      ? (GlComputeShading() ? GlShading::kCompute : GlShading::kFragment)
                      : shading;
  const ImageFormat image_format = ImageFormatFor(state.bits);
  state.image_format = image_format.format;
  state.program = LinkProgram(state.shading, image_format.qualifier);
  glGenVertexArrays(1, &state.vertex_array);
  if (state.shading == GlShading::kCompute) {
    glGenTextures(1, &state.image);
    glBindTexture(GL_TEXTURE_2D, state.image);
    glTexStorage2D(GL_TEXTURE_2D, 1, state.image_format, map.width, map.height);
    glBindTexture(GL_TEXTURE_2D, 0);
    GLint read_framebuffer = 0;
    glGetIntegerv(GL_READ_FRAMEBUFFER_BINDING, &read_framebuffer);
    glGenFramebuffers(1, &state.image_framebuffer);
    glBindFramebuffer(GL_READ_FRAMEBUFFER, state.image_framebuffer);
    glFramebufferTexture2D(GL_READ_FRAMEBUFFER, GL_COLOR_ATTACHMENT0, GL_TEXTURE_2D, state.image,
                           0);
    glReadBuffer(GL_COLOR_ATTACHMENT0);
    const GLenum status = glCheckFramebufferStatus(GL_READ_FRAMEBUFFER);
    glBindFramebuffer(GL_READ_FRAMEBUFFER, read_framebuffer);
    if (status != GL_FRAMEBUFFER_COMPLETE) {
      throw IoError("GlProjectorRenderer: the compute shader's " + std::to_string(map.width) +
                    "x" + std::to_string(map.height) + " image is not a complete framebuffer");
    }
  }

  // Per pixel: the patch, and the hit point with the share.
  const size_t pixels = static_cast<size_t>(map.width) * map.height;
  std::vector<float> point_share(4 * pixels, 0.0f);
  for (int position = 0; position < map.lit_pixels; ++position) {
    const int32_t index = map.pixels_by_patch[position];
    if (!map.point_by_patch.empty()) {
      for (int axis = 0; axis < 3; ++axis)
        point_share[4 * index + axis] = map.point_by_patch[position][axis];
    }
    point_share[4 * index + 3] = map.share[index];
  }
  state.MakeTexture2D(kPixelPatch, GL_R32I, GL_RED_INTEGER, GL_INT, map.patch.data());
  state.MakeTexture2D(kPixelPoint, GL_RGBA32F, GL_RGBA, GL_FLOAT, point_share.data());
  point_share = {};

  // kSmooth, per pixel: its bumps' nodes and normalised weights (static: they depend on where
  // the pixel's ray hits only), so that the shader sums at most 12 node values. With the seamless
  // field's default radius most pixels have seven, some nine (a box room at 1 000 patches: 93% had
  // more than four, 2% more than eight; evaluating the bumps per pixel for those took the H200
  // 2.6 ms a 1080p image, reading four at most 1.7 ms with eight: docs/nodes.md).
  constexpr int kSlots = 4 * static_cast<int>(kBumpNodes.size());
  if (const SeamlessField* field = planner.field()) {
    std::vector<int32_t> nodes(kSlots * pixels, -1);
    std::vector<float> weights(kSlots * pixels, 0.0f);
    const int n = rig.size();
#pragma omp parallel
    {
      std::vector<std::pair<int, double>> bumps;
#pragma omp for schedule(dynamic, 16)
      for (int i = 0; i < n; ++i) {
        if (field->Flat(i)) continue;  // x = −1: m = 1
        const int begin = field->node_begin()[i];
        for (int position = map.patch_begin[i]; position < map.patch_begin[i + 1]; ++position) {
          const size_t index = static_cast<size_t>(map.pixels_by_patch[position]);
          field->Bumps(i, map.point_by_patch[position], &bumps);
          if (bumps.size() > kSlots) {
            nodes[kSlots * index] = i;
            nodes[kSlots * index + 3] = -2;  // the shader evaluates them
            continue;
          }
          for (size_t b = 0; b < bumps.size(); ++b) {
            nodes[kSlots * index + b] = field->node_list()[begin + bumps[b].first];
            weights[kSlots * index + b] = static_cast<float>(bumps[b].second);
          }
        }
      }
    }
    // Slots 0–3, 4–7 and 8–11 in a texture each (RGBA: four per texel).
    std::vector<int32_t> nodes_part(4 * pixels);
    std::vector<float> weights_part(4 * pixels);
    for (size_t part = 0; part < kBumpNodes.size(); ++part) {
      for (size_t index = 0; index < pixels; ++index) {
        for (int b = 0; b < 4; ++b) {
          nodes_part[4 * index + b] = nodes[kSlots * index + 4 * part + b];
          weights_part[4 * index + b] = weights[kSlots * index + 4 * part + b];
        }
      }
      state.MakeTexture2D(kBumpNodes[part], GL_RGBA32I, GL_RGBA_INTEGER, GL_INT, nodes_part.data());
      state.MakeTexture2D(kBumpWeights[part], GL_RGBA32F, GL_RGBA, GL_FLOAT, weights_part.data());
    }
  } else {
    const std::array<int32_t, 4> none = {-1, -1, -1, -1};
    const std::array<float, 4> zero = {0, 0, 0, 0};
    for (const Unit unit : kBumpNodes)
      state.MakeTexture2D(unit, GL_RGBA32I, GL_RGBA_INTEGER, GL_INT, none.data(), true);
    for (const Unit unit : kBumpWeights)
      state.MakeTexture2D(unit, GL_RGBA32F, GL_RGBA, GL_FLOAT, zero.data(), true);
  }

  // Per patch: the seamless field's bumps and node lists (a flat field: every list just i).
  const int n = rig.size();
  std::vector<float> centroid(4 * static_cast<size_t>(n), 0.0f);
  std::vector<int32_t> node_begin(n + 1), node_list;
  if (const SeamlessField* field = planner.field()) {
    for (int i = 0; i < n; ++i) {
      for (int axis = 0; axis < 3; ++axis) centroid[4 * i + axis] = float(rig.centroid(i, axis));
      centroid[4 * i + 3] = static_cast<float>(field->radius2()[i]);
    }
    node_begin.assign(field->node_begin().begin(), field->node_begin().end());
    node_list.assign(field->node_list().begin(), field->node_list().end());
  } else {
    for (int i = 0; i <= n; ++i) node_begin[i] = i;
    for (int i = 0; i < n; ++i) node_list.push_back(i);
  }
  state.MakeTextureBuffer(kPatchCentroid, GL_RGBA32F, centroid.data(),
                          centroid.size() * sizeof(float), n, GL_STATIC_DRAW);
  state.MakeTextureBuffer(kNodeBegin, GL_R32I, node_begin.data(),
                          node_begin.size() * sizeof(int32_t), node_begin.size(), GL_STATIC_DRAW);
  state.MakeTextureBuffer(kNodeList, GL_R32I, node_list.data(), node_list.size() * sizeof(int32_t),
                          node_list.size(), GL_STATIC_DRAW);

  // Per channel the light of every code value.
  const int max_code = tables.codes[0].max_code();
  std::vector<float> code_light(3 * static_cast<size_t>(max_code + 1));
  for (int c = 0; c < 3; ++c) {
    for (int q = 0; q <= max_code; ++q)
      code_light[c * (max_code + 1) + q] = static_cast<float>(tables.codes[c].Light(q));
  }
  state.MakeTextureBuffer(kCodeLight, GL_R32F, code_light.data(), code_light.size() * sizeof(float),
                          code_light.size(), GL_STATIC_DRAW);
  // and where each bin of light starts its search (CodeTable's table: r's bin is exact in
  // single precision too, r · 2^k, and a code whose light is ≤ the bin's start in double is so
  // in single precision, so the walk only ever goes up, to the code the CPU finds).
  constexpr int kBins = internal::CodeTable::bins();
  std::vector<int32_t> code_first(3 * static_cast<size_t>(kBins + 1));
  for (int c = 0; c < 3; ++c) {
    for (int b = 0; b <= kBins; ++b) code_first[c * (kBins + 1) + b] = tables.codes[c].FirstOfBin(b);
  }
  state.MakeTextureBuffer(kCodeFirst, GL_R32I, code_first.data(),
                          code_first.size() * sizeof(int32_t), code_first.size(), GL_STATIC_DRAW);
  for (const Unit unit : {kLevel, kNodeValue, kPatchMean}) {
    state.MakeTextureBuffer(unit, GL_RGBA32F, nullptr, 0, n, GL_STREAM_DRAW);
  }

  glUseProgram(state.program);
  for (int unit = 0; unit < kUnits; ++unit)
    glUniform1i(glGetUniformLocation(state.program, kSamplerNames[unit]), unit);
  const Eigen::Vector3f inverse_delta = tables.inverse_delta.cast<float>();
  glUniform3fv(glGetUniformLocation(state.program, "inverse_delta"), 1, inverse_delta.data());
  const Eigen::Matrix3f mixing_inverse = tables.mixing_inverse.cast<float>();  // column-major
  glUniformMatrix3fv(glGetUniformLocation(state.program, "mixing_inverse"), 1, GL_FALSE,
                     mixing_inverse.data());
  glUniform1i(glGetUniformLocation(state.program, "identity_mixing"), tables.identity_mixing);
  glUniform1i(glGetUniformLocation(state.program, "max_code"), max_code);
  glUniform1i(glGetUniformLocation(state.program, "code_bins"), internal::CodeTable::bins());
  glUniform1i(glGetUniformLocation(state.program, "ordered_dither"),
              options.dither == DitherMethod::kOrdered);
  glUniform1i(glGetUniformLocation(state.program, "smooth_light"),
              options.light == LightField::kSmooth);
  glUniform1i(glGetUniformLocation(state.program, "image_height"), map.height);
  if (state.shading == GlShading::kCompute)
    glUniform1i(glGetUniformLocation(state.program, "image_width"), map.width);
  std::array<GLint, 64> bayer;
  std::copy(internal::kBayer.begin(), internal::kBayer.end(), bayer.begin());
  glUniform1iv(glGetUniformLocation(state.program, "bayer"), 64, bayer.data());
  glUseProgram(0);
  if (const GLenum error = glGetError(); error != GL_NO_ERROR) {
    throw IoError("GlProjectorRenderer: OpenGL error " + std::to_string(error) +
                  " uploading projector '" + rig.projectors[projector].name + "'");
  }
}

GlProjectorRenderer::~GlProjectorRenderer() = default;

int GlProjectorRenderer::width() const { return state_->width; }
int GlProjectorRenderer::height() const { return state_->height; }
int GlProjectorRenderer::bits() const { return state_->bits; }
GlShading GlProjectorRenderer::shading() const { return state_->shading; }

void GlProjectorRenderer::Draw(const FramePlan& plan) {
  State& state = *state_;
  const bool smooth = state.light == LightField::kSmooth;
  if (plan.level.rows() != state.patches || plan.light != state.light ||
      (smooth && (plan.node_value.rows() != state.patches || plan.mean.rows() != state.patches))) {
    throw std::invalid_argument("GlProjectorRenderer: the plan is not one of this rig's (" +
                                std::to_string(plan.level.rows()) + " patches, light " +
                                LightFieldName(plan.light) + "; the rig " +
                                std::to_string(state.patches) + ", light " +
                                LightFieldName(state.light) + ")");
  }
  state.Upload(kLevel, plan.level, true);
  if (smooth) {
    state.Upload(kNodeValue, plan.node_value, false);
    state.Upload(kPatchMean, plan.mean, false);
  }
  glViewport(0, 0, state.width, state.height);
  glDisable(GL_BLEND);
  glDisable(GL_DEPTH_TEST);
  glDisable(GL_SCISSOR_TEST);
  glDisable(GL_DITHER);  // codes are exact fractions of the framebuffer's levels: no GL dither
  glUseProgram(state.program);
  for (int unit = 0; unit < kUnits; ++unit) {
    glActiveTexture(GL_TEXTURE0 + unit);
    glBindTexture(unit <= kLastTexture2D ? GL_TEXTURE_2D : GL_TEXTURE_BUFFER, state.textures[unit]);
  }
  glBindVertexArray(state.vertex_array);
  if (state.timer_query != 0) glBeginQuery(GL_TIME_ELAPSED, state.timer_query);
  if (state.shading == GlShading::kCompute) {
    glBindImageTexture(0, state.image, 0, GL_FALSE, 0, GL_WRITE_ONLY, state.image_format);
    constexpr int kGroup = 16;  // the compute shader's local size
    glDispatchCompute((state.width + kGroup - 1) / kGroup, (state.height + kGroup - 1) / kGroup, 1);
    glMemoryBarrier(GL_FRAMEBUFFER_BARRIER_BIT);
    // Into the current draw framebuffer as the fragment path draws: a copy of the same pixels.
    GLint read_framebuffer = 0;
    glGetIntegerv(GL_READ_FRAMEBUFFER_BINDING, &read_framebuffer);
    glBindFramebuffer(GL_READ_FRAMEBUFFER, state.image_framebuffer);
    glBlitFramebuffer(0, 0, state.width, state.height, 0, 0, state.width, state.height,
                      GL_COLOR_BUFFER_BIT, GL_NEAREST);
    glBindFramebuffer(GL_READ_FRAMEBUFFER, read_framebuffer);
    glBindImageTexture(0, 0, 0, GL_FALSE, 0, GL_WRITE_ONLY, GL_RGBA8);
  } else {
    glDrawArrays(GL_TRIANGLES, 0, 3);
  }
  if (state.timer_query != 0) glEndQuery(GL_TIME_ELAPSED);
  glBindVertexArray(0);
  glUseProgram(0);
  for (int unit = kUnits - 1; unit >= 0; --unit) {
    glActiveTexture(GL_TEXTURE0 + unit);
    glBindTexture(unit <= kLastTexture2D ? GL_TEXTURE_2D : GL_TEXTURE_BUFFER, 0);
  }
}

void GlProjectorRenderer::Finish() const { glFinish(); }

double GlProjectorRenderer::TimedDraw(const FramePlan& plan) {
  State& state = *state_;
  glGenQueries(1, &state.timer_query);
  try {
    Draw(plan);  // the query brackets the draw call alone, not the uploads
  } catch (...) {
    glDeleteQueries(1, &state.timer_query);
    state.timer_query = 0;
    throw;
  }
  GLuint64 nanoseconds = 0;
  glGetQueryObjectui64v(state.timer_query, GL_QUERY_RESULT, &nanoseconds);  // waits for the GPU
  glDeleteQueries(1, &state.timer_query);
  state.timer_query = 0;
  return 1e-6 * static_cast<double>(nanoseconds);
}

ProjectorImage GlProjectorRenderer::ReadBack() const {
  const State& state = *state_;
  ProjectorImage image;
  image.bits = state.bits;
  glPixelStorei(GL_PACK_ALIGNMENT, 1);
  glPixelStorei(GL_PACK_ROW_LENGTH, 0);
  cv::Mat bottom_up;
  if (state.bits == 8) {
    bottom_up = cv::Mat(state.height, state.width, CV_8UC3);
    glReadPixels(0, 0, state.width, state.height, GL_RGB, GL_UNSIGNED_BYTE, bottom_up.data);
    bottom_up.convertTo(bottom_up, CV_16UC3);
  } else {
    bottom_up = cv::Mat(state.height, state.width, CV_16UC3);
    glReadPixels(0, 0, state.width, state.height, GL_RGB, GL_UNSIGNED_SHORT, bottom_up.data);
    bottom_up.convertTo(bottom_up, CV_16UC3, ((1 << state.bits) - 1) / 65535.0);
  }
  cv::flip(bottom_up, image.codes, 0);
  return image;
}

}  // namespace procam
