#pragma once
// Pixel formats cameras deliver, and their conversion to the images the rest of capture uses.
//
// Every backend (V4L2, Aravis, the test camera) hands its raw buffer to DecodeImage(), so a
// format is converted the same way whatever device produced it. Decoded images follow OpenCV's
// conventions: row-major, (0, 0) the top-left pixel of the readout region, colour in B, G, R
// order, so cv::imwrite() stores them correctly.

#include <cstddef>
#include <cstdint>
#include <opencv2/core.hpp>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

namespace procam {

enum class PixelFormat {
  kMono8,     // one 8-bit grey value per pixel (GenICam Mono8, V4L2 GREY)
  kMono16,    // one 16-bit little-endian grey value per pixel (Mono16, V4L2 Y16)
  kBayerRG8,  // 8-bit colour filter mosaic, first row R G R G ..., second G B G B ...
  kBayerBG8,  // first row B G ..., second G R ...
  kBayerGR8,  // first row G R ..., second B G ...
  kBayerGB8,  // first row G B ..., second R G ...
  kRGB8,      // 3 bytes per pixel, R G B (GenICam RGB8, V4L2 RGB3)
  kBGR8,      // 3 bytes per pixel, B G R (GenICam BGR8, V4L2 BGR3)
  kYUYV,      // 4:2:2, Y0 U Y1 V per pixel pair, BT.601 limited range (V4L2 YUYV, GenICam YUV422_8)
  kMJPEG,     // one JPEG image per frame (V4L2 MJPG/JPEG); may lack Huffman tables
};

// All formats, in the order above.
const std::vector<PixelFormat>& AllPixelFormats();

// The name used in URIs, manifests and on the command line: "Mono8", "Mono16", "BayerRG8",
// "BayerBG8", "BayerGR8", "BayerGB8", "RGB8", "BGR8", "YUYV", "MJPEG".
std::string PixelFormatName(PixelFormat format);

// Parses a name case-insensitively; also accepts GenICam and V4L2 aliases ("RGB8Packed",
// "YUV422_8", "GREY", "Y16", "MJPG", "JPEG"). nullopt when unknown.
std::optional<PixelFormat> ParsePixelFormat(std::string_view name);

bool IsBayer(PixelFormat format);
// True for formats whose decoded image has three channels (everything but Mono8/Mono16).
bool IsColour(PixelFormat format);
// Bytes per pixel of the raw buffer; 0 for MJPEG (compressed, variable size).
int RawBytesPerPixel(PixelFormat format);
// The largest value a decoded pixel can take: 65535 for Mono16, 255 otherwise.
double FullScale(PixelFormat format);

// A raw frame as a device delivers it. `data` is not owned and must outlive the call.
struct RawImage {
  const uint8_t* data = nullptr;
  size_t size = 0;    // bytes available at `data`
  int width = 0;      // pixels
  int height = 0;     // pixels
  size_t stride = 0;  // bytes from one row to the next; 0 = packed (width * bytes/pixel)
  PixelFormat format = PixelFormat::kMono8;
};

// Decodes a raw frame: Mono8 → CV_8UC1, Mono16 → CV_16UC1, every other format → CV_8UC3 (BGR).
// Bayer mosaics are demosaiced (OpenCV's bilinear cvtColor, which names the patterns one
// pixel shifted; this function maps the names). YUYV uses BT.601 limited range. MJPEG is
// decoded with cv::imdecode and must come out width × height.
// Throws IoError when the buffer is too small or does not decode; the message says which
// format and size, the caller adds the device.
cv::Mat DecodeImage(const RawImage& raw);

// The inverse of DecodeImage for the formats a simulated camera produces (all but YUYV and
// MJPEG): packs an image of the matching depth (CV_8UC1, CV_16UC1 or CV_8UC3 BGR) into the
// raw layout of `format`; Bayer formats keep, at each pixel, the channel of the mosaic there.
// Throws std::invalid_argument for YUYV/MJPEG or a mismatched image depth.
std::vector<uint8_t> EncodeRaw(const cv::Mat& image, PixelFormat format);

}  // namespace procam
