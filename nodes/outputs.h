#pragma once
// A node's outputs from the command line's --display: one entry per projector, in order:
//
//   glfw:MONITOR   a fullscreen window on that monitor (index or name; the GLFW backend)
//   record:DIR     DIR/NAME.png rewritten at every frame (for tests and headless trials)
//   memory         kept in memory only (render and present, show nothing)
//
// Every output renders on the GPU when the node does (NodeOptions::gpu): a window with its own
// context, record and memory with an offscreen EGL context (projection/offscreen_gl.h; on the
// CPU where none can be made).
//
// A single entry record:DIR or memory applies to every projector.

#include <string>
#include <vector>

#include "nodes/node.h"

namespace procam {

// Throws std::invalid_argument for an unknown kind, a count that does not match, or glfw: in a
// build without the GLFW backend. Monitors are opened (on the calling thread: GLFW's main
// thread) when the factory is called.
NodeOutputFactory MakeNodeOutputs(const std::vector<std::string>& display);

}  // namespace procam
