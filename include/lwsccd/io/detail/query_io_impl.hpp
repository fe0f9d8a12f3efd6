// lwsccd — definitions for query_io.hpp.
#pragma once

#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <string>

#include "lwsccd/core/error.hpp"
#include "lwsccd/io/detail/mesh_io_impl.hpp"
#include "lwsccd/io/query_io.hpp"

namespace lwsccd {

namespace detail {

// Parses an integer token as the nearest double; `exact` tells whether it is exactly that value.
inline double parse_rational_part(const char* first, const char* last, bool& exact, bool& ok) {
  std::string token(first, last);
  ok = !token.empty();
  for (std::size_t i = (token[0] == '-' || token[0] == '+') ? 1 : 0; ok && i < token.size(); ++i)
    ok = token[i] >= '0' && token[i] <= '9';
  if (!ok || (token.size() == 1 && (token[0] == '-' || token[0] == '+'))) {
    ok = false;
    return 0;
  }
  const double value = std::strtod(token.c_str(), nullptr);
  // Exact iff printing the double back as an integer gives the same digits.
  char buffer[400];
  std::snprintf(buffer, sizeof buffer, "%.0f", value);
  std::string digits = token[0] == '+' ? token.substr(1) : token;
  while (digits.size() > 1 && digits[0] == '0') digits.erase(0, 1);
  if (digits == "-0") digits = "0";
  exact = digits == buffer || (value == 0 && (digits == "0" || digits == "-0"));
  return value;
}

}  // namespace detail

inline QueryFile load_query_csv(const std::string& path) {
  const std::string bytes = detail::read_whole_file(path);
  QueryFile out;
  std::vector<Vec3d> rows;
  std::vector<signed char> row_truth;
  int line = 0;
  std::size_t pos = 0;
  while (pos < bytes.size()) {
    std::size_t end = bytes.find('\n', pos);
    if (end == std::string::npos) end = bytes.size();
    ++line;
    std::string text = bytes.substr(pos, end - pos);
    pos = end + 1;
    if (!text.empty() && text.back() == '\r') text.pop_back();
    if (text.find_first_not_of(" \t") == std::string::npos) continue;
    std::vector<std::pair<const char*, const char*>> fields;
    const char* p = text.c_str();
    const char* const stop = p + text.size();
    while (true) {
      const char* comma = static_cast<const char*>(std::memchr(p, ',', static_cast<std::size_t>(stop - p)));
      const char* field_end = comma ? comma : stop;
      const char* a = p;
      const char* b = field_end;
      while (a < b && (*a == ' ' || *a == '\t')) ++a;
      while (b > a && (b[-1] == ' ' || b[-1] == '\t')) --b;
      fields.emplace_back(a, b);
      if (!comma) break;
      p = comma + 1;
    }
    const std::string where = "line " + std::to_string(line);
    if (fields.size() != 6 && fields.size() != 7)
      throw InputError(path, where, "expected 6 or 7 comma-separated columns, found " + std::to_string(fields.size()));
    Vec3d point{0, 0, 0};
    for (int k = 0; k < 3; ++k) {
      bool exact_num = false, exact_den = false, ok_num = false, ok_den = false;
      const double num = detail::parse_rational_part(fields[2 * k].first, fields[2 * k].second, exact_num, ok_num);
      const double den = detail::parse_rational_part(fields[2 * k + 1].first, fields[2 * k + 1].second, exact_den, ok_den);
      if (!ok_num || !ok_den)
        throw InputError(path, where, "column " + std::to_string(2 * k + (ok_num ? 2 : 1)) + " is not an integer");
      if (den == 0) throw InputError(path, where, "zero denominator in column " + std::to_string(2 * k + 2));
      point[k] = num / den;
      // A power-of-two denominator divides exactly (barring underflow).
      int exponent = 0;
      const bool power_of_two = std::frexp(std::fabs(den), &exponent) == 0.5;
      if (!(exact_num && exact_den && power_of_two)) ++out.inexact;
    }
    signed char truth = -1;
    if (fields.size() == 7) {
      const std::string t(fields[6].first, fields[6].second);
      if (t != "0" && t != "1") throw InputError(path, where, "truth column must be 0 or 1, found '" + t + "'");
      truth = t == "1" ? 1 : 0;
    }
    rows.push_back(point);
    row_truth.push_back(truth);
  }
  if (rows.size() % 8 != 0)
    throw InputError(path, "", std::to_string(rows.size()) + " rows: not a multiple of 8 (8 rows per query)");
  for (std::size_t q = 0; q < rows.size() / 8; ++q) {
    std::array<Vec3d, 8> pts;
    for (int i = 0; i < 8; ++i) {
      pts[i] = rows[8 * q + i];
      if (row_truth[8 * q + i] != row_truth[8 * q])
        throw InputError(path, "query " + std::to_string(q), "its 8 rows disagree on the truth column");
    }
    out.queries.push_back(pts);
    out.truth.push_back(row_truth[8 * q]);
  }
  return out;
}

}  // namespace lwsccd
