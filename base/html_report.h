#pragma once
// Self-contained HTML reports: text, tables, pictures embedded as base64 PNG and plots as
// inline SVG, so the page opens in any browser with no network and no files beside it.

#include <filesystem>
#include <string>
#include <utility>
#include <vector>

#include <opencv2/core/mat.hpp>

namespace procam {

class HtmlReport {
 public:
  explicit HtmlReport(std::string title);

  void Heading(const std::string& text, int level = 2);
  void Paragraph(const std::string& text);
  void Table(const std::vector<std::string>& header, const std::vector<std::vector<std::string>>& rows);
  // A row of pictures (8-bit BGR or grey OpenCV images) with captions.
  void Figures(const std::vector<std::pair<std::string, cv::Mat>>& captioned);
  // Lines of (x, y) points on a log-scale y axis (y > 0 only), with a legend beside the plot
  // (widened to its longest name). Where every x is a whole number (iterations), the x axis has
  // whole-number ticks only.
  using Series = std::pair<std::string, std::vector<std::pair<double, double>>>;
  void Plot(const std::string& title, const std::string& x_label, const std::string& y_label,
            const std::vector<Series>& series);

  // The complete page. A script marks <body data-ready="yes"> once every picture has decoded,
  // so headless browsers (and tests) can tell the page really rendered.
  std::string Html() const;
  // Writes the page atomically. Throws IoError.
  void Write(const std::filesystem::path& path) const;

 private:
  std::string title_;
  std::string body_;
};

// What a reader would trip over in a report page (Html()): a heading that appears twice, a
// picture outside a captioned figure or with an empty caption, a picture that does not decode as
// PNG. Empty when the page is well formed. For tests.
std::vector<std::string> CheckReportStructure(const std::string& html);

std::string HtmlEscape(const std::string& text);
std::string Base64(const std::string& bytes);

}  // namespace procam
