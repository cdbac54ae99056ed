#pragma once
// Valid UTF-8 (RFC 3629), for text that must be UTF-8 where it goes: a WebSocket text message
// (a browser drops the connection otherwise), a JSON file (its readers refuse it otherwise).
// Paths and messages may hold bytes of another encoding.

#include <cstddef>
#include <string>

namespace raystack {

// The length of the UTF-8 sequence at text[i] (1 to 4), or 0 if none is there: a stray or
// truncated byte, an overlong form, a surrogate, or a code point past U+10FFFF.
inline size_t Utf8Length(const std::string& text, size_t i) {
  const auto c = static_cast<unsigned char>(text[i]);
  const size_t n = c < 0x80 ? 1 : (c >> 5) == 0x6 ? 2 : (c >> 4) == 0xe ? 3 : (c >> 3) == 0x1e ? 4 : 0;
  if (n == 0 || i + n > text.size() || (n == 2 && c < 0xc2) || (n == 4 && c > 0xf4)) return 0;
  for (size_t k = 1; k < n; ++k)
    if ((static_cast<unsigned char>(text[i + k]) >> 6) != 0x2) return 0;
  // The second byte's range where the lead allows less.
  const auto second = static_cast<unsigned char>(n > 1 ? text[i + 1] : 0);
  if ((c == 0xe0 && second < 0xa0) || (c == 0xed && second > 0x9f) || (c == 0xf0 && second < 0x90) ||
      (c == 0xf4 && second > 0x8f))
    return 0;
  return n;
}

}  // namespace raystack
