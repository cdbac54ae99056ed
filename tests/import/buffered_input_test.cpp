#include "tools/import/buffered_input.h"

#include <gtest/gtest.h>

#include "tests/import/import_test_util.h"

namespace raystack::import {
namespace {

std::vector<std::string> AllLines(BufferedInput& input) {
  std::vector<std::string> lines;
  std::string_view line;
  while (input.NextLine(&line)) lines.emplace_back(line);
  return lines;
}

TEST(BufferedInput, SplitsLfAndCrlfLinesAndKeepsTheLastUnterminatedOne) {
  ScratchFiles files;
  auto input = BufferedInput::Open(files.Write("a.txt", "one\r\ntwo\n\nfour"), nullptr);
  ASSERT_TRUE(input.ok());
  EXPECT_EQ(AllLines(*input), (std::vector<std::string>{"one", "two", "", "four"}));
  EXPECT_TRUE(input->status().ok());
  EXPECT_EQ(input->line_number(), 4u);
}

TEST(BufferedInput, LinesCrossingBufferRefillsAreWhole) {
  ScratchFiles files;
  std::string text;
  std::vector<std::string> expected;
  for (int i = 0; i < 200; ++i) {
    expected.push_back(std::string(static_cast<size_t>(i % 13), 'x') + std::to_string(i));
    text += expected.back() + "\n";
  }
  auto input = BufferedInput::Open(files.Write("a.txt", text), nullptr, 16);
  ASSERT_TRUE(input.ok());
  EXPECT_EQ(AllLines(*input), expected);
  EXPECT_TRUE(input->status().ok());
}

TEST(BufferedInput, LineLongerThanTheBufferIsAnErrorWithItsLine) {
  ScratchFiles files;
  auto input = BufferedInput::Open(
      files.Write("long.txt", "short\n" + std::string(100, 'a') + "\n"), nullptr, 32);
  ASSERT_TRUE(input.ok());
  AllLines(*input);
  ExpectErrorMentions(input->status(), {"long.txt:2:", "longer than 32 bytes"});
}

TEST(BufferedInput, MixesLinesAndBytesAndReportsOffsets) {
  ScratchFiles files;
  auto input = BufferedInput::Open(files.Write("b.bin", "head\nABCDEF"), nullptr, 8);
  ASSERT_TRUE(input.ok());
  EXPECT_EQ(input->Peek(4), "head");
  std::string_view line;
  ASSERT_TRUE(input->NextLine(&line));
  EXPECT_EQ(line, "head");
  EXPECT_EQ(input->offset(), 5u);
  char bytes[4];
  ASSERT_TRUE(input->ReadBytes(bytes, 4).ok());
  EXPECT_EQ(std::string(bytes, 4), "ABCD");
  ExpectErrorMentions(input->ReadBytes(bytes, 4), {"b.bin: byte 9:", "unexpected end of file"});
}

TEST(BufferedInput, MissingFileIsAnErrorNamingIt) {
  auto input = BufferedInput::Open("/nonexistent/raystack/model.obj", nullptr);
  ExpectErrorMentions(input.status(), {"/nonexistent/raystack/model.obj"});
}

}  // namespace
}  // namespace raystack::import
