// The page's building blocks of `mcms report`: text checks, escaping, tables.
#include "jobs/html_report_internal.h"

#include <Eigen/Cholesky>
#include <numbers>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <map>
#include <optional>
#include <set>
#include <sstream>
#include <system_error>

#include <nlohmann/json.hpp>

#include "core/error.h"
#include "core/io.h"
#include "core/limits.h"
#include "core/output_folder.h"
#include "core/pose_math.h"
#include "core/statistics.h"
#include "core/svg_plot.h"

namespace mcms::html_report_internal {

namespace fs = std::filesystem;
constexpr size_t kMaxSortableRows = 2000;  // a longer table shows its first and last rows

// Why `s` is not UTF-8 text ("" when it is): a NUL byte, a control character other than
// tab, line feed, carriage return and form feed, or a byte sequence that is not UTF-8 (a
// sequence cut at the end of a bounded read is allowed).
// The length of the UTF-8 sequence at s[i] (1 for ASCII); 0 where it is not UTF-8, -1 where
// a valid start is cut by the end of `s`.
int Utf8Length(const std::string& s, size_t i) {
  const auto c = static_cast<unsigned char>(s[i]);
  if (c < 0x80) return 1;
  int len = 0;  // the sequence's length by its lead byte
  if (c >= 0xc2 && c <= 0xdf) len = 2;
  else if (c >= 0xe0 && c <= 0xef) len = 3;
  else if (c >= 0xf0 && c <= 0xf4) len = 4;
  if (len == 0) return 0;
  for (int k = 1; k < len; ++k) {
    if (i + k >= s.size()) return -1;
    if ((static_cast<unsigned char>(s[i + k]) & 0xc0) != 0x80) return 0;
  }
  return len;
}

bool ControlCharacter(unsigned char c) { return c < 0x20 && c != '\t' && c != '\n' && c != '\r' && c != '\f'; }

std::string NotText(const std::string& s) {
  for (size_t i = 0; i < s.size();) {
    const auto c = static_cast<unsigned char>(s[i]);
    if (c == 0) return "a NUL byte at " + std::to_string(i);
    if (ControlCharacter(c)) return "control character " + std::to_string(c) + " at " + std::to_string(i);
    const int len = Utf8Length(s, i);
    if (len < 0) return "";
    if (len == 0) return "a byte that is not UTF-8 at " + std::to_string(i);
    i += len;
  }
  return "";
}

// `s` escaped for HTML; a byte that is not UTF-8 or a control character (a file name is any
// bytes but '/' and NUL) becomes U+FFFD, so the page stays UTF-8.
std::string Html(const std::string& s) {
  std::string o;
  o.reserve(s.size());
  for (size_t i = 0; i < s.size(); ++i) {
    const char c = s[i];
    const int len = Utf8Length(s, i);
    if (len <= 0 || (len == 1 && ControlCharacter(static_cast<unsigned char>(c)))) {
      o += "\xef\xbf\xbd";
      continue;
    }
    if (len > 1) {
      o.append(s, i, static_cast<size_t>(len));
      i += static_cast<size_t>(len) - 1;
      continue;
    }
    switch (c) {
      case '<':
        o += "&lt;";
        break;
      case '>':
        o += "&gt;";
        break;
      case '&':
        o += "&amp;";
        break;
      case '"':
        o += "&quot;";
        break;
      case '\'':
        o += "&#39;";
        break;
      default:
        o += c;
    }
  }
  return o;
}

std::string Base64(const std::string& in) {
  static const char* t = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
  std::string o;
  o.reserve((in.size() + 2) / 3 * 4);
  size_t i = 0;
  for (; i + 2 < in.size(); i += 3) {
    const unsigned v = (static_cast<unsigned char>(in[i]) << 16) | (static_cast<unsigned char>(in[i + 1]) << 8) |
                       static_cast<unsigned char>(in[i + 2]);
    o += t[(v >> 18) & 63], o += t[(v >> 12) & 63], o += t[(v >> 6) & 63], o += t[v & 63];
  }
  if (i + 1 == in.size()) {
    const unsigned v = static_cast<unsigned char>(in[i]) << 16;
    o += t[(v >> 18) & 63], o += t[(v >> 12) & 63], o += "==";
  } else if (i + 2 == in.size()) {
    const unsigned v = (static_cast<unsigned char>(in[i]) << 16) | (static_cast<unsigned char>(in[i + 1]) << 8);
    o += t[(v >> 18) & 63], o += t[(v >> 12) & 63], o += t[(v >> 6) & 63], o += '=';
  }
  return o;
}

std::string Lower(std::string s) {
  for (char& c : s) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return s;
}

bool StartsWith(const std::string& s, const std::string& p) {
  return s.compare(0, p.size(), p) == 0;
}

std::string Num(double v) {
  char buf[32];
  std::snprintf(buf, sizeof(buf), "%.6g", v);
  return buf;
}

std::string Bytes(uintmax_t n) {
  char buf[32];
  if (n < 10000)
    std::snprintf(buf, sizeof(buf), "%ju B", n);
  else if (n < 10000000)
    std::snprintf(buf, sizeof(buf), "%.0f kB", n / 1e3);
  else
    std::snprintf(buf, sizeof(buf), "%.0f MB", n / 1e6);
  return buf;
}


// A CSV read by the one reader (core/io.h ReadCsv); on a malformed table its message in
// *error, and the page says the table was not shown.
Table ReadTable(const fs::path& path, std::string* error) {
  Table t;
  try {
    CsvTable c = ReadCsv(path);
    t.comments = std::move(c.comments);
    t.header = std::move(c.header);
    t.rows = std::move(c.rows);
  } catch (const InputError& e) {
    // The page names the file already: the reader's message from its line on.
    std::string m = e.what();
    if (m.rfind(path.string(), 0) == 0) m = m.substr(path.string().size());
    *error = m.substr(std::min(m.size(), m.find_first_not_of(": ")));
  }
  return t;
}


std::string FigureHtml(const std::string& svg, const std::string& caption) {
  return "<figure><img class=\"figure\" alt=\"" + Html(caption) + "\" src=\"data:image/svg+xml;base64," + Base64(svg) +
         "\"><figcaption>" + Html(caption) + "</figcaption></figure>\n";
}

std::string Note(const std::string& s) {
  return "<p class=\"note\">" + Html(s) + "</p>\n";
}

// Rows of a table as HTML (all columns; the container scrolls sideways when wide).
void TableRows(std::ostringstream& o, const Table& t, size_t begin, size_t end) {
  for (size_t r = begin; r < end; ++r) {
    o << "<tr>";
    for (size_t c = 0; c < t.rows[r].size(); ++c) {
      // Numbers to 6 significant digits (the file keeps them all); text as it is.
      const auto v = t.Value(r, static_cast<int>(c));
      o << "<td>" << (v && t.rows[r][c].size() > 8 ? Num(*v) : Html(t.rows[r][c])) << "</td>";
    }
    o << "</tr>\n";
  }
}

std::string TableHtml(const Table& t, size_t max_rows) {
  std::ostringstream o;
  for (const auto& c : t.comments) o << "<div class=\"comment\">" << Html(c) << "</div>\n";
  const size_t n = t.rows.size();
  if (n > max_rows) {
    // Per-column statistics.
    o << "<p>" << n << " rows, " << t.header.size() << " columns; per column:</p>\n<div class=\"scroll\"><table>\n"
      << "<tr><th>column</th><th>values</th><th>min</th><th>median</th><th>max</th><th>mean</th><th>text values "
         "(count)</th></tr>\n";
    for (size_t c = 0; c < t.header.size(); ++c) {
      std::vector<double> v;
      std::map<std::string, size_t> text;
      size_t empty = 0;
      for (size_t r = 0; r < n; ++r) {
        if (auto x = t.Value(r, static_cast<int>(c)))
          v.push_back(*x);
        else if (t.rows[r][c].empty())
          ++empty;
        else
          ++text[t.rows[r][c]];
      }
      o << "<tr><td>" << Html(t.header[c]) << "</td><td>" << v.size() << " numbers";
      if (empty) o << ", " << empty << " empty";
      o << "</td>";
      if (!v.empty()) {
        double sum = 0;
        for (double x : v) sum += x;
        std::vector<double> s = v;
        const double med = SelectedMedian(s);
        o << "<td>" << Num(*std::min_element(v.begin(), v.end())) << "</td><td>" << Num(med) << "</td><td>"
          << Num(*std::max_element(v.begin(), v.end())) << "</td><td>" << Num(sum / static_cast<double>(v.size()))
          << "</td>";
      } else {
        o << "<td></td><td></td><td></td><td></td>";
      }
      o << "<td>";
      std::vector<std::pair<size_t, std::string>> by_count;
      for (const auto& [k, m] : text) by_count.push_back({m, k});
      std::sort(by_count.begin(), by_count.end(), [](const auto& a, const auto& b) { return a.first > b.first; });
      for (size_t i = 0; i < by_count.size() && i < 6; ++i)
        o << (i ? ", " : "") << Html(by_count[i].second.empty() ? "(empty)" : by_count[i].second) << " ("
          << by_count[i].first << ")";
      if (by_count.size() > 6) o << ", ... (" << by_count.size() << " distinct)";
      o << "</td></tr>\n";
    }
    o << "</table></div>\n";
    if (n <= kMaxSortableRows)
      o << "<details><summary>all " << n << " rows (a click on a column's header sorts by it)</summary>\n";
    else
      o << "<p>First and last rows:</p>\n";
  }
  o << "<div class=\"scroll" << (n > max_rows ? " tall" : "") << "\"><table class=\"sortable\">\n<thead><tr>";
  for (const auto& h : t.header) o << "<th>" << Html(h) << "</th>";
  o << "</tr></thead>\n<tbody>\n";
  if (n <= kMaxSortableRows) {
    TableRows(o, t, 0, n);
  } else {
    const size_t k = std::max<size_t>(1, max_rows / 2);
    TableRows(o, t, 0, k);
    o << "<tr><td class=\"gap\" colspan=\"" << t.header.size() << "\">... " << n - 2 * k << " rows ...</td></tr>\n";
    TableRows(o, t, n - k, n);
  }
  o << "</tbody></table></div>\n";
  if (n > max_rows && n <= kMaxSortableRows) o << "</details>\n";
  return o.str();
}

}  // namespace mcms::html_report_internal
