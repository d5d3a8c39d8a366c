#pragma once
// One projector's image rendered on the GPU from a frame plan (frame_plan.h), by an OpenGL
// shader, into the current framebuffer (a display node's fullscreen window: GlfwDisplay::Draw).
// Two paths do the same per-pixel work (GlShading): a compute shader that stores into an image of
// the projector's size, then blits it into the framebuffer (OpenGL 4.3; the default where the
// context has it), or a fragment shader drawing one fullscreen triangle (OpenGL 3.3). Compute is
// the default because data-centre GPUs such as the H100 run graphics work on a small part of the
// chip (NVIDIA's Hopper architecture paper) and compute work on all of it: docs/nodes.md has the
// timings. Part of the optional backend target procam_projection_glfw; OpenGL functions are
// loaded through libepoxy.
//
// Static data, uploaded once when the renderer is made: per pixel the patch it lights (−1:
// none), its share (w a / Ω) and the world point its ray hits, and for kSmooth its bumps: the
// nodes j whose bump reaches the point and their normalised weights K̃_j (SeamlessField::Bumps,
// in double, stored as floats; up to 12 in three pairs of textures, 96 bytes a pixel, else the
// shader evaluates them from the centroids); per patch the centroid c_j and
// r_j² and the node lists of the seamless field (SeamlessField, CSR); per channel the light of
// each code value (the response, as CodeTable); the mixing inverse, 1/Δ and the 8×8 Bayer
// matrix of projector_images.cc. Per frame only the plan's per-patch arrays go up (τ, and for
// kSmooth v̂ and the patch means: 48 bytes a patch), then the shader does step 3 of
// projector_images.h for each pixel p of patch i:
//   m      = v(x_p) / mean_i, v(x_p) = Σ_j K̃_j(x_p) v̂_j (kSmooth; 1 on flat patches and
//            channels whose mean is 0),
//   s      = min(1, share_p · τ_i · m / Δ) per channel, 1 where τ_i is +inf,
//   r      = clip(mixing⁻¹ s, 0, 1),
//   code_c = Quantise(r_c, threshold): the largest code whose light ≤ r_c, raised by one where
//            r_c lies more than `threshold` of the way to the next (½, or the Bayer matrix's
//            (b + ½)/64 at the pixel's column and row for ordered dithering),
// and black where the pixel lights nothing. It computes in single precision where the CPU
// computes in double: the codes equal the CPU's except where r_c falls within rounding of a
// threshold, and there differ by one code step (gl_renderer_test measures how often).
//
// Codes go out as code / max_code in each channel of the framebuffer: exact on an 8-bit
// framebuffer for 8-bit projectors, and on a 10-bit one for 10-bit projectors (on an 8-bit
// framebuffer a 10-bit code shows as its nearest 8-bit level, as GlfwDisplay::Show does).
//
// Needs OpenGL 3.3 (core or compatibility profile: Mesa's llvmpipe and NVIDIA's drivers give
// it): texture buffers, integer textures, GLSL 3.30; the compute path 4.3 (both give 4.5 or
// more). On the compute path the image holds the codes exactly (RGBA8 for 8-bit projectors,
// RGB10_A2 for 10-bit, RGBA16 otherwise) and the blit converts them to the framebuffer's depth.
// All calls must come with the renderer's context current, on that context's thread. Detail and
// error diffusion stay on the CPU (ShadeProjectorImages / RenderProjectorImages).

#include <memory>
#include <string>

#include "projection/frame_plan.h"
#include "projection/projector_images.h"

namespace procam {

// The current OpenGL context as the driver names it: "VERSION, RENDERER" (e.g. "4.5 (Compatibility
// Profile) Mesa 22.3.6, llvmpipe (LLVM 15.0.6, 256 bits)"), for a display node's log.
std::string OpenGlDescription();

// How GlProjectorRenderer shades its pixels (gl_renderer.h's header comment).
enum class GlShading {
  kAuto,      // kCompute where the current context has OpenGL 4.3
  kFragment,  // a fragment shader over one fullscreen triangle
  kCompute,   // a compute shader into an image, then blitted into the framebuffer
};
const char* GlShadingName(GlShading shading);  // "auto", "fragment", "compute"
// Whether the current context runs compute shaders (what kAuto picks kCompute on).
bool GlComputeShading();

class GlProjectorRenderer {
 public:
  // Uploads projector `projector`'s static data of the planner's rig (the planner must outlive
  // nothing: what the shader needs is copied). Needs a current OpenGL ≥ 3.3 context. Throws
  // std::invalid_argument for a bad projector index or options the GPU does not render
  // (detail, error diffusion), and IoError when the context is older than 3.3 or the shader
  // does not build (one line with the driver's log).
  // kCompute on a context without compute shaders throws IoError.
  GlProjectorRenderer(const FramePlanner& planner, int projector,
                      GlShading shading = GlShading::kAuto);
  // Deletes the GL objects: the renderer's context must still exist and be current.
  ~GlProjectorRenderer();
  GlProjectorRenderer(const GlProjectorRenderer&) = delete;
  GlProjectorRenderer& operator=(const GlProjectorRenderer&) = delete;

  int width() const;
  int height() const;
  int bits() const;
  GlShading shading() const;  // kFragment or kCompute: the path chosen

  // Uploads the plan's per-patch arrays and draws the projector's image into the current draw
  // framebuffer, pixel (c, r) of the image at window pixel (c, height − 1 − r) (row 0 at the
  // top), the viewport set to the image. Leaves no program or vertex array bound. Throws
  // std::invalid_argument if the plan is not one of a planner with this rig and light.
  void Draw(const FramePlan& plan);
  // Waits until the GPU has drawn (glFinish): for timing, or before a frame barrier.
  void Finish() const;
  // Draw, timed by the GPU itself (a GL_TIME_ELAPSED query around the draw call alone: the
  // shading of every pixel, not the plan's upload), in milliseconds; waits for the result.
  double TimedDraw(const FramePlan& plan);
  // The image as the current read framebuffer holds it (glReadPixels of the back buffer after
  // Draw): codes at the projector's bit depth, read at 8 bits per channel for 8-bit projectors
  // and 16 for 10-bit ones (exact where the framebuffer has 10 bits per channel).
  ProjectorImage ReadBack() const;

 private:
  struct State;  // GL objects and uniforms
  std::unique_ptr<State> state_;
};

}  // namespace procam
