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

#include "common/base/status.h"
#include "common/base/log.h"  // StrFormat

namespace raystack {

// The whole of `s` as a T (from_chars: no locale, no leading space or '+').
template <typename T>
bool ParseNumber(std::string_view s, T* out) {
  auto [p, ec] = std::from_chars(s.data(), s.data() + s.size(), *out);
  return ec == std::errc() && p == s.data() + s.size();
}

// `text`, given to `option`, into *out within [lo, hi]; `unit` names what it counts ("MiB").
template <typename T>
Status ParseOptionNumber(const std::string& option, const std::string& text, T* out, double lo,
                         double hi, const char* unit = "") {
  // %.10g: 16777216 in full, not 1.67772e+07.
  const std::string range = StrFormat("from %.10g to %.10g%s%s%s", lo, hi, *unit ? " (" : "",
                                      unit, *unit ? ")" : "");
  if (!ParseNumber(text, out)) {
    double wide = 0;
    if (ParseNumber(text, &wide) && std::isfinite(wide))
      return Status::Error(StrFormat("%s %s: must be %s%s", option.c_str(), text.c_str(),
                                     wide >= lo && wide <= hi ? "a whole number " : "",
                                     range.c_str()));
    return Status::Error(StrFormat("%s: '%s' is not a number; give one %s", option.c_str(),
                                   text.c_str(), range.c_str()));
  }
  // Written so that NaN ("nan" parses) is out of every range.
  if (!(static_cast<double>(*out) >= lo && static_cast<double>(*out) <= hi))
    return Status::Error(StrFormat("%s %s: must be %s", option.c_str(), text.c_str(), range.c_str()));
  return OkStatus();
}

}  // namespace raystack
