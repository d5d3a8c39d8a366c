#pragma once
// Test patterns for aligning projectors (procam show --pattern): generated in code, so a test
// states exactly what the window must show.

#include <opencv2/core/mat.hpp>
#include <string>

#include "projection/projector_images.h"

namespace procam {

enum class TestPattern {
  kGrid,   // black; white lines every 64 px from the top-left pixel, a 1-px white border, a
           // centre cross, and the four corner pixels red, green, blue, yellow (clockwise from
           // the top-left) so that flips and rotations show
  kBars,   // eight vertical colour bars: white, yellow, cyan, green, magenta, red, blue, black
  kWhite,  // every pixel at full drive
  kBlack,  // every pixel at code 0
};
const char* TestPatternName(TestPattern pattern);
bool ParseTestPattern(const std::string& name, TestPattern* pattern);

// An 8-bit image of the pattern at `size` (pixels).
ProjectorImage MakeTestPattern(TestPattern pattern, cv::Size size);

}  // namespace procam
