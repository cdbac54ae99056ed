#pragma once
// Writes PLY files for tests: any format, any property types and layout, lists anywhere.

#include <bit>
#include <cstdint>
#include <cstring>
#include <optional>
#include <sstream>
#include <string>
#include <vector>

namespace raystack::import {

struct TestPlyProperty {
  std::string type;        // "float", "uchar", "int16", ... (item type for lists)
  std::string name;
  std::string count_type;  // non-empty: a list with this count type
};

struct TestPlyElement {
  TestPlyElement(std::string name_in, std::vector<TestPlyProperty> properties_in,
                 std::vector<std::vector<double>> rows_in,
                 std::optional<uint64_t> declared_count_in = std::nullopt)
      : name(std::move(name_in)), properties(std::move(properties_in)),
        rows(std::move(rows_in)), declared_count(declared_count_in) {}

  std::string name;
  std::vector<TestPlyProperty> properties;
  // One row per record; a list contributes its count then its items.
  std::vector<std::vector<double>> rows;
  std::optional<uint64_t> declared_count;  // header count if not rows.size()
};

class TestPlyWriter {
 public:
  // format: "ascii", "binary_little_endian" or "binary_big_endian".
  static std::string Build(const std::string& format, const std::vector<TestPlyElement>& elements) {
    std::ostringstream out;
    out << "ply\nformat " << format << " 1.0\ncomment made by a test\n";
    for (const TestPlyElement& e : elements) {
      out << "element " << e.name << " " << e.declared_count.value_or(e.rows.size()) << "\n";
      for (const TestPlyProperty& p : e.properties) {
        out << "property ";
        if (!p.count_type.empty()) out << "list " << p.count_type << " ";
        out << p.type << " " << p.name << "\n";
      }
    }
    out << "end_header\n";
    std::string body;
    for (const TestPlyElement& e : elements)
      for (const std::vector<double>& row : e.rows) AppendRow(format, e, row, &body);
    return out.str() + body;
  }

 private:
  static void AppendRow(const std::string& format, const TestPlyElement& e,
                        const std::vector<double>& row, std::string* body) {
    size_t next = 0;
    for (const TestPlyProperty& p : e.properties) {
      if (!p.count_type.empty()) {
        size_t count = static_cast<size_t>(row[next]);
        AppendValue(format, p.count_type, row[next++], body);
        // Fewer items than the count: a damaged list, on purpose.
        for (size_t i = 0; i < count && next < row.size(); ++i)
          AppendValue(format, p.type, row[next++], body);
      } else {
        AppendValue(format, p.type, row[next++], body);
      }
    }
    if (format == "ascii") body->back() = '\n';
  }

  static void AppendValue(const std::string& format, const std::string& type, double value,
                          std::string* body) {
    if (format == "ascii") {
      std::ostringstream text;
      text.precision(17);
      text << value << " ";
      *body += text.str();
      return;
    }
    char bytes[8];
    size_t size = 0;
    auto store = [&](auto typed) {
      size = sizeof(typed);
      std::memcpy(bytes, &typed, size);
    };
    if (type == "char" || type == "int8") store(static_cast<int8_t>(value));
    else if (type == "uchar" || type == "uint8") store(static_cast<uint8_t>(value));
    else if (type == "short" || type == "int16") store(static_cast<int16_t>(value));
    else if (type == "ushort" || type == "uint16") store(static_cast<uint16_t>(value));
    else if (type == "int" || type == "int32") store(static_cast<int32_t>(value));
    else if (type == "uint" || type == "uint32") store(static_cast<uint32_t>(value));
    else if (type == "float" || type == "float32") store(static_cast<float>(value));
    else store(value);
    bool big = format == "binary_big_endian";
    if (big != (std::endian::native == std::endian::big))
      for (size_t i = 0; i < size / 2; ++i) std::swap(bytes[i], bytes[size - 1 - i]);
    body->append(bytes, size);
  }
};

}  // namespace raystack::import
