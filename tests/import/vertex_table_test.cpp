#include "tools/import/vertex_table.h"

#include <gtest/gtest.h>

#include <random>

namespace raystack::import {
namespace {

// Distinct, reproducible values for record `i`.
void Fill(uint64_t i, int floats, float* out) {
  for (int k = 0; k < floats; ++k) out[k] = static_cast<float>(i) * 0.5f + static_cast<float>(k);
}

void ExpectRecord(VertexTable& table, uint64_t i) {
  float expected[VertexTable::kMaxFloatsPerVertex];
  float actual[VertexTable::kMaxFloatsPerVertex];
  Fill(i, table.floats_per_vertex(), expected);
  ASSERT_TRUE(table.Get(i, actual).ok());
  for (int k = 0; k < table.floats_per_vertex(); ++k) ASSERT_EQ(actual[k], expected[k]) << i;
}

void AppendRecords(VertexTable& table, uint64_t count) {
  float values[VertexTable::kMaxFloatsPerVertex];
  for (uint64_t i = 0; i < count; ++i) {
    Fill(i, table.floats_per_vertex(), values);
    ASSERT_TRUE(table.Append(values).ok());
  }
}

TEST(VertexTable, StaysInMemoryWithinBudget) {
  MemoryBudget budget(64 << 20);
  VertexTable table(3, &budget, "");
  AppendRecords(table, 100'000);
  EXPECT_FALSE(table.spilled());
  EXPECT_EQ(table.size(), 100'000u);
  for (uint64_t i = 0; i < table.size(); i += 7) ExpectRecord(table, i);
}

TEST(VertexTable, SpillsWithATinyBudgetAndReturnsIdenticalValues) {
  MemoryBudget budget(4096);
  VertexTable table(3, &budget, "");
  AppendRecords(table, 100'000);
  EXPECT_TRUE(table.spilled());
  EXPECT_LE(budget.used(), 4096u);
  for (uint64_t i = 0; i < table.size(); ++i) ExpectRecord(table, i);
  // Random order defeats the page cache: every miss goes back to the file.
  std::mt19937_64 random(7);
  for (int n = 0; n < 20'000; ++n) ExpectRecord(table, random() % table.size());
}

TEST(VertexTable, SpillsMidwayAndGivesItsPagesBackToTheSharedBudget) {
  MemoryBudget budget(3 * VertexTable::kPageBytes);
  VertexTable first(8, &budget, "");
  VertexTable second(3, &budget, "");
  AppendRecords(first, 10'000);   // 5 pages of 8-float records: spills after 3
  EXPECT_TRUE(first.spilled());
  EXPECT_EQ(budget.used(), 0u);
  AppendRecords(second, 10'000);  // 2 pages: fits in what `first` released
  EXPECT_FALSE(second.spilled());
  EXPECT_EQ(budget.used(), 2 * VertexTable::kPageBytes);
  for (uint64_t i = 0; i < 10'000; ++i) {
    ExpectRecord(first, i);
    ExpectRecord(second, i);
  }
}

TEST(VertexTable, ReadsRecordsWhileStillAppending) {
  MemoryBudget budget(0);
  VertexTable table(2, &budget, "");
  float values[2];
  for (uint64_t i = 0; i < 50'000; ++i) {
    Fill(i, 2, values);
    ASSERT_TRUE(table.Append(values).ok());
    ExpectRecord(table, i);      // from the unwritten tail page
    ExpectRecord(table, i / 2);  // from the file
  }
}

TEST(VertexTable, ReportsAnUnusableTempFolder) {
  MemoryBudget budget(0);
  VertexTable table(3, &budget, "/nonexistent/raystack");
  float values[3] = {1, 2, 3};
  Status status = table.Append(values);
  ASSERT_FALSE(status.ok());
  EXPECT_NE(status.message().find("/nonexistent/raystack"), std::string::npos) << status.message();
}

}  // namespace
}  // namespace raystack::import
