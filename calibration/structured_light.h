#pragma once
// Structured light for projector-camera correspondences: Gray code with inverse patterns plus
// phase shifting, decoded per camera pixel into a sub-pixel projector (column, row) and a
// reliability mask.
//
// Sequence (MakeStructuredLightSequence), for each encoded axis (columns, then rows):
//   white, black                         once, first: the shadow / contrast test
//   Gray bit b and its inverse           b = the most significant bit down to `finest_bit`
//   N phase-shifted sinusoids            only with phase_period > 0
// Projector pixel (u, v) is column u, row v (capture/patterns.h); a decoded coordinate is in the
// projector's pixel-centre convention (projection/projector.h): the centre of pixel u is u.
//
// Global illumination. In a room, a camera pixel receives the projector's light directly and,
// through interreflections, from everything else the projector lights. For a pattern with wide
// stripes (the coarse Gray bits) that bounce light depends on the pattern: a pixel in an unlit
// stripe beside a brightly lit wall can be brighter than the direct light of a lit pixel on a
// grazed surface, so any fixed threshold misreads it. For a high-frequency pattern the bounce
// light is nearly the same for the pattern and its inverse (each lights half of every region;
// Nayar et al. 2006), so comparing the two per pixel decides the bit by the direct light alone.
// Three measures, each switchable so their effect can be measured:
//   - complementary binarization: bit = [pattern > inverse], refused where |pattern − inverse|
//     is a small fraction of white − black (StructuredLightDecodeOptions);
//   - XOR codes (Gupta, Agrawal, Veeraraghavan & Narasimhan, "Structured light 3D scanning in the
//     presence of global illumination", CVPR 2011): every coarse Gray plane is shown XORed with
//     the finest Gray plane, so all planes have stripes no wider than the finest one; the decoder
//     XORs them back;
//   - phase shifting: the bits finer than a quarter of the sinusoid's period are not shown at all;
//     the position within a period comes from the phase of N sinusoids of period P (high
//     frequency, so their bounce light is nearly constant and drops out of the phase), and the
//     Gray code only has to be right to within P/2 to unwrap it.

#include <cstdint>
#include <opencv2/core.hpp>
#include <string>
#include <vector>

#include "capture/patterns.h"

namespace procam {

class OptionTable;

struct StructuredLightOptions {
  int width = 1024;     // projector pixels, [4, 16384]
  int height = 768;     // projector pixels, [4, 16384]
  bool columns = true;  // encode the column u
  bool rows = true;     // encode the row v
  // Period of the phase-shifted sinusoids in projector pixels: a power of two in [4, 1024] and
  // no larger than the encoded sizes; 0 = no phase shifting (the Gray code goes down to single
  // pixels and decoded coordinates are integers).
  int phase_period = 16;
  int phase_steps = 4;  // sinusoids per axis, [3, 64]
  // Show the coarse Gray planes XORed with the finest shown plane (Gupta et al. 2011).
  bool xor_codes = true;
  // The sinusoids are encoded as value^(1/pattern_gamma) so that a projector with this response
  // gamma emits a sinusoid in light (from photometric calibration), (0, 10]. 1 = encode the
  // sinusoid itself; a projector's gamma then distorts it into harmonics that 4-step phase
  // shifting partly mistakes for phase.
  double pattern_gamma = 1.0;
  bool Check(std::string* why) const;
};

// The finest Gray bit shown: log2(phase_period) − 2 with phase shifting (the Gray code then
// resolves P/4 pixels, enough to unwrap the phase with a margin of P/4), else 0.
int StructuredLightFinestBit(const StructuredLightOptions& options);

// The sequence above, kind "structured_light", patterns CV_8UC3 (grey), named "white", "black",
// "sl_col_b08", "sl_col_b08_inv", ..., "sl_col_phase0", ... (rows: "sl_row_..."). Throws
// std::invalid_argument when options.Check() fails.
CaptureSequence MakeStructuredLightSequence(const StructuredLightOptions& options);

enum class Binarization {
  // One threshold for the whole image: the mean of (white + black)/2 over the pixels that pass
  // the contrast test. The textbook baseline; inverse patterns are ignored.
  kGlobalThreshold,
  // Per pixel: (white + black)/2 of that pixel. Inverse patterns are ignored.
  kPixelThreshold,
  // Per pixel: the pattern against its inverse.
  kComplementary,
};
const char* BinarizationName(Binarization binarization);

struct StructuredLightDecodeOptions {
  Binarization binarization = Binarization::kComplementary;
  // Every threshold below is the larger of a fraction of the pixel's own white − black contrast
  // and `noise_sigmas` standard deviations of the photos' noise, which the decoder estimates from
  // the photos themselves (StructuredLightMap::noise_sigma): a real camera's read noise, JPEG
  // and quantisation set the floor, the scene's contrast the rest.
  // Shadow test: a pixel is decoded only where white − black ≥ min_contrast × the 99th
  // percentile of white − black over the image, [0, 1).
  double min_contrast = 0.05;
  // A bit is accepted only where |pattern − inverse| (complementary) or 2 |pattern − threshold|
  // (thresholds) is at least this fraction of white − black, [0, 1).
  double min_bit_contrast = 0.1;
  // The phase is accepted only where the sinusoids' amplitude is at least this fraction of
  // (white − black)/2, [0, 1).
  double min_modulation = 0.2;
  // How many noise standard deviations each difference must exceed, [0, 100]; 0 = no noise floor.
  double noise_sigmas = 4.0;
  // Gray bits per axis that may fail the bit test and still decode, [0, 4]: they are tried at both
  // values, and the pixel decodes where the phase unwraps to the same coordinate either way
  // (beside a blurred stripe edge; DecodeStructuredLight). 0 = every bit must pass. Off by
  // default: it also decodes pixels that mix two surfaces at a depth edge, to a coordinate between
  // theirs (docs/synthetic.md); for a defocused projector or camera, 4 with plain Gray codes.
  int faint_bits = 0;
  // Declares --min-contrast, --min-bit-contrast, --min-modulation, --noise-sigmas and
  // --faint-bits in `table`, bound to these fields (base/option_table.h).
  void Declare(OptionTable* table);
  bool Check(std::string* why) const;
};

// Why a camera pixel was not decoded (StructuredLightMap::refused): the first test it failed.
enum class DecodeRefusal : uint8_t {
  kDecoded = 0,     // every encoded axis decoded
  kShadowed = 1,    // white − black under the contrast threshold
  kAmbiguous = 2,   // Gray bits under the bit-contrast threshold that change the decode
  kWeakPhase = 3,   // sinusoid amplitude under the modulation threshold
  kOutOfRange = 4,  // decoded coordinate outside the projector image
  kUnwrap = 5,      // the phases could not be unwrapped (no coarser code resolves their period)
};
const char* DecodeRefusalName(DecodeRefusal refusal);

// Per camera pixel, what it sees of the projector.
struct StructuredLightMap {
  cv::Mat column;  // CV_32FC1 projector column (pixel centres at integers); NaN where not decoded
  cv::Mat row;     // CV_32FC1 projector row; NaN where not decoded (or rows not encoded)
  cv::Mat mask;    // CV_8UC1, 255 where every encoded axis decoded
  cv::Mat refused;  // CV_8UC1, DecodeRefusal per pixel (kDecoded where mask is 255)
  // Each axis decodes on its own: where one fails its tests, the other may still hold a
  // coordinate (a surface lit at a grazing angle crowds many projector columns into one camera
  // pixel while its rows stay resolved).
  // Why pixels were refused on some axis (a pixel counts once, for the first test it fails).
  long long shadowed = 0;      // white − black under the contrast threshold
  long long ambiguous = 0;     // bits under the bit-contrast threshold that change the decode
  long long weak_phase = 0;    // sinusoid amplitude under the modulation threshold
  long long out_of_range = 0;  // decoded coordinate outside the projector image
  long long unwrap = 0;        // phases no coarser code could unwrap
  // Where an axis has both a Gray code and phases and every Gray bit reads clearly: pixels whose
  // unwrapped phase lies within its Gray cell (widened by one projector pixel each side), and
  // those where it does not.
  long long gray_phase_agree = 0;
  long long gray_phase_disagree = 0;
  // The photos' noise, one standard deviation in the images' units, estimated from pattern and
  // inverse pairs (pattern + inverse = white + black, up to noise, wherever the bit is clear) or,
  // without inverses, from neighbouring pixels of the black image.
  double noise_sigma = 0.0;
};

// A structured-light capture as another tool (or procam) ordered it: the images, by index in
// capture order, and what each shows. MakeStructuredLightSequence's order is one such layout
// (LayoutOf); the layout file (calibration/capture_layout.h) describes others.
struct StructuredLightLayout {
  // A Gray code along one axis: the bit images from the most significant bit down to
  // `finest_bit`, each optionally followed by its inverse.
  struct Gray {
    bool column = true;  // the code encodes projector columns (else rows)
    int cell = 1;        // projector pixels per code value, ≥ 1 (OpenCV's cells when scaled up)
    int bits = 0;        // bits of the full code: ⌈log2 ⌈size / cell⌉⌉
    int finest_bit = 0;  // lowest bit shown, [0, bits)
    // Every plane above the finest shown is XORed with the finest (Gupta et al. 2011).
    bool xor_codes = false;
    std::vector<int> images;   // per shown bit, most significant first: its image's index
    std::vector<int> inverse;  // per shown bit: its inverse's index, or −1 (none)
  };
  // N phase-shifted sinusoids along one axis: image k shows, at projector coordinate u,
  // 0.5 + 0.5 cos(direction · 2π (u − origin) / period + shifts[k]).
  struct Phase {
    bool column = true;
    double period = 16.0;       // projector pixels, > 1
    double origin = 0.0;        // coordinate of phase 0, projector pixels
    int direction = 1;          // +1 or −1
    std::vector<double> shifts;  // radians, one per image, ≥ 3 distinct
    std::vector<int> images;
  };
  static constexpr int kMaxPhasesPerAxis = 16;
  int width = 0, height = 0;  // projector pixels
  int white = -1, black = -1;  // image indices (required)
  std::vector<Gray> gray;
  std::vector<Phase> phases;
  int image_count = 0;
  bool Check(std::string* why) const;
  // Whether a Gray code or a phase set encodes projector columns (`column`) or rows.
  bool Encodes(bool column) const;
};

// MakeStructuredLightSequence(options)'s order as a layout. Throws std::invalid_argument when
// options.Check() fails.
StructuredLightLayout LayoutOf(const StructuredLightOptions& options);

// Decodes `captured`: one camera image per pattern of MakeStructuredLightSequence(options), in
// order, same size, any depth, one or three channels (three are averaged), linear in light
// (subtract the camera's black level first if it has one). Throws std::invalid_argument when the
// options fail Check() or the count or sizes do not match.
StructuredLightMap DecodeStructuredLight(const StructuredLightOptions& options,
                                         const std::vector<cv::Mat>& captured,
                                         const StructuredLightDecodeOptions& decode_options = {});

// Decodes images ordered as `layout` says. Per axis, the Gray code gives a coordinate to within
// half a cell; the phases, coarsest period first, refine it, each unwrapped by the estimate
// before it (x = w + P round((estimate − w) / P), which needs the estimate within P/2); where
// the estimate is too coarse for a period (OpenCV's cells as wide as the period), two phase sets
// of periods P1 > P2 are first combined into their beat, of period P1 P2 / (P1 − P2) (temporal
// heterodyne unwrapping). Without phases a coordinate is its Gray cell's centre. Gray bits too
// faint to read (under the bit-contrast floor: beside a blurred stripe edge) are tried at both
// values, up to decode_options.faint_bits per axis: the pixel decodes where every value that leads
// to a coordinate leads to the same one (the phases unwrap the same from the cells on either side
// of the edge), and is refused as ambiguous where they differ. Throws std::invalid_argument when
// the layout fails Check() or the count or sizes do not match.
StructuredLightMap DecodeStructuredLight(const StructuredLightLayout& layout,
                                         const std::vector<cv::Mat>& captured,
                                         const StructuredLightDecodeOptions& decode_options = {});

// A picture of a decode for people to look at: three panels side by side, each the camera's
// image size scaled to at most 640 pixels wide — the decoded columns and rows (colour maps over
// the projector's width and height, black where not decoded) and why pixels were refused (one
// colour per DecodeRefusal, named in a legend). CV_8UC3.
cv::Mat DecodePicture(const StructuredLightMap& map, int projector_width, int projector_height);

}  // namespace procam
