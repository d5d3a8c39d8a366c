#pragma once
// The display-to-camera latency of a rig, measured: how long after a pattern is shown (Show()
// returned) a frame whose exposure starts can first see it. The sequencer's settle time must
// cover it; measuring it replaces a guessed --settle-ms.
//
// Method (a flash sequence): reference frames of the display's black and its full white give,
// for every camera pixel the display lights, the two levels. Then the display alternates
// between white and black `edges` times, each change shown at a random phase of the camera's
// frame clock, and every frame after a change is classed by how far its lit pixels have moved
// from the old level to the new one: still old (< 10 %), new (> 90 %), or in between (a frame
// whose exposure the change fell into). A frame exposed from s to s + e after a change shown at
// t0 bounds the latency L of that change:
//   still old:  L > s − t0      (its exposure began before the light changed)
//   new:        L ≤ s − t0      (it saw only the new light)
//   in between: s − t0 < L ≤ s + e − t0
// so each change's latency lies in (lower, upper], an interval of about a frame period (random
// phases move it). A rig's latency varies from change to change (a display's refresh, a
// compositor's frame, a camera's transfer): the measurement reports the median change's, the
// range every change fell in, and settles for the slowest.

#include <cstdint>
#include <string>

#include "capture/camera.h"
#include "capture/display.h"

namespace procam {

struct LatencyOptions {
  int edges = 8;                 // changes of the display measured, [1, 200]
  double max_latency_ms = 1000;  // a change not seen within this (plus two frames) fails, (0, 60000]
  double grab_timeout_ms = 2000;  // per frame, (0, 600000]; the exposure is added
  double min_contrast = 0.02;    // lit pixels: white − black above this fraction of full scale, (0, 1)
  uint32_t seed = 1;             // the random phases
  bool Check(std::string* why) const;
};

struct LatencyMeasurement {
  double estimate_ms = 0.0;      // the median change's latency (the middle of its interval)
  double lower_ms = 0.0;         // every change's latency was above this ...
  double upper_ms = 0.0;         // ... and at most this (milliseconds after Show() returned)
  double frame_period_ms = 0.0;  // median interval between frames' exposure starts
  double exposure_ms = 0.0;      // the frames' exposure
  int edges = 0;                 // display changes measured
  int frames = 0;                // frames classed
  double lit_fraction = 0.0;     // of the camera's pixels, those the display lights
  double EstimateMs() const { return estimate_ms; }
  // The settle time the sequencer needs: the slowest change's upper bound plus a margin (the
  // changes' spread upper − lower, 10 % or 5 ms, whichever is largest), rounded up to a
  // millisecond. The spread: a chain that jitters (a compositor and a screen grabber, as the
  // emulated room's) can be slower on a later change than on any of the few measured.
  double SettleMs() const;
  std::string Summary() const;  // one line, for logs
};

// Measures with `display` and `camera`, which must be streaming (Start() called) and look at
// what the display lights. Leaves the display black. Throws std::invalid_argument for options
// that fail Check(), IoError naming the display and camera when the display lights nothing the
// camera sees, or when a change is not seen within max_latency_ms; camera errors pass through.
// Throws Stopped (base/stop.h) when a stop is requested part-way (read before every frame).
LatencyMeasurement MeasureDisplayLatency(Camera* camera, PatternDisplay* display,
                                         const LatencyOptions& options = {});

}  // namespace procam
