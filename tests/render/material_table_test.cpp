#include "common/render/material_table.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <limits>
#include <string>
#include <vector>

namespace raystack::render {
namespace {

// An MTL record with the converter's defaults (illum 2, d 1, Kd 0.8) and Ni 1 as given by an
// MTL (the converter stores 0 when the MTL has no Ni).
store::MaterialRecord Record(const std::string& name) {
  store::MaterialRecord r{};
  std::strncpy(r.name, name.c_str(), sizeof r.name - 1);
  for (int k = 0; k < 3; ++k) r.kd[k] = 0.8f;
  r.ni = 1;
  r.d = 1;
  r.illum = 2;
  return r;
}

void Set(float out[3], Vec3f v) {
  out[0] = v.x;
  out[1] = v.y;
  out[2] = v.z;
}

TEST(MaterialFromMtl, PlainRecordIsDiffuseWithKd) {
  store::MaterialRecord r = Record("wall");
  Set(r.kd, {0.1f, 0.2f, 0.3f});
  Set(r.ks, {0.5f, 0.5f, 0.5f});  // a highlight colour, not a mirror
  const Material m = MaterialFromMtl(r);
  EXPECT_EQ(m.type, MaterialType::kDiffuse);
  EXPECT_EQ(m.albedo, (Vec3f{0.1f, 0.2f, 0.3f}));
  EXPECT_FALSE(m.emissive());
  EXPECT_FALSE(m.specular());
}

TEST(MaterialFromMtl, Illum3And5AreMirrorsWithKs) {
  for (int illum : {3, 5}) {
    store::MaterialRecord r = Record("chrome");
    r.illum = illum;
    Set(r.ks, {0.9f, 0.8f, 0.7f});
    const Material m = MaterialFromMtl(r);
    EXPECT_EQ(m.type, MaterialType::kMirror) << illum;
    EXPECT_EQ(m.albedo, (Vec3f{0.9f, 0.8f, 0.7f}));
    EXPECT_TRUE(m.specular());
  }
}

TEST(MaterialFromMtl, GlassIllumsAndTransparency) {
  for (int illum : {4, 6, 7, 9}) {
    store::MaterialRecord r = Record("glass");
    r.illum = illum;
    r.ni = 1.33f;
    const Material m = MaterialFromMtl(r);
    EXPECT_EQ(m.type, MaterialType::kGlass) << illum;
    EXPECT_EQ(m.ior, 1.33f);
    EXPECT_EQ(m.albedo, (Vec3f{1, 1, 1}));  // Ks zero: clear
  }
  store::MaterialRecord r = Record("see-through");
  r.d = 0.5f;  // illum 2, but transparent
  r.ni = 0.5f;
  Set(r.ks, {0.2f, 0.9f, 0.2f});
  const Material m = MaterialFromMtl(r);
  EXPECT_EQ(m.type, MaterialType::kGlass);
  EXPECT_EQ(m.ior, 1.5f);                          // Ni < 1
  EXPECT_EQ(m.albedo, (Vec3f{0.2f, 0.9f, 0.2f}));  // tinted by Ks
  r.ni = 0.99f;
  EXPECT_EQ(MaterialFromMtl(r).ior, 1.5f);
  r.ni = 1.0f;
  EXPECT_EQ(MaterialFromMtl(r).ior, 1.0f);  // the rule is "< 1"
  r.ni = 7.0f;
  EXPECT_EQ(MaterialFromMtl(r).ior, kMaxIor);
}

TEST(MaterialFromMtl, MirrorRuleWinsOverTransparency) {
  store::MaterialRecord r = Record("odd");
  r.illum = 3;
  r.d = 0.5f;
  Set(r.ks, {0.5f, 0.5f, 0.5f});
  EXPECT_EQ(MaterialFromMtl(r).type, MaterialType::kMirror);
  Set(r.ks, {0, 0, 0});  // a black mirror: the transparency decides
  EXPECT_EQ(MaterialFromMtl(r).type, MaterialType::kGlass);
}

// Found by a helper converting exporters' files: CityEngine writes illum 3 with Ks 0 for its
// Lambert materials (a black mirror), Maya illum 4 with Ni 1 and no transparency for every
// Lambert (a glass of index 1, invisible). Both are diffuse with their Kd, and say why.
TEST(MaterialFromMtl, IllumsThatExportersWriteForLambertsAreDiffuse) {
  store::MaterialRecord city = Record("facade");
  city.illum = 3;
  Set(city.kd, {0.6f, 0.5f, 0.4f});
  std::string note;
  Material m = MaterialFromMtl(city, &note);
  EXPECT_EQ(m.type, MaterialType::kDiffuse);
  EXPECT_EQ(m.albedo, (Vec3f{0.6f, 0.5f, 0.4f}));
  EXPECT_NE(note.find("illum 3 asks for a mirror, but its Ks is 0"), std::string::npos) << note;

  store::MaterialRecord maya = Record("lambert2SG");
  maya.illum = 4;
  maya.ni = 1.0f;
  Set(maya.kd, {0.5f, 0.5f, 0.5f});
  m = MaterialFromMtl(maya, &note);
  EXPECT_EQ(m.type, MaterialType::kDiffuse);
  EXPECT_EQ(m.albedo, (Vec3f{0.5f, 0.5f, 0.5f}));
  EXPECT_NE(note.find("illum 4 asks for glass, but it is opaque"), std::string::npos) << note;
  maya.ni = 0;  // no Ni in the MTL: the glass its illum asks for, of index 1.5
  m = MaterialFromMtl(maya, &note);
  EXPECT_EQ(m.type, MaterialType::kGlass);
  EXPECT_EQ(m.ior, 1.5f);
  EXPECT_TRUE(note.empty()) << note;
  maya.ni = 1.0f;
  maya.d = 0.9f;  // transparent: glass whatever its index
  EXPECT_EQ(MaterialFromMtl(maya).type, MaterialType::kGlass);
  // Transparent without Ni (a one-face window): a clear sheet of index 1, as stores converted
  // before Ni's absence was told apart had it; 1.5 would bend all that is seen through it.
  maya.ni = 0;
  EXPECT_EQ(MaterialFromMtl(maya).type, MaterialType::kGlass);
  EXPECT_EQ(MaterialFromMtl(maya).ior, 1.0f);

  // A mirror whose Kd is stronger than its Ks stays a mirror (the MTL says so), and says so.
  store::MaterialRecord metal = Record("metal");
  metal.illum = 3;
  Set(metal.kd, {0.8f, 0.1f, 0.1f});
  Set(metal.ks, {0.5f, 0.5f, 0.5f});
  EXPECT_EQ(MaterialFromMtl(metal, &note).type, MaterialType::kMirror);
  EXPECT_NE(note.find("is stronger than its Ks but unused"), std::string::npos) << note;
  Set(metal.kd, {0.1f, 0.1f, 0.1f});
  MaterialFromMtl(metal, &note);
  EXPECT_TRUE(note.empty()) << note;
}

TEST(MaterialFromMtl, KeEmitsWhateverTheType) {
  store::MaterialRecord r = Record("lamp");
  Set(r.ke, {17, 12, 4});
  Material m = MaterialFromMtl(r);
  EXPECT_EQ(m.type, MaterialType::kDiffuse);
  EXPECT_EQ(m.emission, (Vec3f{17, 12, 4}));
  EXPECT_TRUE(m.emissive());
  r.illum = 7;
  r.ni = 1.5f;
  m = MaterialFromMtl(r);
  EXPECT_EQ(m.type, MaterialType::kGlass);
  EXPECT_TRUE(m.emissive());
  Set(r.ke, {0, 0, 0});
  EXPECT_FALSE(MaterialFromMtl(r).emissive());
}

TEST(MaterialFromMtl, BadNumbersNeverReachShading) {
  store::MaterialRecord r = Record("bad");
  const float nan = std::numeric_limits<float>::quiet_NaN();
  Set(r.kd, {nan, -1, std::numeric_limits<float>::infinity()});
  Set(r.ke, {nan, -3, 0});
  const Material m = MaterialFromMtl(r);
  EXPECT_EQ(m.albedo, (Vec3f{0, 0, 0}));
  EXPECT_EQ(m.emission, (Vec3f{0, 0, 0}));
  r.illum = 4;
  r.ni = nan;
  EXPECT_EQ(MaterialFromMtl(r).ior, 1.5f);
}

TEST(MaterialTable, StoreMaterialsOverridesAndDefault) {
  store::MaterialRecord chrome = Record("chrome");
  chrome.illum = 3;
  Set(chrome.ks, {1, 1, 1});
  const std::vector<store::MaterialRecord> records = {Record("wall"), chrome, Record("floor")};
  Scene scene;
  scene.default_material.albedo = {0.5f, 0.5f, 0.5f};
  Material red;
  red.albedo = {0.9f, 0.1f, 0.1f};
  scene.overrides["floor"] = red;

  const MaterialTable table = MaterialTable::Build(records, scene);
  EXPECT_EQ(table.size(), 4u);  // three store materials and the default
  EXPECT_EQ(table.Get(0).type, MaterialType::kDiffuse);
  EXPECT_EQ(table.Get(0).albedo, (Vec3f{0.8f, 0.8f, 0.8f}));
  EXPECT_EQ(table.Get(1).type, MaterialType::kMirror);
  EXPECT_EQ(table.Get(2).albedo, red.albedo);
  EXPECT_EQ(table.Get(store::kNoMaterial).albedo, (Vec3f{0.5f, 0.5f, 0.5f}));
  EXPECT_EQ(table.Get(3).albedo, (Vec3f{0.5f, 0.5f, 0.5f}));
  EXPECT_EQ(table.Get(store::kNoMaterial16).albedo, (Vec3f{0.5f, 0.5f, 0.5f}));
  EXPECT_TRUE(table.any_specular());
  EXPECT_FALSE(table.any_emissive());
}

TEST(MaterialTable, FlagsCoverTheDefaultAndOverrides) {
  Scene scene;
  EXPECT_FALSE(MaterialTable::Build({}, scene).any_specular());
  EXPECT_EQ(MaterialTable::Build({}, scene).size(), 1u);
  scene.default_material.emission = {1, 1, 1};
  EXPECT_TRUE(MaterialTable::Build({}, scene).any_emissive());

  const std::vector<store::MaterialRecord> records = {Record("box")};
  Scene glass_scene;
  glass_scene.overrides["box"].type = MaterialType::kGlass;
  const MaterialTable table = MaterialTable::Build(records, glass_scene);
  EXPECT_TRUE(table.any_specular());
  EXPECT_EQ(table.Get(0).type, MaterialType::kGlass);
}

TEST(MaterialTable, OverrideOfAMissingMaterialIsAWarning) {
  const std::vector<store::MaterialRecord> records = {Record("wall")};
  Scene scene;
  scene.source = "scene.json";
  scene.overrides["wal"].type = MaterialType::kMirror;  // a typo
  testing::internal::CaptureStderr();
  const MaterialTable table = MaterialTable::Build(records, scene);
  const std::string log = testing::internal::GetCapturedStderr();
  EXPECT_EQ(table.Get(0).type, MaterialType::kDiffuse);
  EXPECT_FALSE(table.any_specular());
  EXPECT_NE(log.find("scene.json: materials.wal"), std::string::npos) << log;
  EXPECT_NE(log.find("no material of that name"), std::string::npos) << log;
}

// Found by a scene author: a typo's warning did not say what the name might have been, and a
// "default" beside a store whose faces all carry MTL materials changed nothing without a word.
TEST(MaterialTable, WarningsNameWhatWasMeant) {
  const std::vector<store::MaterialRecord> records = {Record("shortBox"), Record("tallBox"),
                                                      Record("light")};
  const auto warnings = [&](const Scene& scene) {
    testing::internal::CaptureStderr();
    (void)MaterialTable::Build(records, scene);
    return testing::internal::GetCapturedStderr();
  };
  Scene typo;
  typo.source = "scene.json";
  typo.overrides["shortbox"].type = MaterialType::kMirror;  // case
  typo.overrides["talBox"].type = MaterialType::kMirror;    // one letter
  typo.overrides["lamp"].type = MaterialType::kMirror;      // nothing near: the names listed
  std::string log = warnings(typo);
  EXPECT_NE(log.find("materials.shortbox: the store has no material of that name; the override is "
                     "unused (did you mean \"shortBox\"?)"), std::string::npos) << log;
  EXPECT_NE(log.find("materials.talBox: the store has no material of that name; the override is "
                     "unused (did you mean \"tallBox\"?)"), std::string::npos) << log;
  EXPECT_NE(log.find("materials.lamp: the store has no material of that name; the override is "
                     "unused (it has shortBox, tallBox, light)"), std::string::npos) << log;
  Scene with_default;
  with_default.source = "scene.json";
  with_default.default_given = true;
  log = warnings(with_default);
  EXPECT_NE(log.find("materials.default applies only to triangles without a material"),
            std::string::npos) << log;
  EXPECT_NE(log.find("(it has shortBox, tallBox, light)"), std::string::npos) << log;
  // Without MTL materials the default is every triangle's: nothing to say.
  testing::internal::CaptureStderr();
  (void)MaterialTable::Build({}, with_default);
  EXPECT_EQ(testing::internal::GetCapturedStderr(), "");
}

TEST(MaterialTable, LongNamesMatchTheStoresTruncation) {
  const std::string long_name(80, 'm');
  const std::vector<store::MaterialRecord> records = {Record(long_name)};  // kept to 63 bytes
  Scene scene;
  scene.overrides[long_name].type = MaterialType::kMirror;
  testing::internal::CaptureStderr();
  const MaterialTable table = MaterialTable::Build(records, scene);
  EXPECT_EQ(testing::internal::GetCapturedStderr(), "");
  EXPECT_EQ(table.Get(0).type, MaterialType::kMirror);
}

// Found by a real-model user test, 2026-11-26: two MTL names equal in their first 63 bytes are
// one name in the store, and an override of one silently changed both.
TEST(MaterialTable, AnOverrideMatchingSeveralStoreMaterialsIsAWarning) {
  const std::string red = std::string(63, 'a') + "XRED", green = std::string(63, 'a') + "YGREEN";
  const std::vector<store::MaterialRecord> records = {Record(red), Record(green), Record("x")};
  Scene scene;
  scene.source = "scene.json";
  scene.overrides[red].type = MaterialType::kMirror;
  scene.overrides["x"].type = MaterialType::kMirror;
  testing::internal::CaptureStderr();
  const MaterialTable table = MaterialTable::Build(records, scene);
  const std::string log = testing::internal::GetCapturedStderr();
  EXPECT_EQ(table.Get(1).type, MaterialType::kMirror);  // the store cannot tell them apart
  EXPECT_NE(log.find("scene.json: materials." + red + " matches 2 materials of the store"),
            std::string::npos) << log;
  EXPECT_EQ(log.find("materials.x "), std::string::npos) << log;
}

}  // namespace
}  // namespace raystack::render
