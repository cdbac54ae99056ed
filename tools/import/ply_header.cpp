#include "tools/import/ply_header.h"

#include <optional>

#include "tools/import/text_scan.h"

namespace raystack::import {
namespace {

// Real files have a handful of each; more means a damaged or hostile header.
constexpr size_t kMaxElements = 1024;
constexpr size_t kMaxProperties = 1024;

std::optional<PlyType> ParseType(std::string_view name) {
  struct Alias {
    std::string_view name;
    PlyType type;
  };
  static constexpr Alias kAliases[] = {
      {"char", PlyType::kInt8},     {"int8", PlyType::kInt8},
      {"uchar", PlyType::kUint8},   {"uint8", PlyType::kUint8},
      {"short", PlyType::kInt16},   {"int16", PlyType::kInt16},
      {"ushort", PlyType::kUint16}, {"uint16", PlyType::kUint16},
      {"int", PlyType::kInt32},     {"int32", PlyType::kInt32},
      {"uint", PlyType::kUint32},   {"uint32", PlyType::kUint32},
      {"float", PlyType::kFloat32}, {"float32", PlyType::kFloat32},
      {"double", PlyType::kFloat64}, {"float64", PlyType::kFloat64},
  };
  for (const Alias& alias : kAliases)
    if (alias.name == name) return alias.type;
  return std::nullopt;
}

bool IsPrintable(std::string_view line) {
  for (char c : line)
    if (static_cast<unsigned char>(c) < 0x20 && c != '\t') return false;
  return true;
}

// `word` is the start of a header keyword ("elem", "end_he"): what a file cut short ends with.
bool IsKeywordStart(std::string_view word) {
  for (std::string_view keyword : {"element", "property", "end_header", "format", "comment", "obj_info"})
    if (keyword.starts_with(word)) return true;
  return false;
}

class HeaderParser {
 public:
  explicit HeaderParser(BufferedInput& input) : input_(input) {}
  Expected<PlyHeader> Parse();

 private:
  Status ParseFormat(std::string_view rest);
  Status ParseElement(std::string_view rest);
  Status ParseProperty(std::string_view rest);
  Status Type(std::string_view name, PlyType* type);

  BufferedInput& input_;
  PlyHeader header_;
  bool have_format_ = false;
};

Expected<PlyHeader> HeaderParser::Parse() {
  std::string_view line;
  if (!input_.NextLine(&line) || Trim(line) != "ply")
    return input_.LineError("not a PLY file (no 'ply' on the first line)");
  while (input_.NextLine(&line)) {
    if (!IsPrintable(line)) return input_.LineError("binary data in the PLY header");
    std::string_view rest = line;
    std::string_view keyword = NextToken(&rest);
    if (keyword == "end_header") {
      if (!have_format_) return input_.LineError("PLY header has no format line");
      return std::move(header_);
    }
    Status status;
    if (keyword == "format") status = ParseFormat(rest);
    else if (keyword == "element") status = ParseElement(rest);
    else if (keyword == "property") status = ParseProperty(rest);
    else if (keyword == "comment" || keyword == "obj_info" || keyword.empty()) continue;
    else if (input_.offset() >= input_.file_size() && IsKeywordStart(keyword))
      // The file's last bytes, cut inside a keyword (a persona read "unknown ... 'elem'").
      status = input_.LineError("the file ends inside the PLY header, at '" + std::string(line) +
                                "' (truncated?)");
    else
      status = input_.LineError(
          "unknown PLY header line " + Quoted(keyword) +
          (keyword.find_first_not_of("0123456789+-.eE") == std::string_view::npos
               ? " (numbers: the data? the header needs an end_header line before it)"
               : ""));
    if (!status.ok()) return status;
  }
  if (!input_.status().ok()) return input_.status();
  return input_.LineError("PLY header ends without end_header");
}

Status HeaderParser::ParseFormat(std::string_view rest) {
  std::string_view name = NextToken(&rest);
  std::string_view version = NextToken(&rest);
  if (version != "1.0")
    return input_.LineError("unsupported PLY version '" + std::string(version) + "'");
  if (name == "ascii") header_.format = PlyFormat::kAscii;
  else if (name == "binary_little_endian") header_.format = PlyFormat::kBinaryLittleEndian;
  else if (name == "binary_big_endian") header_.format = PlyFormat::kBinaryBigEndian;
  else return input_.LineError("unsupported PLY format '" + std::string(name) + "'");
  have_format_ = true;
  return OkStatus();
}

Status HeaderParser::ParseElement(std::string_view rest) {
  std::string_view name = NextToken(&rest);
  std::string_view count_text = NextToken(&rest);
  int64_t count = 0;
  if (name.empty() || ParseInt(count_text, &count) != nullptr || count < 0 ||
      !NextToken(&rest).empty())
    return input_.LineError("bad element line (expected 'element NAME COUNT')");
  if (header_.elements.size() == kMaxElements)
    return input_.LineError("too many elements in the PLY header");
  for (const PlyElement& element : header_.elements)
    if (element.name == name)
      return input_.LineError("element '" + std::string(name) + "' declared twice");
  header_.elements.push_back({std::string(name), static_cast<uint64_t>(count), {}});
  return OkStatus();
}

Status HeaderParser::ParseProperty(std::string_view rest) {
  if (header_.elements.empty()) return input_.LineError("property before any element");
  PlyElement& element = header_.elements.back();
  if (element.properties.size() == kMaxProperties)
    return input_.LineError("too many properties in element '" + element.name + "'");
  PlyProperty property;
  std::string_view type = NextToken(&rest);
  if (type == "list") {
    property.is_list = true;
    RAYSTACK_RETURN_IF_ERROR(Type(NextToken(&rest), &property.count_type));
    if (!IsIntegerType(property.count_type))
      return input_.LineError("list count type must be an integer type");
    type = NextToken(&rest);
  }
  RAYSTACK_RETURN_IF_ERROR(Type(type, &property.type));
  property.name = std::string(NextToken(&rest));
  if (property.name.empty() || !NextToken(&rest).empty())
    return input_.LineError("bad property line (expected 'property [list T] T NAME')");
  if (element.Find(property.name) >= 0)
    return input_.LineError("property '" + property.name + "' declared twice");
  element.properties.push_back(std::move(property));
  return OkStatus();
}

Status HeaderParser::Type(std::string_view name, PlyType* type) {
  std::optional<PlyType> parsed = ParseType(name);
  if (!parsed) return input_.LineError("unknown PLY type '" + std::string(name) + "'");
  *type = *parsed;
  return OkStatus();
}

}  // namespace

int PlyElement::Find(const std::string& property_name) const {
  for (size_t i = 0; i < properties.size(); ++i)
    if (properties[i].name == property_name) return static_cast<int>(i);
  return -1;
}

Expected<PlyHeader> ReadPlyHeader(BufferedInput& input) { return HeaderParser(input).Parse(); }

}  // namespace raystack::import
