// Captures from other tools: layout files read and written, imports of photos as sessions, and
// the general decoder on sequences as other tools generate them (OpenCV's GrayCodePattern, a
// two-frequency three-step phase-shift set) against the synthetic truth of where each camera
// pixel looks; the real photographs of ../shared/data/real/phase_shifting_object2.
#include "calibration/capture_layout.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <numbers>
#include <opencv2/imgcodecs.hpp>
#include <random>

#include "base/io.h"
#include "base/image_io.h"
#include "tests/testing/testing.h"

namespace procam {
namespace {

namespace fs = std::filesystem;
using testing::TempDir;

// The layout of kamino410/phase-shifting's captures, as the repository ships it.
fs::path SourceDirLayout() {
  return testing::SourceDir() / "data" / "layouts" / "kamino410_phase_shifting.json";
}

// The patterns themselves as grey photos (as ExportPatterns writes them): camera pixel (x, y)
// sees projector pixel (x, y).
std::vector<cv::Mat> IdealCaptures(const CaptureSequence& sequence) {
  std::vector<cv::Mat> captured;
  for (const Pattern& pattern : sequence.patterns) {
    cv::Mat grey;
    cv::extractChannel(pattern.image, grey, 0);
    captured.push_back(grey);
  }
  return captured;
}

void ExpectSameMap(const StructuredLightMap& a, const StructuredLightMap& b) {
  ASSERT_EQ(a.column.size(), b.column.size());
  EXPECT_EQ(cv::countNonZero(a.mask != b.mask), 0);
  for (int y = 0; y < a.column.rows; ++y) {
    for (int x = 0; x < a.column.cols; ++x) {
      for (const auto* m : {&a.column, &a.row}) {
        const cv::Mat& other = m == &a.column ? b.column : b.row;
        const float u = m->at<float>(y, x), w = other.at<float>(y, x);
        ASSERT_TRUE((std::isnan(u) && std::isnan(w)) || u == w) << x << "," << y << ": " << u << " " << w;
      }
    }
  }
}

// procam's own sequence, written for another program by ExportPatterns, photographed (here: the
// patterns themselves) and imported back, decodes exactly as the session procam captures would.
TEST(CaptureLayout, ExportedPatternsImportAndDecodeAsProcamsOwn) {
  for (const int period : {0, 16}) {
    StructuredLightOptions options;
    options.width = 200;
    options.height = 72;
    options.phase_period = period;
    const TempDir dir;
    const int count = ExportPatterns(options, dir.path());
    const CaptureSequence sequence = MakeStructuredLightSequence(options);
    ASSERT_EQ(count, static_cast<int>(sequence.patterns.size()));
    // The layout read back describes the sequence image for image.
    const CaptureLayout layout = ReadCaptureLayout(dir / "layout.json");
    const StructuredLightLayout decodable = layout.Decodable();
    const StructuredLightLayout own = LayoutOf(options);
    ASSERT_EQ(decodable.image_count, own.image_count);
    ASSERT_EQ(decodable.gray.size(), own.gray.size());
    for (size_t g = 0; g < own.gray.size(); ++g) {
      EXPECT_EQ(decodable.gray[g].images, own.gray[g].images);
      EXPECT_EQ(decodable.gray[g].inverse, own.gray[g].inverse);
      EXPECT_EQ(decodable.gray[g].finest_bit, own.gray[g].finest_bit);
    }
    ASSERT_EQ(decodable.phases.size(), own.phases.size());
    for (size_t p = 0; p < own.phases.size(); ++p) {
      EXPECT_EQ(decodable.phases[p].images, own.phases[p].images);
      for (size_t k = 0; k < own.phases[p].shifts.size(); ++k)
        EXPECT_NEAR(decodable.phases[p].shifts[k], own.phases[p].shifts[k], 1e-12);
    }
    // The written PNGs are the patterns (8-bit grey).
    const cv::Mat third = ReadImage(dir / "pat002.png", cv::IMREAD_UNCHANGED);
    cv::Mat expected;
    cv::extractChannel(sequence.patterns[2].image, expected, 0);
    EXPECT_EQ(cv::countNonZero(third != expected), 0);

    ImportOptions import;
    import.layout = dir / "layout.json";
    import.out = dir / "session";
    import.name = "left";
    const DecodeSummary summary = ImportCaptures(import);
    EXPECT_EQ(summary.decoded, options.width * options.height) << summary.BriefReport();
    const StructuredLightMap direct = DecodeStructuredLight(options, IdealCaptures(sequence));
    ExpectSameMap(summary.map, direct);
    // Every reader of sessions reads it.
    const StructuredLightSession session = ReadStructuredLightSession(dir / "session");
    EXPECT_EQ(session.display_name, "import:left");
    ExpectSameMap(DecodeStructuredLight(session.layout, session.images), direct);
    EXPECT_TRUE(fs::exists(dir / "session" / "decode" / "decode.png"));
    EXPECT_TRUE(fs::exists(dir / "session" / "decode" / "result.json"));
  }
}

// Where camera pixel (x, y) looks: a slightly skewed affine map onto a 1920×1080 projector.
cv::Point2d Truth(double x, double y) { return {6.2 * x + 4.1 + 0.2 * y, 5.2 * y + 2.7 + 0.1 * x}; }

// The patterns as the generating tools define them, at projector coordinate u of `size` pixels.
// OpenCV's GrayCodePattern (structured_light module, graycodepattern.cpp): for a code of
// ⌈size/cell⌉ values, bit image j (j = 0 first) shows bit (bits − 1 − j) of the reflected binary
// code of the cell index, white for 1; each followed by its inverse.
double OpenCvGrayValue(double u, int cell, int bits, int image_in_axis) {
  const int n = static_cast<int>(std::floor(u / cell));
  const int gray = n ^ (n >> 1);
  const int bit = bits - 1 - image_in_axis / 2;
  const int value = (gray >> bit) & 1;
  return (image_in_axis % 2 == 0) ? value : 1 - value;
}
// kamino410/phase-shifting (phase_shifting.py, generate): 0.5 (cos(u · ω + π (k − 2) 2/3) + 1),
// k = 1, 2, 3, ω = 6π/200 then 4π/200.
double KaminoPhaseValue(double u, double omega, int k) {
  return 0.5 * (std::cos(u * omega + std::numbers::pi * (k - 2) * 2.0 / 3.0) + 1.0);
}

// Photos of a sequence of the kamino410 layout, each camera pixel the mean of 3×3 samples over
// its footprint (blur of about one camera pixel, i.e. six projector pixels), ambient light, read
// noise and 8-bit quantisation: 12 phase images, 18 Gray images, white, black.
std::vector<cv::Mat> RenderKaminoPhotos(int width, int height, double noise) {
  std::mt19937 random(7);
  std::normal_distribution<double> read_noise(0.0, noise);
  const int cell = 100, column_bits = 5, row_bits = 4;  // ⌈log2 20⌉, ⌈log2 11⌉
  std::vector<cv::Mat> photos;
  const auto render = [&](const std::function<double(double u, double v)>& light) {
    cv::Mat photo(height, width, CV_8UC1);
    for (int y = 0; y < height; ++y) {
      for (int x = 0; x < width; ++x) {
        double sum = 0.0;
        for (int sy = -1; sy <= 1; ++sy)
          for (int sx = -1; sx <= 1; ++sx) {
            const cv::Point2d p = Truth(x + sx / 3.0, y + sy / 3.0);
            sum += light(p.x, p.y);
          }
        const double value = 12.0 + 200.0 * sum / 9.0 + read_noise(random);
        photo.at<uint8_t>(y, x) = cv::saturate_cast<uint8_t>(value);
      }
    }
    photos.push_back(photo);
  };
  for (bool column : {true, false})
    for (double omega : {6 * std::numbers::pi / 200, 4 * std::numbers::pi / 200})
      for (int k = 1; k <= 3; ++k)
        render([&](double u, double v) { return KaminoPhaseValue(column ? u : v, omega, k); });
  for (int j = 0; j < 2 * column_bits; ++j)
    render([&](double u, double) { return OpenCvGrayValue(u, cell, column_bits, j); });
  for (int j = 0; j < 2 * row_bits; ++j)
    render([&](double, double v) { return OpenCvGrayValue(v, cell, row_bits, j); });
  render([](double, double) { return 1.0; });
  render([](double, double) { return 0.0; });
  return photos;
}

struct Errors {
  double median = 0, p95 = 0, max = 0;
  double decoded_fraction = 0;
};

Errors Score(const StructuredLightMap& map) {
  std::vector<double> errors;
  long long inside = 0;
  for (int y = 0; y < map.column.rows; ++y) {
    for (int x = 0; x < map.column.cols; ++x) {
      const cv::Point2d truth = Truth(x, y);
      if (truth.x < 1919.5 && truth.y < 1079.5) ++inside;
      if (!map.mask.at<uint8_t>(y, x)) continue;
      errors.push_back(std::abs(map.column.at<float>(y, x) - truth.x));
      errors.push_back(std::abs(map.row.at<float>(y, x) - truth.y));
    }
  }
  Errors result;
  if (errors.empty()) return result;
  std::sort(errors.begin(), errors.end());
  result.median = errors[errors.size() / 2];
  result.p95 = errors[errors.size() * 95 / 100];
  result.max = errors.back();
  result.decoded_fraction = 0.5 * errors.size() / std::max<long long>(1, inside);
  return result;
}

// OpenCV's Gray code in 100-pixel cells, as wide as the coarser sinusoid's period: the Gray cell
// alone cannot unwrap it (half a cell of doubt is half a period), so the decoder unwraps the
// beat of the two sets (period 200) first. Against the truth of each camera pixel.
TEST(CaptureLayout, OpenCvGrayCodeAndTwoFrequencyPhaseDecodeAgainstTruth) {
  const TempDir dir;
  const std::vector<cv::Mat> photos = RenderKaminoPhotos(300, 200, 1.5);
  for (size_t i = 0; i < photos.size(); ++i) {
    char name[32];
    std::snprintf(name, sizeof(name), "pat%02zu.png", i);
    ASSERT_TRUE(cv::imwrite((dir / name).string(), photos[i]));
  }
  ImportOptions import;
  import.layout = SourceDirLayout();
  import.folder = dir.path();
  import.out = dir / "session";
  const DecodeSummary summary = ImportCaptures(import);
  const Errors errors = Score(summary.map);
  std::printf("decoded %.4f of the pixels inside the projector; error median %.3f, 95%% %.3f, max "
              "%.3f projector px; %s\n",
              errors.decoded_fraction, errors.median, errors.p95, errors.max,
              summary.BriefReport().c_str());
  // 8-bit photos of 3-step sinusoids with σ = 1.5 DN on an amplitude of 100 DN: the phase's
  // standard deviation is about σ √(2/3) / 100 rad, 0.2 px at a period of 66.7 px.
  EXPECT_GT(errors.decoded_fraction, 0.97);
  EXPECT_LT(errors.median, 0.3);
  EXPECT_LT(errors.p95, 0.8);
  EXPECT_LT(errors.max, 3.0);  // no pixel unwrapped into the wrong period
  // The noise estimated from the photos: 1.5 DN read noise (and 8-bit rounding, 0.29 DN).
  EXPECT_NEAR(summary.map.noise_sigma, std::hypot(1.5, 1.0 / std::sqrt(12.0)), 0.3);
  const long long both = summary.map.gray_phase_agree + summary.map.gray_phase_disagree;
  EXPECT_GT(summary.map.gray_phase_agree, 0.98 * both);
}

fs::path RealData() { return testing::SharedDir() / "data" / "real" / "phase_shifting_object2"; }

// Real photographs (kamino410/phase-shifting, sample_data/object2: mugs in front of a wall),
// imported with their layout and decoded. No ground truth comes with them; what is checked: the
// phase and the Gray code agree where both decode, the wall decodes over most of the image and
// smoothly, the decode is reported with its picture.
TEST(CaptureLayout, RealPhaseShiftingPhotosImportAndDecode) {
  if (!fs::exists(RealData() / "pat31.png"))
    GTEST_SKIP() << RealData() << " is missing (the team's shared data)";
  const TempDir dir;
  ImportOptions import;
  import.layout = SourceDirLayout();
  import.folder = RealData();
  import.out = dir / "session";
  const DecodeSummary summary = ImportCaptures(import);
  std::printf("%s\n", summary.BriefReport().c_str());
  const StructuredLightMap& map = summary.map;
  EXPECT_EQ(summary.camera_size, cv::Size(1936, 1216));
  const double decoded = static_cast<double>(summary.decoded) / summary.pixels;
  const long long both = map.gray_phase_agree + map.gray_phase_disagree;
  const double agree = static_cast<double>(map.gray_phase_agree) / std::max<long long>(1, both);
  std::printf("decoded %.4f, phase within its Gray cell %.4f of %lld\n", decoded, agree, both);
  EXPECT_GT(decoded, 0.5);
  EXPECT_GT(agree, 0.97);
  // Smooth on the wall: along each row the decoded column grows by nearly the same step from
  // pixel to pixel; the second difference is mostly noise (a wrong period would be 66 px).
  std::vector<double> second;
  long long jumps = 0;
  for (int y = 0; y < map.column.rows; y += 8) {
    for (int x = 1; x + 1 < map.column.cols; ++x) {
      const float a = map.column.at<float>(y, x - 1), b = map.column.at<float>(y, x),
                  c = map.column.at<float>(y, x + 1);
      if (std::isnan(a) || std::isnan(b) || std::isnan(c)) continue;
      const double d = std::abs(a - 2 * b + c);
      second.push_back(d);
      if (d > 20.0) ++jumps;
    }
  }
  ASSERT_FALSE(second.empty());
  std::sort(second.begin(), second.end());
  const double median = second[second.size() / 2];
  std::printf("column second difference: median %.3f px, %lld of %zu over 20 px\n", median, jumps,
              second.size());
  EXPECT_LT(median, 0.5);
  // Over 20 px only at depth edges (the mugs' outlines).
  EXPECT_LT(static_cast<double>(jumps) / second.size(), 0.01);
  EXPECT_TRUE(fs::exists(dir / "session" / "decode" / "decode.png"));
}

// A photo changed after it was imported is refused by every reader, naming it.
TEST(CaptureLayout, PhotoChangedAfterImportIsRefused) {
  StructuredLightOptions options;
  options.width = 64;
  options.height = 32;
  options.phase_period = 0;
  const TempDir dir;
  ExportPatterns(options, dir.path());
  ImportOptions import;
  import.layout = dir / "layout.json";
  import.out = dir / "session";
  ImportCaptures(import);
  const cv::Mat white = ReadImage(dir / "pat000.png", cv::IMREAD_UNCHANGED);
  cv::Mat changed = white.clone();
  changed.at<uint8_t>(3, 3) = 17;
  ASSERT_TRUE(cv::imwrite((dir / "pat000.png").string(), changed));
  try {
    ReadStructuredLightSession(dir / "session");
    FAIL() << "a changed photo was read";
  } catch (const IoError& error) {
    EXPECT_NE(std::string(error.what()).find("pat000.png: changed since it was recorded"),
              std::string::npos)
        << error.what();
  }
}

// Bad layouts: one line naming the file and the key.
TEST(CaptureLayout, BadLayoutsNameTheFileAndKey) {
  const TempDir dir;
  const auto expect_error = [&](const std::string& text, const std::string& expected) {
    const fs::path file = dir.Write("layout.json", text);
    try {
      ReadCaptureLayout(file);
      ADD_FAILURE() << "accepted: " << text;
    } catch (const IoError& error) {
      const std::string what = error.what();
      EXPECT_NE(what.find(file.string()), std::string::npos) << what;
      EXPECT_NE(what.find(expected), std::string::npos) << what;
    }
  };
  const std::string head =
      R"({"format": "procam capture layout", "version": 1, "projector": {"width": 640, "height": 480}, )";
  expect_error(head + R"("sequence": [{"kind": "white"}, {"kind": "blak"}]})", "sequence[1].kind");
  expect_error(head + R"("sequence": [{"kind": "white"}, {"kind": "black"}, {"kind": "phase", "axis": "columns", "period": 16, "shifts_deg": [0, 90]}]})",
               "sequence[2].shifts_deg");
  expect_error(head + R"("sequence": [{"kind": "white"}, {"kind": "gray", "code": "opencv", "cell": 10}]})",
               "no black image");
  expect_error(head + R"("sequence": [{"kind": "white"}, {"kind": "black"}, {"kind": "gray", "cell": 640, "axes": "columns"}]})",
               "sequence[2].cell");
  expect_error(R"({"format": "procam capture layout", "version": 2, "projector": {"width": 640, "height": 480}, "sequence": []})",
               "version");
  expect_error(head + R"("files": {"pattern": "pat.png"}, "sequence": [{"kind": "white"}]})",
               "files.pattern");
  // The photo count against the layout names the folder.
  const fs::path layout = dir.Write(
      "count.json",
      head + R"("sequence": [{"kind": "white"}, {"kind": "black"}, {"kind": "gray", "code": "opencv", "cell": 40}]})");
  ImportOptions import;
  import.layout = layout;
  import.folder = dir / "photos";
  fs::create_directories(import.folder);
  import.out = dir / "session";
  try {
    ImportCaptures(import);
    ADD_FAILURE() << "imported an empty folder";
  } catch (const IoError& error) {
    EXPECT_NE(std::string(error.what()).find("needs 18 photos"), std::string::npos) << error.what();
  }
  EXPECT_FALSE(fs::exists(dir / "session" / "session.json"));
}

}  // namespace
}  // namespace procam
