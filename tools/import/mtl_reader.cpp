#include "tools/import/mtl_reader.h"

#include <set>

#include "common/base/log.h"
#include "tools/import/text_scan.h"

namespace raystack::import {

uint32_t MaterialTable::Add(std::string_view name) {
  auto index = static_cast<uint32_t>(materials_.size());
  materials_.push_back(Material{});
  materials_.back().name = std::string(name);
  defined_.push_back(false);
  index_.emplace(std::string(name), index);
  return index;
}

uint32_t MaterialTable::Use(std::string_view name) {
  auto it = index_.find(std::string(name));
  return it != index_.end() ? it->second : Add(name);
}

Material* MaterialTable::Define(std::string_view name) {
  auto it = index_.find(std::string(name));
  uint32_t index = it != index_.end() ? it->second : Add(name);
  if (defined_[index]) return nullptr;
  defined_[index] = true;
  return &materials_[index];
}

std::string MaterialTable::DefinedAt(std::string_view name) const {
  auto it = index_.find(std::string(name));
  return it == index_.end() ? std::string() : materials_[it->second].defined_at;
}

std::vector<std::string> MaterialTable::UndefinedNames() const {
  std::vector<std::string> names;
  for (size_t i = 0; i < materials_.size(); ++i)
    if (!defined_[i]) names.push_back(materials_[i].name);
  return names;
}

namespace {

// Reads the remaining numbers of one MTL statement.
class MtlLine {
 public:
  MtlLine(BufferedInput& input, std::string_view rest) : input_(input), rest_(rest) {}

  Status Float(float* out) {
    std::string_view token = NextToken(&rest_);
    if (const char* why = ParseFloat(token, out))
      return input_.LineError(std::string(why) + " '" + std::string(token) + "'");
    return OkStatus();
  }
  // "r g b", or one value for all three (allowed by the MTL spec).
  Status Color(Vec3f* out) {
    RAYSTACK_RETURN_IF_ERROR(Float(&out->x));
    if (NextTokenIsEmpty()) {
      out->y = out->z = out->x;
      return OkStatus();
    }
    RAYSTACK_RETURN_IF_ERROR(Float(&out->y));
    // (Two numbers: a persona read "missing number ''".)
    if (NextTokenIsEmpty()) return input_.LineError("a colour takes 1 or 3 numbers, not 2");
    return Float(&out->z);
  }
  Status Int(int* out) {
    std::string_view token = NextToken(&rest_);
    int64_t value = 0;
    if (const char* why = ParseInt(token, &value))
      return input_.LineError(std::string(why) + " '" + std::string(token) + "'");
    if (value < 0 || value > 100) return input_.LineError("illum out of range");
    *out = static_cast<int>(value);
    return OkStatus();
  }
  std::string_view rest() const { return rest_; }
  // Reads past the next token when it is `token` ("d -halo 0.6": the halo form of d).
  void SkipIf(std::string_view token) {
    std::string_view copy = rest_;
    if (NextToken(&copy) == token) rest_ = copy;
  }

 private:
  bool NextTokenIsEmpty() const {
    std::string_view copy = rest_;
    return NextToken(&copy).empty();
  }

  BufferedInput& input_;
  std::string_view rest_;
};

// The statement a key names, whatever its case ("KD", "ILLUM" are written by some tools): its
// canonical spelling for the statements read, "" for those known and ignored (maps, Ka, Ns, the
// PBR extension, ...), and nullptr for keys of no MTL statement.
const char* CanonicalKey(std::string_view key) {
  std::string lower(key);
  for (char& c : lower) c = static_cast<char>(c >= 'A' && c <= 'Z' ? c - 'A' + 'a' : c);
  for (const char* read : {"newmtl", "Kd", "Ks", "Ke", "Ni", "d", "Tr", "illum"}) {
    std::string l(read);
    for (char& c : l) c = static_cast<char>(c >= 'A' && c <= 'Z' ? c - 'A' + 'a' : c);
    if (l == lower) return read;
  }
  if (lower.starts_with("map_")) return "";
  for (const char* ignored : {"ka", "ns", "tf", "sharpness", "bump", "disp", "decal", "refl",
                              "norm", "pr", "pm", "ps", "pc", "pcr", "aniso", "anisor", "km",
                              "tw", "ts", "kt"})
    if (lower == ignored) return "";
  return nullptr;
}

}  // namespace

Status ReadMtl(BufferedInput& input, MaterialTable* table) {
  Material scratch;  // receives statements outside any (or in a repeated) newmtl block
  Material* current = &scratch;
  std::set<std::string, std::less<>> warned;
  // Values as the file has them: the renderer brings them into range (render::MaterialFromMtl:
  // negative colours as 0, Ni outside [1, 4] for glass). What makes no sense (a negative
  // colour, an opacity outside [0, 1], a fourth colour number) is reported, naming the place;
  // models in the wild have them, and refusing the whole model would help nobody.
  auto out_of_range = [&](std::string_view key, const char* what) {
    if (!warned.insert(std::string(key) + what).second) return;  // once a file: models repeat them
    LOG_WARNING("import", "%s:%llu: %.*s: %s (the first such line)", input.path().c_str(),
                static_cast<unsigned long long>(input.line_number()), static_cast<int>(key.size()),
                key.data(), what);
  };
  std::string_view line;
  bool any_newmtl = false;
  while (input.NextLine(&line)) {
    if (input.line_number() == 1) line = WithoutByteOrderMark(line);
    std::string_view rest = StripComment(line);
    std::string_view key = NextToken(&rest);
    if (key.empty()) continue;
    const char* canonical = CanonicalKey(key);
    if (!canonical) {
      if (warned.insert("unknown " + std::string(key)).second)
        LOG_WARNING("import", "%s:%llu: %s is no MTL statement raystack knows; ignored (the "
                    "first such line)", input.path().c_str(),
                    static_cast<unsigned long long>(input.line_number()), Quoted(key).c_str());
      continue;
    }
    if (*canonical) key = canonical;
    MtlLine values(input, rest);
    if (key != "newmtl" && !any_newmtl && warned.insert("before newmtl").second)
      LOG_WARNING("import", "%s:%llu: %s before any newmtl belongs to no material; ignored",
                  input.path().c_str(), static_cast<unsigned long long>(input.line_number()),
                  Quoted(key).c_str());
    if (key == "newmtl") {
      any_newmtl = true;
      std::string_view name = Trim(rest);
      if (name.empty()) return input.LineError("newmtl without a name");
      current = table->Define(name);
      if (current)
        current->defined_at = input.path() + ":" + std::to_string(input.line_number());
      if (!current) {
        LOG_WARNING("import", "%s:%llu: material '%.*s' defined again; keeping the first (%s)",
                    input.path().c_str(), static_cast<unsigned long long>(input.line_number()),
                    static_cast<int>(name.size()), name.data(), table->DefinedAt(name).c_str());
        current = &scratch;
      }
    } else if ((key == "Kd" || key == "Ks" || key == "Ke") &&
               (Trim(rest).starts_with("spectral") || Trim(rest).starts_with("xyz"))) {
      if (warned.insert(std::string(key) + " spectral/xyz").second)
        LOG_WARNING("import", "%s:%llu: only rgb colours are supported; '%.*s' ignored",
                    input.path().c_str(), static_cast<unsigned long long>(input.line_number()),
                    static_cast<int>(key.size()), key.data());
    } else if (key == "Kd" || key == "Ks" || key == "Ke") {
      Vec3f* colour = key == "Kd" ? &current->kd : key == "Ks" ? &current->ks : &current->ke;
      RAYSTACK_RETURN_IF_ERROR(values.Color(colour));
      if (!Trim(values.rest()).empty()) out_of_range(key, "more than 3 numbers; the rest ignored");
      if (colour->x < 0 || colour->y < 0 || colour->z < 0)
        out_of_range(key, "a colour value below 0 (rendered as 0)");
      // As a scene file's albedo above 1 is warned of (a hostile-input review's Kd 1e30 passed
      // without a word, its pixels at 1e18). Ke is an emission: any value is one.
      if (key != "Ke" && (colour->x > 1 || colour->y > 1 || colour->z > 1))
        out_of_range(key, "a colour value above 1: the surface reflects more light than it receives");
    } else if (key == "Ni") {  // (below 1, as many exporters write for opaque materials: 1.5 for glass)
      RAYSTACK_RETURN_IF_ERROR(values.Float(&current->ni));
    } else if (key == "d" || key == "Tr") {  // opacity, or transparency (its complement)
      float v = 0;
      if (key == "d") values.SkipIf("-halo");
      RAYSTACK_RETURN_IF_ERROR(values.Float(&v));
      if (!(v >= 0.0f && v <= 1.0f)) out_of_range(key, "outside [0, 1]");
      current->d = key == "d" ? v : 1.0f - v;
    } else if (key == "illum") {
      RAYSTACK_RETURN_IF_ERROR(values.Int(&current->illum));
    }
  }
  return input.status();
}

}  // namespace raystack::import
