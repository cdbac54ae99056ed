#include "tools/import/ply_values.h"

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstring>
#include <limits>
#include <string>

#include "common/base/log.h"
#include "tools/import/text_scan.h"

namespace raystack::import {
namespace {

bool FitsIntegerType(int64_t value, PlyType type) {
  struct Range {
    int64_t min, max;
  };
  static constexpr Range kRanges[] = {
      {INT8_MIN, INT8_MAX},   {0, UINT8_MAX},  {INT16_MIN, INT16_MAX},
      {0, UINT16_MAX},        {INT32_MIN, INT32_MAX}, {0, UINT32_MAX},
  };
  const Range& range = kRanges[static_cast<int>(type)];
  return value >= range.min && value <= range.max;
}

template <typename T>
T Load(const unsigned char* bytes) {
  T value;
  std::memcpy(&value, bytes, sizeof(T));
  return value;
}

}  // namespace

Status PlyValueReader::BeginRecord(std::string_view element_name) {
  if (!ascii()) return OkStatus();
  if (element_ == element_name) {
    ++record_;
  } else {
    element_ = element_name;
    record_ = 0;
  }
  std::string_view line;
  do {
    if (!input_.NextLine(&line)) {
      if (!input_.status().ok()) return input_.status();
      return input_.LineError("unexpected end of file in element '" + std::string(element_name) +
                              "'");
    }
    line = Trim(line);
  } while (line.empty());
  rest_ = line;
  return OkStatus();
}

Status PlyValueReader::EndRecord() {
  if (!ascii()) return OkStatus();
  std::string_view token = raystack::import::NextToken(&rest_);
  // Often a line of the next element, read as this one's: the file has fewer records than its
  // header declares (a vertex count one too high read the first face as a vertex).
  if (!token.empty())
    return Error(StrFormat("more values on the line than the header declares for %s %llu ('%s'); "
                           "if this is a line of the next element, the file has fewer '%s' lines "
                           "than its header says", element_.c_str(),
                           static_cast<unsigned long long>(record_),
                           std::string(token).c_str(), element_.c_str()));
  return OkStatus();
}

Status PlyValueReader::NextToken(std::string_view* token) {
  *token = raystack::import::NextToken(&rest_);
  if (token->empty()) return Error("fewer values on the line than the header declares");
  return OkStatus();
}

Status PlyValueReader::ReadBinary(PlyType type, double* real, int64_t* integer) {
  unsigned char bytes[8];
  // At most 8 (a double); the bound also tells GCC so, which otherwise warns, on arm64, that the
  // reversal below may write past `bytes`.
  const size_t size = std::min(static_cast<size_t>(PlyTypeBytes(type)), sizeof(bytes));
  value_offset_ = input_.offset();
  RAYSTACK_RETURN_IF_ERROR(input_.ReadBytes(bytes, size));
  const bool file_big_endian = format_ == PlyFormat::kBinaryBigEndian;
  if (file_big_endian != (std::endian::native == std::endian::big))
    std::reverse(bytes, bytes + size);
  switch (type) {
    case PlyType::kInt8: *integer = Load<int8_t>(bytes); break;
    case PlyType::kUint8: *integer = Load<uint8_t>(bytes); break;
    case PlyType::kInt16: *integer = Load<int16_t>(bytes); break;
    case PlyType::kUint16: *integer = Load<uint16_t>(bytes); break;
    case PlyType::kInt32: *integer = Load<int32_t>(bytes); break;
    case PlyType::kUint32: *integer = Load<uint32_t>(bytes); break;
    case PlyType::kFloat32: *real = static_cast<double>(Load<float>(bytes)); return OkStatus();
    case PlyType::kFloat64: *real = Load<double>(bytes); return OkStatus();
  }
  *real = static_cast<double>(*integer);
  return OkStatus();
}

Status PlyValueReader::ReadFloat(PlyType type, float* out, bool non_finite_as_nan) {
  if (ascii()) {
    std::string_view token;
    RAYSTACK_RETURN_IF_ERROR(NextToken(&token));
    if (IsIntegerType(type)) {
      int64_t value = 0;
      RAYSTACK_RETURN_IF_ERROR(ParseAsciiInteger(token, type, &value));
      *out = static_cast<float>(value);
      return OkStatus();
    }
    if (const char* why = ParseFloat(token, out)) {
      if (non_finite_as_nan &&
          (SpellsNonFinite(token) || std::strcmp(why, "number out of float range") == 0)) {
        *out = std::numeric_limits<float>::quiet_NaN();
        return OkStatus();
      }
      return Error(std::string(why) + ": " + Quoted(token));
    }
    return OkStatus();
  }
  double real = 0;
  int64_t integer = 0;
  RAYSTACK_RETURN_IF_ERROR(ReadBinary(type, &real, &integer));
  if (!std::isfinite(real) ||
      std::fabs(real) > static_cast<double>(std::numeric_limits<float>::max())) {
    if (!non_finite_as_nan) return Error("value is not a finite float");
    real = std::numeric_limits<double>::quiet_NaN();
  }
  *out = static_cast<float>(real);
  return OkStatus();
}

Status PlyValueReader::ReadDouble(PlyType type, double* out) {
  if (ascii()) {
    std::string_view token;
    RAYSTACK_RETURN_IF_ERROR(NextToken(&token));
    if (IsIntegerType(type)) {
      int64_t value = 0;
      RAYSTACK_RETURN_IF_ERROR(ParseAsciiInteger(token, type, &value));
      *out = static_cast<double>(value);
      return OkStatus();
    }
    if (const char* why = ParseDouble(token, out))
      return Error(std::string(why) + ": " + Quoted(token));
    return OkStatus();
  }
  int64_t integer = 0;
  RAYSTACK_RETURN_IF_ERROR(ReadBinary(type, out, &integer));
  if (!std::isfinite(*out)) return Error("value is not a finite number");
  return OkStatus();
}

Status PlyValueReader::ReadInteger(PlyType type, int64_t* out) {
  if (!ascii()) {
    double real = 0;
    return ReadBinary(type, &real, out);
  }
  std::string_view token;
  RAYSTACK_RETURN_IF_ERROR(NextToken(&token));
  return ParseAsciiInteger(token, type, out);
}

Status PlyValueReader::ParseAsciiInteger(std::string_view token, PlyType type, int64_t* out) {
  if (const char* why = ParseInt(token, out))
    return Error(std::string(why) + ": " + Quoted(token));
  if (!FitsIntegerType(*out, type)) return Error("integer out of range for its type");
  return OkStatus();
}

Status PlyValueReader::Skip(PlyType type) {
  if (ascii()) {
    std::string_view token;
    return NextToken(&token);
  }
  double real = 0;
  int64_t integer = 0;
  return ReadBinary(type, &real, &integer);
}

Status PlyValueReader::SkipList(PlyType count_type, PlyType item_type) {
  int64_t count = 0;
  RAYSTACK_RETURN_IF_ERROR(ReadInteger(count_type, &count));
  if (count < 0) return Error("negative list length");
  for (int64_t i = 0; i < count; ++i) RAYSTACK_RETURN_IF_ERROR(Skip(item_type));
  return OkStatus();
}

Status PlyValueReader::Error(std::string_view message) const {
  return ascii() ? input_.LineError(message) : input_.ByteError(value_offset_, message);
}

}  // namespace raystack::import
