#include "tools/plot_svg.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <sstream>
#include <vector>

namespace motionlod::tools {
namespace {

using nlohmann::json;

struct Series {
  std::string label;
  std::string color;
  bool dashed = false;
  std::vector<std::pair<double, double>> points;  // (kept joints, mean E)
};

std::string Escape(const std::string& text) {
  std::string out;
  for (char c : text) {
    switch (c) {
      case '<': out += "&lt;"; break;
      case '>': out += "&gt;"; break;
      case '&': out += "&amp;"; break;
      case '"': out += "&quot;"; break;
      default: out += c;
    }
  }
  return out;
}

std::string Number(double value) {
  char buffer[32];
  std::snprintf(buffer, sizeof buffer, "%.4g", value);
  return buffer;
}

StatusOr<Series> ReadSeries(const json& points, std::string label, std::string color,
                            const char* field, bool dashed) {
  Series series{std::move(label), std::move(color), dashed, {}};
  for (const json& p : points) {
    if (!p.is_object() || !p.contains("joints") || !p.contains(field) ||
        !p["joints"].is_number() || !p[field].is_number()) {
      return InvalidArgument(std::string("report: every level needs numeric 'joints' and '") + field + "'");
    }
    series.points.emplace_back(p["joints"].get<double>(), p[field].get<double>());
  }
  std::sort(series.points.begin(), series.points.end());
  return series;
}

}  // namespace

StatusOr<std::string> RenderErrorPlotSvg(const json& report) {
  if (!report.is_object() || report.value("format", "") != "motionlod-report") {
    return InvalidArgument("not a motionlod report (missing \"format\": \"motionlod-report\")");
  }
  std::vector<Series> series;
  const char* colors[] = {"#1f77b4", "#d62728", "#2ca02c", "#9467bd"};
  if (report.contains("variant_curves") && report["variant_curves"].is_object()) {
    int index = 0;
    for (const char* name : {"vp", "vpno", "vp+pd", "vpno+pd"}) {
      if (!report["variant_curves"].contains(name)) continue;
      auto s = ReadSeries(report["variant_curves"][name], name, colors[index++ % 4], "mean_E", false);
      if (!s.ok()) return s.status();
      series.push_back(std::move(*s));
    }
    if (report["variant_curves"].contains("vp")) {
      auto s = ReadSeries(report["variant_curves"]["vp"], "unoptimised", "#7f7f7f", "baseline_mean_E", true);
      if (!s.ok()) return s.status();
      series.push_back(std::move(*s));
    }
  } else if (report.contains("levels") && report["levels"].is_array()) {
    const std::string variant = report.value("variant", "level set");
    auto s = ReadSeries(report["levels"], variant, colors[0], "mean_E", false);
    if (!s.ok()) return s.status();
    series.push_back(std::move(*s));
    auto b = ReadSeries(report["levels"], "unoptimised", "#7f7f7f", "baseline_mean_E", true);
    if (!b.ok()) return b.status();
    series.push_back(std::move(*b));
  }
  if (series.empty() || series[0].points.empty()) return InvalidArgument("report: no levels to plot");

  double x_max = 1, y_max = 0;
  for (const Series& s : series) {
    for (const auto& [x, y] : s.points) {
      if (!std::isfinite(x) || !std::isfinite(y)) return InvalidArgument("report: non-finite values");
      x_max = std::max(x_max, x);
      y_max = std::max(y_max, y);
    }
  }
  if (y_max <= 0) y_max = 1;
  y_max *= 1.05;

  const double width = 720, height = 440, left = 70, right = 170, top = 40, bottom = 60;
  const double plot_w = width - left - right, plot_h = height - top - bottom;
  auto px = [&](double x) { return left + plot_w * (x / x_max); };
  auto py = [&](double y) { return top + plot_h * (1 - y / y_max); };

  std::ostringstream svg;
  svg << "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"" << width << "\" height=\"" << height
      << "\" viewBox=\"0 0 " << width << " " << height << "\" font-family=\"sans-serif\" font-size=\"12\">\n";
  svg << "<rect width=\"100%\" height=\"100%\" fill=\"white\"/>\n";
  const std::string title = "Mean E(t) per level: " +
                            report.value("/character/source"_json_pointer, std::string("character")) +
                            " / " + report.value("/motion/name"_json_pointer, std::string("motion"));
  svg << "<text x=\"" << left << "\" y=\"24\" font-size=\"14\">" << Escape(title) << "</text>\n";
  // Axes with ticks.
  svg << "<g stroke=\"#333\" fill=\"none\"><line x1=\"" << left << "\" y1=\"" << top + plot_h << "\" x2=\""
      << left + plot_w << "\" y2=\"" << top + plot_h << "\"/><line x1=\"" << left << "\" y1=\"" << top
      << "\" x2=\"" << left << "\" y2=\"" << top + plot_h << "\"/></g>\n";
  const int x_step = std::max(1, static_cast<int>(std::ceil(x_max / 10)));
  for (int x = 0; x <= x_max; x += x_step) {
    svg << "<line x1=\"" << px(x) << "\" y1=\"" << top + plot_h << "\" x2=\"" << px(x) << "\" y2=\""
        << top + plot_h + 5 << "\" stroke=\"#333\"/><text x=\"" << px(x) << "\" y=\"" << top + plot_h + 18
        << "\" text-anchor=\"middle\">" << x << "</text>\n";
  }
  for (int q = 0; q <= 5; ++q) {
    const double y = y_max * q / 5;
    svg << "<line x1=\"" << left - 5 << "\" y1=\"" << py(y) << "\" x2=\"" << left + plot_w << "\" y2=\""
        << py(y) << "\" stroke=\"#ddd\"/><text x=\"" << left - 8 << "\" y=\"" << py(y) + 4
        << "\" text-anchor=\"end\">" << Number(y) << "</text>\n";
  }
  svg << "<text x=\"" << left + plot_w / 2 << "\" y=\"" << height - 18
      << "\" text-anchor=\"middle\">kept joints</text>\n";
  svg << "<text transform=\"translate(18," << top + plot_h / 2
      << ") rotate(-90)\" text-anchor=\"middle\">mean E(t)</text>\n";
  for (size_t index = 0; index < series.size(); ++index) {
    const Series& s = series[index];
    svg << "<polyline fill=\"none\" stroke=\"" << s.color << "\" stroke-width=\"2\""
        << (s.dashed ? " stroke-dasharray=\"6 4\"" : "") << " points=\"";
    for (const auto& [x, y] : s.points) svg << px(x) << "," << py(y) << " ";
    svg << "\"/>\n";
    for (const auto& [x, y] : s.points) {
      svg << "<circle cx=\"" << px(x) << "\" cy=\"" << py(y) << "\" r=\"2.5\" fill=\"" << s.color << "\"/>\n";
    }
    const double ly = top + 10 + 20 * index;
    svg << "<line x1=\"" << left + plot_w + 15 << "\" y1=\"" << ly << "\" x2=\"" << left + plot_w + 45
        << "\" y2=\"" << ly << "\" stroke=\"" << s.color << "\" stroke-width=\"2\""
        << (s.dashed ? " stroke-dasharray=\"6 4\"" : "") << "/><text x=\"" << left + plot_w + 52
        << "\" y=\"" << ly + 4 << "\">" << Escape(s.label) << "</text>\n";
  }
  svg << "</svg>\n";
  return svg.str();
}

}  // namespace motionlod::tools
