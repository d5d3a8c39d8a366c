#include "base/html_report.h"

#include <algorithm>
#include <cmath>
#include <set>

#include <opencv2/imgcodecs.hpp>
#include <fmt/format.h>

#include "base/io.h"

namespace procam {

std::string HtmlEscape(const std::string& text) {
  std::string out;
  for (const char c : text) {
    switch (c) {
      case '&': out += "&amp;"; break;
      case '<': out += "&lt;"; break;
      case '>': out += "&gt;"; break;
      case '"': out += "&quot;"; break;
      default: out += c;
    }
  }
  return out;
}

std::string Base64(const std::string& bytes) {
  static const char* kAlphabet = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
  std::string out;
  out.reserve((bytes.size() + 2) / 3 * 4);
  for (size_t k = 0; k < bytes.size(); k += 3) {
    const uint32_t a = static_cast<unsigned char>(bytes[k]);
    const uint32_t b = k + 1 < bytes.size() ? static_cast<unsigned char>(bytes[k + 1]) : 0;
    const uint32_t c = k + 2 < bytes.size() ? static_cast<unsigned char>(bytes[k + 2]) : 0;
    const uint32_t triple = (a << 16) | (b << 8) | c;
    out += kAlphabet[(triple >> 18) & 63];
    out += kAlphabet[(triple >> 12) & 63];
    out += k + 1 < bytes.size() ? kAlphabet[(triple >> 6) & 63] : '=';
    out += k + 2 < bytes.size() ? kAlphabet[triple & 63] : '=';
  }
  return out;
}

HtmlReport::HtmlReport(std::string title) : title_(std::move(title)) {}

void HtmlReport::Heading(const std::string& text, int level) {
  body_ += fmt::format("<h{0}>{1}</h{0}>\n", std::clamp(level, 1, 4), HtmlEscape(text));
}

void HtmlReport::Paragraph(const std::string& text) { body_ += "<p>" + HtmlEscape(text) + "</p>\n"; }

void HtmlReport::Table(const std::vector<std::string>& header, const std::vector<std::vector<std::string>>& rows) {
  body_ += "<table>\n<tr>";
  for (const std::string& cell : header) body_ += "<th>" + HtmlEscape(cell) + "</th>";
  body_ += "</tr>\n";
  for (const auto& row : rows) {
    body_ += "<tr>";
    for (const std::string& cell : row) body_ += "<td>" + HtmlEscape(cell) + "</td>";
    body_ += "</tr>\n";
  }
  body_ += "</table>\n";
}

void HtmlReport::Figures(const std::vector<std::pair<std::string, cv::Mat>>& captioned) {
  body_ += "<div class=\"figures\">\n";
  for (const auto& [caption, image] : captioned) {
    std::vector<uchar> png;
    if (!cv::imencode(".png", image, png)) throw IoError("report: cannot encode picture '" + caption + "'");
    body_ += fmt::format("<figure><img alt=\"{0}\" src=\"data:image/png;base64,{1}\"><figcaption>{0}</figcaption></figure>\n",
                         HtmlEscape(caption), Base64(std::string(png.begin(), png.end())));
  }
  body_ += "</div>\n";
}

void HtmlReport::Plot(const std::string& title, const std::string& x_label, const std::string& y_label,
                      const std::vector<Series>& series) {
  size_t longest_name = 0;
  bool whole_x = true;
  for (const auto& [name, points] : series) {
    longest_name = std::max(longest_name, name.size());
    for (const auto& point : points) whole_x &= point.first == std::floor(point.first);
  }
  // The legend sits right of the plot: ~7.5 px per character at 13 px.
  const double left = 70, top = 30, bottom = 50;
  const double right = std::max(160.0, 7.5 * static_cast<double>(longest_name) + 24.0);
  const double width = 480 + right, height = 360;
  double x_min = 1e300, x_max = -1e300, y_min = 1e300, y_max = -1e300;
  for (const auto& [name, points] : series) {
    for (const auto& [x, y] : points) {
      if (!(y > 0.0)) continue;
      x_min = std::min(x_min, x);
      x_max = std::max(x_max, x);
      y_min = std::min(y_min, std::log10(y));
      y_max = std::max(y_max, std::log10(y));
    }
  }
  if (x_min > x_max) return;
  if (x_max == x_min) x_max = x_min + 1;
  y_min = std::floor(y_min);
  y_max = std::max(std::ceil(y_max), y_min + 1);
  auto sx = [&](double x) { return left + (x - x_min) / (x_max - x_min) * (width - left - right); };
  auto sy = [&](double y) { return top + (y_max - std::log10(y)) / (y_max - y_min) * (height - top - bottom); };
  static const char* kColours[] = {"#d62728", "#1f77b4", "#2ca02c", "#9467bd", "#ff7f0e", "#8c564b"};
  std::string svg = fmt::format("<svg class=\"plot\" width=\"{}\" height=\"{}\" viewBox=\"0 0 {} {}\">\n", width, height,
                                width, height);
  svg += fmt::format("<text x=\"{}\" y=\"18\" class=\"title\">{}</text>\n", left, HtmlEscape(title));
  svg += fmt::format("<rect x=\"{}\" y=\"{}\" width=\"{}\" height=\"{}\" fill=\"none\" stroke=\"#999\"/>\n", left, top,
                     width - left - right, height - top - bottom);
  for (int decade = static_cast<int>(y_min); decade <= static_cast<int>(y_max); ++decade) {
    const double y = sy(std::pow(10.0, decade));
    svg += fmt::format("<line x1=\"{}\" x2=\"{}\" y1=\"{:.1f}\" y2=\"{:.1f}\" stroke=\"#eee\"/>", left, width - right, y, y);
    svg += fmt::format("<text x=\"{}\" y=\"{:.1f}\" text-anchor=\"end\">1e{}</text>\n", left - 6, y + 4, decade);
  }
  if (whole_x) {
    const double step = std::max(1.0, std::ceil((x_max - x_min) / 6.0));
    for (double x = std::ceil(x_min); x <= x_max + 1e-9; x += step) {
      svg += fmt::format("<text x=\"{:.1f}\" y=\"{}\" text-anchor=\"middle\">{:.0f}</text>\n", sx(x),
                         height - bottom + 18, x);
    }
  } else {
    for (int tick = 0; tick <= 5; ++tick) {
      const double x = x_min + (x_max - x_min) * tick / 5;
      svg += fmt::format("<text x=\"{:.1f}\" y=\"{}\" text-anchor=\"middle\">{:.3g}</text>\n", sx(x),
                         height - bottom + 18, x);
    }
  }
  svg += fmt::format("<text x=\"{}\" y=\"{}\" text-anchor=\"middle\">{}</text>\n", (left + width - right) / 2, height - 8,
                     HtmlEscape(x_label));
  svg += fmt::format("<text x=\"14\" y=\"{}\" transform=\"rotate(-90 14 {})\" text-anchor=\"middle\">{}</text>\n",
                     (top + height - bottom) / 2, (top + height - bottom) / 2, HtmlEscape(y_label));
  for (size_t s = 0; s < series.size(); ++s) {
    std::string points;
    for (const auto& [x, y] : series[s].second) {
      if (y > 0.0) points += fmt::format("{:.1f},{:.1f} ", sx(x), sy(y));
    }
    const char* colour = kColours[s % 6];
    svg += fmt::format("<polyline fill=\"none\" stroke=\"{}\" stroke-width=\"2\" points=\"{}\"/>\n", colour, points);
    svg += fmt::format("<text x=\"{}\" y=\"{}\" fill=\"{}\">{}</text>\n", width - right + 10, top + 16 + 18 * s, colour,
                       HtmlEscape(series[s].first));
  }
  svg += "</svg>\n";
  body_ += svg;
}

std::string HtmlReport::Html() const {
  return "<!DOCTYPE html>\n<html lang=\"en\">\n<head>\n<meta charset=\"utf-8\">\n<title>" + HtmlEscape(title_) +
         "</title>\n<style>\n"
         "body{font-family:sans-serif;margin:24px;color:#222;max-width:1400px}\n"
         "table{border-collapse:collapse;margin:12px 0}td,th{border:1px solid #ccc;padding:4px 8px;text-align:right}\n"
         "th{background:#f3f3f3}.figures{display:flex;flex-wrap:wrap;gap:12px}\n"
         "figure{margin:0}figure img{max-width:420px;display:block}figcaption{font-size:13px;color:#555}\n"
         ".plot text{font-size:12px}.plot .title{font-size:14px;font-weight:bold}\n"
         "</style>\n</head>\n<body data-ready=\"no\">\n<h1>" +
         HtmlEscape(title_) + "</h1>\n" + body_ +
         "<script>\nwindow.addEventListener('load', function() {\n"
         "  var images = Array.prototype.slice.call(document.images);\n"
         "  var ok = images.every(function(i) { return i.complete && i.naturalWidth > 0; });\n"
         "  document.body.setAttribute('data-ready', ok ? 'yes' : 'broken');\n"
         "  document.body.setAttribute('data-images', String(images.length));\n"
         "});\n</script>\n</body>\n</html>\n";
}

void HtmlReport::Write(const std::filesystem::path& path) const { WriteFileAtomically(path, Html()); }

namespace {

std::string Unbase64(const std::string& text) {
  static const std::string kAlphabet =
      "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
  std::string bytes;
  int bits = 0, value = 0;
  for (const char c : text) {
    if (c == '=') break;
    const size_t index = kAlphabet.find(c);
    if (index == std::string::npos) return "";
    value = (value << 6) | static_cast<int>(index);
    bits += 6;
    if (bits >= 8) {
      bits -= 8;
      bytes.push_back(static_cast<char>((value >> bits) & 0xff));
    }
  }
  return bytes;
}

}  // namespace

std::vector<std::string> CheckReportStructure(const std::string& html) {
  std::vector<std::string> problems;
  std::set<std::string> headings;
  for (size_t h = html.find("<h"); h != std::string::npos; h = html.find("<h", h + 2)) {
    if (h + 3 >= html.size() || html[h + 2] < '1' || html[h + 2] > '6' || html[h + 3] != '>') continue;
    const std::string close = "</h" + std::string(1, html[h + 2]) + ">";
    const size_t end = html.find(close, h);
    if (end == std::string::npos) continue;
    const std::string text = html.substr(h + 4, end - h - 4);
    if (!headings.insert(text).second) problems.push_back("heading '" + text + "' appears twice");
  }
  size_t at = 0;
  int pictures = 0;
  while ((at = html.find("<img", at)) != std::string::npos) {
    ++pictures;
    const size_t end = html.find('>', at);
    const std::string tag = html.substr(at, end - at);
    const size_t figure = html.rfind("<figure>", at), closed = html.rfind("</figure>", at);
    const size_t caption = html.find("<figcaption>", end), caption_end = html.find("</figcaption>", end);
    const bool in_figure = figure != std::string::npos && (closed == std::string::npos || closed < figure);
    const bool captioned = caption != std::string::npos && caption_end != std::string::npos &&
                           caption_end > caption + 12 &&
                           caption < html.find("</figure>", end);
    if (!in_figure || !captioned)
      problems.push_back("picture " + std::to_string(pictures) + " has no caption");
    const std::string prefix = "src=\"data:image/png;base64,";
    const size_t source = tag.find(prefix);
    bool decodes = false;
    if (source != std::string::npos) {
      const size_t start = source + prefix.size();
      const std::string bytes = Unbase64(tag.substr(start, tag.find('"', start) - start));
      const std::vector<uchar> buffer(bytes.begin(), bytes.end());
      decodes = !buffer.empty() && !cv::imdecode(buffer, cv::IMREAD_UNCHANGED).empty();
    }
    if (!decodes) problems.push_back("picture " + std::to_string(pictures) + " does not decode");
    at = end;
  }
  return problems;
}

}  // namespace procam
