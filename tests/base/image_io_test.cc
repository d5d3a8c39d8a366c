#include "base/image_io.h"

#include <gtest/gtest.h>

#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <string>

#include "base/io.h"
#include "tests/testing/testing.h"

namespace procam {
namespace {

// Files of a few bytes whose headers state 30000 x 30000 pixels or more (fuzz/regressions/image/):
// OpenCV's decoders allocated the whole image (2.7 GB for the 62-byte BMP) before finding the
// data missing. ReadImage refuses them from the header, naming the size; sides near 2^32, whose
// product overflowed in the first version of the check, are found by fuzz_image.
TEST(ReadImage, RefusesHeadersStatingMorePixelsThanItReads) {
  const auto dir = testing::SourceDir() / "fuzz/regressions/image";
  for (const char* name : {"bmp_header_30000x30000.bmp", "png_header_30000x30000.png",
                           "jpeg_header_65000x65000.jpg", "tiff_header_40000x40000.tif",
                           "sides_overflowing_their_product.img"}) {
    try {
      ReadImage(dir / name, cv::IMREAD_UNCHANGED);
      ADD_FAILURE() << "accepted " << name;
    } catch (const IoError& error) {
      EXPECT_NE(std::string(error.what()).find(name), std::string::npos) << error.what();
      EXPECT_NE(std::string(error.what()).find("pixels (at most"), std::string::npos) << error.what();
    }
  }
}

// The formats procam writes and reads keep working: PNG (8 and 16 bits), JPEG, TIFF (float, as
// capture sessions' HDR frames), BMP and Netpbm; anything else is refused by name.
TEST(ReadImage, ReadsPngJpegTiffBmpAndPpmAndRefusesOtherFormats) {
  const testing::TempDir dir;
  cv::Mat image(3, 5, CV_8UC3, cv::Scalar(10, 200, 30));
  for (const char* extension : {".png", ".jpg", ".tiff", ".bmp"}) {
    std::vector<uchar> bytes;
    ASSERT_TRUE(cv::imencode(extension, image, bytes));
    const auto path = dir.Write(std::string("a") + extension, std::string(bytes.begin(), bytes.end()));
    const cv::Mat back = ReadImage(path, cv::IMREAD_UNCHANGED);
    EXPECT_EQ(back.size(), image.size()) << extension;
  }
  std::vector<uchar> hdr;
  const cv::Mat radiance(4, 2, CV_32FC3, cv::Scalar(0.5, 1.5, 2.5));
  ASSERT_TRUE(cv::imencode(".tiff", radiance, hdr));
  EXPECT_EQ(ReadImage(dir.Write("hdr.tiff", std::string(hdr.begin(), hdr.end())), cv::IMREAD_UNCHANGED).type(),
            CV_32FC3);
  // Netpbm, which play's frame directories accept, is read with its header's size checked.
  std::vector<uchar> ppm;
  ASSERT_TRUE(cv::imencode(".ppm", image, ppm));
  EXPECT_EQ(ReadImage(dir.Write("a.ppm", std::string(ppm.begin(), ppm.end())), cv::IMREAD_UNCHANGED).size(),
            image.size());
  EXPECT_THROW(ReadImage(dir.Write("big.ppm", "P6\n# a comment\n30000 30000\n255\n"), cv::IMREAD_UNCHANGED),
               IoError);
  EXPECT_THROW(ReadImage(dir.Write("a.gif", "GIF89a\x05\x00\x03\x00"), cv::IMREAD_UNCHANGED), IoError);
}

}  // namespace
}  // namespace procam
