// Report pages: the structure check that the demo's, verify's and evaluate's tests apply.
#include "base/html_report.h"

#include <gtest/gtest.h>
#include <opencv2/core.hpp>

namespace procam {
namespace {

cv::Mat Picture() { return cv::Mat(8, 12, CV_8UC3, cv::Scalar(10, 200, 30)); }

TEST(HtmlReport, WellFormedPageHasNoProblems) {
  HtmlReport report("title");
  report.Heading("One");
  report.Figures({{"a picture", Picture()}, {"another", Picture()}});
  report.Heading("Two");
  report.Plot("cost", "iteration", "f", {{"a long series name that needs room", {{0, 1.0}, {1, 0.5}, {7, 0.1}}}});
  EXPECT_TRUE(CheckReportStructure(report.Html()).empty());
}

TEST(HtmlReport, StructureCheckFindsDoubledHeadingsMissingCaptionsAndBadPictures) {
  HtmlReport report("title");
  report.Heading("Verification");
  report.Heading("Verification", 3);
  report.Figures({{"", Picture()}});
  std::string html = report.Html();
  std::vector<std::string> problems = CheckReportStructure(html);
  ASSERT_EQ(problems.size(), 2u);
  EXPECT_EQ(problems[0], "heading 'Verification' appears twice");
  EXPECT_EQ(problems[1], "picture 1 has no caption");
  // A picture whose data is cut short does not decode.
  const size_t data = html.find("base64,") + 7;
  html.erase(data + 20, html.find('"', data) - data - 20);
  problems = CheckReportStructure(html);
  ASSERT_FALSE(problems.empty());
  EXPECT_EQ(problems.back(), "picture 1 does not decode");
}

TEST(HtmlReport, IterationAxesHaveWholeNumberTicks) {
  HtmlReport report("title");
  report.Plot("cost", "iteration", "f", {{"s", {{0, 1.0}, {1, 0.5}, {2, 0.2}, {3, 0.1}}}});
  const std::string html = report.Html();
  for (const char* tick : {">0</text>", ">1</text>", ">2</text>", ">3</text>"})
    EXPECT_NE(html.find(tick), std::string::npos) << tick;
  EXPECT_EQ(html.find(">0.6</text>"), std::string::npos);
  EXPECT_EQ(html.find(">1.2</text>"), std::string::npos);
}

}  // namespace
}  // namespace procam
