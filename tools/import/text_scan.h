#pragma once
// Tokens and numbers in one line of text (OBJ, MTL, PLY ascii). Numbers go through
// std::from_chars: locale-free, no allocation, correctly rounded, several times faster than
// strtod. Parse functions return nullptr on success, else a short reason for an error message.

#include <charconv>
#include <cmath>
#include <cstdint>
#include <limits>
#include <string>
#include <string_view>
#include <system_error>

namespace raystack::import {

inline bool IsBlank(char c) { return c == ' ' || c == '\t' || c == '\r' || c == '\f' || c == '\v'; }

// A token of the file as an error message shows it: in quotes, control bytes (a NUL cut the
// message there) as \xNN, at most kShownBytes of it (a 1 MB number was echoed whole: a
// hostile-input review).
inline std::string Quoted(std::string_view token) {
  constexpr size_t kShownBytes = 48;
  std::string out = "'";
  for (size_t i = 0; i < token.size() && i < kShownBytes; ++i) {
    const auto c = static_cast<unsigned char>(token[i]);
    if (c < 0x20 || c == 0x7f) {
      constexpr char kHex[] = "0123456789abcdef";
      out += "\\x";
      out += kHex[c >> 4];
      out += kHex[c & 15];
    } else {
      out += static_cast<char>(c);
    }
  }
  out += "'";
  if (token.size() > kShownBytes) out += "... (" + std::to_string(token.size()) + " bytes)";
  return out;
}

// The text with leading and trailing blanks removed.
inline std::string_view Trim(std::string_view text) {
  while (!text.empty() && IsBlank(text.front())) text.remove_prefix(1);
  while (!text.empty() && IsBlank(text.back())) text.remove_suffix(1);
  return text;
}

// Removes and returns the next blank-separated token of *rest ("" when none is left).
inline std::string_view NextToken(std::string_view* rest) {
  size_t start = 0;
  while (start < rest->size() && IsBlank((*rest)[start])) ++start;
  size_t stop = start;
  while (stop < rest->size() && !IsBlank((*rest)[stop])) ++stop;
  std::string_view token = rest->substr(start, stop - start);
  rest->remove_prefix(stop);
  return token;
}

// A file's first line without the UTF-8 byte order mark some editors put there.
inline std::string_view WithoutByteOrderMark(std::string_view first_line) {
  return first_line.starts_with("\xEF\xBB\xBF") ? first_line.substr(3) : first_line;
}

// The text before a '#' comment.
inline std::string_view StripComment(std::string_view line) {
  size_t hash = line.find('#');
  return hash == std::string_view::npos ? line : line.substr(0, hash);
}

// A finite float. Rejects "nan", "inf" and values beyond the float range; values too small
// for a float become the nearest denormal or zero, as a C compiler would round them.
inline const char* ParseFloat(std::string_view token, float* out) {
  if (!token.empty() && token.front() == '+') {
    token.remove_prefix(1);  // from_chars refuses '+'
    if (!token.empty() && token.front() == '-') return "not a number";
  }
  if (token.empty()) return "missing number";
  const char* end = token.data() + token.size();
  float value = 0;
  auto [ptr, ec] = std::from_chars(token.data(), end, value);
  if (ec == std::errc::result_out_of_range) {
    // Overflow or underflow: decide which in double precision.
    double wide = 0;
    auto [wide_ptr, wide_ec] = std::from_chars(token.data(), end, wide);
    if (wide_ptr != end) return "not a number";  // digits, then something else
    if (wide_ec != std::errc() || std::fabs(wide) > static_cast<double>(std::numeric_limits<float>::max()))
      return "number out of float range";
    value = static_cast<float>(wide);
    ptr = end;
    ec = std::errc();
  }
  if (ec != std::errc() || ptr != end) return "not a number";
  if (!std::isfinite(value)) return "number is not finite";
  *out = value;
  return nullptr;
}

// A finite double (positions read for --shift, whose digits a float would round away).
inline const char* ParseDouble(std::string_view token, double* out) {
  if (!token.empty() && token.front() == '+') {
    token.remove_prefix(1);
    if (!token.empty() && token.front() == '-') return "not a number";
  }
  if (token.empty()) return "missing number";
  const char* end = token.data() + token.size();
  double value = 0;
  auto [ptr, ec] = std::from_chars(token.data(), end, value);
  if (ec == std::errc::result_out_of_range) return "number out of range";
  if (ec != std::errc() || ptr != end) return "not a number";
  if (!std::isfinite(value)) return "number is not finite";
  *out = value;
  return nullptr;
}

// How programs print a number that is not finite: "nan", "-inf", "Infinity", and MSVC's
// "-1.#IND", "1.#INF00", "1.#QNAN0" (3ds Max writes these for a degenerate face's normal).
inline bool SpellsNonFinite(std::string_view token) {
  std::string lower(token);
  for (char& c : lower) c = static_cast<char>(c >= 'A' && c <= 'Z' ? c - 'A' + 'a' : c);
  return lower.find("nan") != std::string::npos || lower.find("inf") != std::string::npos ||
         lower.find("#ind") != std::string::npos;
}

// A comment starts at '#', except in MSVC's spellings of numbers that are not finite (a '#'
// right after a '.': "-1.#IND"), which 3ds Max writes in `vn` lines.
inline std::string_view StripCommentKeepingMsvcNonFinite(std::string_view line) {
  for (size_t i = 0; i < line.size(); ++i)
    if (line[i] == '#' && (i == 0 || line[i - 1] != '.')) return line.substr(0, i);
  return line;
}

// A decimal integer (an optional sign, then digits; nothing else).
inline const char* ParseInt(std::string_view token, int64_t* out) {
  if (!token.empty() && token.front() == '+') {
    token.remove_prefix(1);
    if (!token.empty() && token.front() == '-') return "not an integer";
  }
  if (token.empty()) return "missing integer";
  const char* end = token.data() + token.size();
  auto [ptr, ec] = std::from_chars(token.data(), end, *out);
  if (ec == std::errc::result_out_of_range) return "integer out of range";
  if (ec != std::errc() || ptr != end) return "not an integer";
  return nullptr;
}

}  // namespace raystack::import
