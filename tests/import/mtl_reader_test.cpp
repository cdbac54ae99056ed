#include "tools/import/mtl_reader.h"

#include <gtest/gtest.h>

#include "tests/import/import_test_util.h"

namespace raystack::import {
namespace {

Status ReadMtlText(const ScratchFiles& files, const std::string& text, MaterialTable* table) {
  auto input = BufferedInput::Open(files.Write("lib.mtl", text), nullptr);
  if (!input.ok()) return input.status();
  return ReadMtl(*input, table);
}

TEST(MtlReader, ReadsTheKeysARayTracerUses) {
  ScratchFiles files;
  MaterialTable table;
  ASSERT_TRUE(ReadMtlText(files,
                          "# comment\n"
                          "newmtl lamp\n"
                          "  Kd 0.1 0.2 0.3\n  Ks 0.5\n\tKe 17 12 4 # warm\n"
                          "  Ni 1.5\n  d 0.25\n  illum 7\n  map_Kd wood.png\n  Ns 10\n"
                          "newmtl glass\r\n  Tr 0.75\r\n",
                          &table)
                  .ok());
  std::vector<Material> materials = table.Take();
  ASSERT_EQ(materials.size(), 2u);
  const Material& lamp = materials[0];
  EXPECT_EQ(lamp.name, "lamp");
  EXPECT_EQ(lamp.kd, (Vec3f{0.1f, 0.2f, 0.3f}));
  EXPECT_EQ(lamp.ks, (Vec3f{0.5f, 0.5f, 0.5f}));
  EXPECT_EQ(lamp.ke, (Vec3f{17, 12, 4}));
  EXPECT_EQ(lamp.ni, 1.5f);
  EXPECT_EQ(lamp.d, 0.25f);
  EXPECT_EQ(lamp.illum, 7);
  EXPECT_EQ(materials[1].name, "glass");
  EXPECT_EQ(materials[1].d, 0.25f);
  EXPECT_EQ(materials[1].kd, Material{}.kd);
}

TEST(MtlReader, UseBeforeDefinitionKeepsTheIndex) {
  ScratchFiles files;
  MaterialTable table;
  EXPECT_EQ(table.Use("late"), 0u);
  EXPECT_EQ(table.Use("never"), 1u);
  ASSERT_TRUE(ReadMtlText(files, "newmtl late\nKd 1 0 0\n", &table).ok());
  EXPECT_EQ(table.Use("late"), 0u);
  EXPECT_EQ(table.UndefinedNames(), std::vector<std::string>{"never"});
  std::vector<Material> materials = table.Take();
  EXPECT_EQ(materials[0].kd, (Vec3f{1, 0, 0}));
  EXPECT_EQ(materials[1].kd, Material{}.kd);
}

// Values are stored as the file has them (the renderer brings them into range, and an Ni
// below 1 means 1.5 for glass there), with warnings naming the line where they make no sense.
TEST(MtlReader, ValuesOutOfRangeAreStoredAsWritten) {
  ScratchFiles files;
  MaterialTable table;
  ASSERT_TRUE(ReadMtlText(files,
                          "newmtl a\nKd -0.5 0.2 0.3 0.9\nKe -1e38\nKs -2\nNi 0\nd 2\n"
                          "newmtl b\nNi 1000\nTr -1\n",
                          &table)
                  .ok());
  std::vector<Material> materials = table.Take();
  ASSERT_EQ(materials.size(), 2u);
  EXPECT_EQ(materials[0].kd, (Vec3f{-0.5f, 0.2f, 0.3f}));
  EXPECT_EQ(materials[0].ke, (Vec3f{-1e38f, -1e38f, -1e38f}));
  EXPECT_EQ(materials[0].ks, (Vec3f{-2, -2, -2}));
  EXPECT_EQ(materials[0].ni, 0.0f);
  EXPECT_EQ(materials[0].d, 2.0f);
  EXPECT_EQ(materials[1].ni, 1000.0f);
  EXPECT_EQ(materials[1].d, 2.0f);
}

// Found by a hostile-input review: Kd 1e30 passed without a word (pixels at 1e18). A colour
// above 1 reflects more than it receives: said, naming the place, and kept as written; an
// emission (Ke) may be any size.
TEST(MtlReader, AReflectanceAboveOneIsSaid) {
  ScratchFiles files;
  MaterialTable table;
  testing::internal::CaptureStderr();
  ASSERT_TRUE(ReadMtlText(files, "newmtl a\nKe 20 20 20\nKd 0.5 1e30 0.5\n", &table).ok());
  const std::string err = testing::internal::GetCapturedStderr();
  EXPECT_NE(err.find(":3: Kd: a colour value above 1: the surface reflects more light than it "
                     "receives"), std::string::npos) << err;
  EXPECT_EQ(err.find("Ke"), std::string::npos) << err;
  EXPECT_EQ(table.Take()[0].kd, (Vec3f{0.5f, 1e30f, 0.5f}));
}

// Found by a helper converting exporters' files: keys in another case ("KD", "ILLUM") were
// ignored without a word, and "d -halo 0.6" (the MTL spec's halo form) was a fatal error.
TEST(MtlReader, KeysInAnyCaseAndTheHaloFormOfDAreRead) {
  ScratchFiles files;
  MaterialTable table;
  ASSERT_TRUE(ReadMtlText(files,
                          "newmtl a\nKD 0.1 0.8 0.1\nILLUM 3\nkS 0.5\nd -halo 0.6\n"
                          "Pm 0.2\nmap_Kd wood.png\nfrobnicate 1\n",
                          &table)
                  .ok());
  std::vector<Material> materials = table.Take();
  ASSERT_EQ(materials.size(), 1u);
  EXPECT_EQ(materials[0].kd, (Vec3f{0.1f, 0.8f, 0.1f}));
  EXPECT_EQ(materials[0].ks, (Vec3f{0.5f, 0.5f, 0.5f}));
  EXPECT_EQ(materials[0].illum, 3);
  EXPECT_EQ(materials[0].d, 0.6f);
}

TEST(MtlReader, BadNumberNamesFileAndLine) {
  ScratchFiles files;
  MaterialTable table;
  ExpectErrorMentions(ReadMtlText(files, "newmtl a\nKd 1 nan 0\n", &table),
                      {"lib.mtl:2:", "nan"});
  ExpectErrorMentions(ReadMtlText(files, "newmtl a\n\nNi\n", &table), {"lib.mtl:3:"});
  // Two numbers for a colour (a persona read "missing number ''").
  ExpectErrorMentions(ReadMtlText(files, "newmtl a\nKd 0.5 0.5\n", &table),
                      {"lib.mtl:2:", "a colour takes 1 or 3 numbers, not 2"});
}

}  // namespace
}  // namespace raystack::import
