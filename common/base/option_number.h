#pragma once
// A command-line option's number, checked against its range, with the messages users found
// clear: a number out of range is said as such ("not a number" misled users giving 16 MB), a
// number the option's type cannot hold ("-1" for a count, 1.5 threads) as what it is. One
// definition for raystack render and raystack-prep (each had its own, worded apart).

#include <charconv>
#include <cmath>
#include <string>
#include <string_view>
#include <system_error>
#include <type_traits>

#include "common/base/log.h"  // StrFormat
#include "common/base/status.h"

namespace raystack {

// The whole of `s` as a T (from_chars: no locale, no leading space; one leading '+' is taken).
template <typename T>
bool ParseNumber(std::string_view s, T* out, std::errc* error = nullptr) {
  if (s.size() > 1 && s[0] == '+' && s[1] != '-' && s[1] != '+') s.remove_prefix(1);
  auto [p, ec] = std::from_chars(s.data(), s.data() + s.size(), *out);
  if (error) *error = ec;
  return ec == std::errc() && p == s.data() + s.size();
}

// `text`, given to `option`, into *out within [lo, hi]; `unit` names what it counts ("MiB").
template <typename T>
Status ParseOptionNumber(const std::string& option, const std::string& text, T* out, double lo,
                         double hi, const char* unit = "") {
  // Whole-number options show their bounds in digits (1e+12 is not one they take).
  const auto show = [](double v) {
    return std::is_integral_v<T> ? StrFormat("%.0f", v) : StrFormat("%.10g", v);
  };
  const std::string range = "from " + show(lo) + " to " + show(hi) +
                            (*unit ? std::string(" (") + unit + ")" : std::string());
  const auto out_of_range = [&] {
    return Status::Error(StrFormat("%s %s: must be %s", option.c_str(), text.c_str(), range.c_str()));
  };
  std::errc error{};
  if (!ParseNumber(text, out, &error)) {
    double wide = 0;
    std::errc wide_error{};
    const bool number = ParseNumber(text, &wide, &wide_error);
    // Beyond the type (1e999, 99999999999 threads, -1 of a count): out of its range.
    if (error == std::errc::result_out_of_range || wide_error == std::errc::result_out_of_range ||
        (number && std::isfinite(wide) && (wide < lo || wide > hi)))
      return out_of_range();
    if (number && std::isfinite(wide))  // 1.5 threads; 1e3 for 1000
      return Status::Error(StrFormat("%s %s: must be a whole number written in digits, %s",
                                     option.c_str(), text.c_str(), range.c_str()));
    return Status::Error(StrFormat("%s: '%s' is not a number; give one %s", option.c_str(),
                                   text.c_str(), range.c_str()));
  }
  // Written so that NaN ("nan" parses) is out of every range.
  if (!(static_cast<double>(*out) >= lo && static_cast<double>(*out) <= hi)) return out_of_range();
  return OkStatus();
}

}  // namespace raystack
