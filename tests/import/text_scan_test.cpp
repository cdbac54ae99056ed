#include "tools/import/text_scan.h"

#include <gtest/gtest.h>

namespace raystack::import {
namespace {

TEST(TextScan, ParsesFloats) {
  float value = 0;
  EXPECT_EQ(ParseFloat("1.5", &value), nullptr);
  EXPECT_EQ(value, 1.5f);
  EXPECT_EQ(ParseFloat("+2", &value), nullptr);
  EXPECT_EQ(value, 2.0f);
  EXPECT_EQ(ParseFloat("-3e2", &value), nullptr);
  EXPECT_EQ(value, -300.0f);
  EXPECT_EQ(ParseFloat("0.000000", &value), nullptr);
  EXPECT_EQ(value, 0.0f);
}

TEST(TextScan, TinyFloatsRoundTowardZero) {
  float value = 1;
  EXPECT_EQ(ParseFloat("1e-60", &value), nullptr);
  EXPECT_EQ(value, 0.0f);
}

TEST(TextScan, RejectsNonFiniteAndMalformedFloats) {
  float value = 7;
  for (const char* bad : {"nan", "NaN", "inf", "-inf", "infinity", "1e39", "-1e39", "1e400",
                          "abc", "1.5x", "", "+", "+-1", "0x10", "1,5"})
    EXPECT_NE(ParseFloat(bad, &value), nullptr) << bad;
  EXPECT_EQ(value, 7.0f);
}

// A token as an error message shows it (a hostile-input review: a NUL cut the message, a 1 MB
// number was echoed whole; digits beyond float range then a letter were "out of range").
TEST(TextScan, TokensAreQuotedShortAndPrintable) {
  EXPECT_EQ(Quoted("1.5x"), "'1.5x'");
  EXPECT_EQ(Quoted(std::string_view("0\0" "2", 3)), "'0\\x002'");
  EXPECT_EQ(Quoted(std::string(1000, '7')), "'" + std::string(48, '7') + "'... (1000 bytes)");
  float f = 0;
  EXPECT_STREQ(ParseFloat("1" + std::string(100, '9') + "x", &f), "not a number");
  EXPECT_STREQ(ParseFloat("1e60", &f), "number out of float range");
}

TEST(TextScan, ParsesIntegers) {
  int64_t value = 0;
  EXPECT_EQ(ParseInt("12", &value), nullptr);
  EXPECT_EQ(value, 12);
  EXPECT_EQ(ParseInt("-3", &value), nullptr);
  EXPECT_EQ(value, -3);
  EXPECT_EQ(ParseInt("+4", &value), nullptr);
  EXPECT_EQ(value, 4);
  for (const char* bad : {"1.0", "99999999999999999999", "x", "", "+-2", "3a"})
    EXPECT_NE(ParseInt(bad, &value), nullptr) << bad;
}

TEST(TextScan, SplitsTokensOnBlanks) {
  std::string_view rest = " \tv  1\t2 \r";
  EXPECT_EQ(NextToken(&rest), "v");
  EXPECT_EQ(NextToken(&rest), "1");
  EXPECT_EQ(NextToken(&rest), "2");
  EXPECT_EQ(NextToken(&rest), "");
  EXPECT_EQ(Trim("  a b \t"), "a b");
  EXPECT_EQ(StripComment("Kd 1 2 3 # red"), "Kd 1 2 3 ");
}

}  // namespace
}  // namespace raystack::import
