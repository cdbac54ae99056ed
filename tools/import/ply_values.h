#pragma once
// The values of a PLY body, one at a time, whatever the format: ascii records are lines of
// tokens; binary values are read in the file's byte order. Errors name the line (ascii) or the
// byte offset of the offending value (binary).

#include <cstdint>
#include <string_view>

#include "common/base/status.h"
#include "tools/import/buffered_input.h"
#include "tools/import/ply_header.h"

namespace raystack::import {

class PlyValueReader {
 public:
  PlyValueReader(BufferedInput& input, PlyFormat format) : input_(input), format_(format) {}

  // Brackets one element record: ascii records are one line each, with nothing left over.
  Status BeginRecord(std::string_view element_name);
  Status EndRecord();

  // A value of any type as a finite float; with `non_finite_as_nan`, a value that is not one
  // (NaN, inf, beyond the float range) reads as NaN instead of being an error.
  Status ReadFloat(PlyType type, float* out, bool non_finite_as_nan = false);
  // A value of any type as a finite double (positions read for --shift).
  Status ReadDouble(PlyType type, double* out);
  // A value of an integer type (the header guarantees lists counts are).
  Status ReadInteger(PlyType type, int64_t* out);
  // Reads past one value or one whole list.
  Status Skip(PlyType type);
  Status SkipList(PlyType count_type, PlyType item_type);

  // An error at the current place.
  Status Error(std::string_view message) const;

 private:
  bool ascii() const { return format_ == PlyFormat::kAscii; }
  Status NextToken(std::string_view* token);
  Status ParseAsciiInteger(std::string_view token, PlyType type, int64_t* out);
  // Reads one binary value into a double or an int64 (integer types), in host byte order.
  Status ReadBinary(PlyType type, double* real, int64_t* integer);

  BufferedInput& input_;
  PlyFormat format_;
  std::string_view rest_;      // ascii: what is left of the record's line
  std::string element_;        // ascii: the element being read, and its record's index
  uint64_t record_ = 0;
  uint64_t value_offset_ = 0;  // binary: where the last value started
};

}  // namespace raystack::import
