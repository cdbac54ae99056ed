#include "master/preview/preview_status.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <vector>
#include <nlohmann/json.hpp>

namespace raystack::master::preview {
namespace {

TEST(StatusJson, UnknownFiguresAreNullAndFinishedTilesLeaveTheList) {
  PreviewStatus s;
  s.frame = 1;
  s.frames = 2;
  s.last_frame = 1;  // (--frames: the page ends the job at the range's last frame)
  s.spp = 2;
  s.samples_total = 4 * 2 * 2;
  s.samples_done = 8;
  s.elapsed_seconds = 2;
  s.tiles = {{1, {{0, 0, 2, 2}, {2, 0, 4, 2}}, ""}, {2, {}, "lost: silent for 10 s"}};
  // A 4x2 image: the left tile has all its samples, the right one lacks one.
  const std::vector<uint32_t> counts = {2, 2, 2, 1, 2, 2, 0, 0};
  const nlohmann::json j = nlohmann::json::parse(StatusJson(s, 4, counts));
  EXPECT_EQ(j["type"], "status");
  EXPECT_EQ(j["frame"], 1);
  EXPECT_EQ(j["frames"], 2);
  EXPECT_EQ(j["last_frame"], 1);
  EXPECT_DOUBLE_EQ(j["progress"].get<double>(), 0.5);
  EXPECT_DOUBLE_EQ(j["samples_per_second"].get<double>(), 4.0);
  EXPECT_DOUBLE_EQ(j["seconds_left"].get<double>(), 2.0);  // 8 samples left at 4/s
  EXPECT_TRUE(j["rays_per_second"].is_null());
  EXPECT_TRUE(j["error_estimate"].is_null());
  EXPECT_EQ(j["finished"], false);
  ASSERT_EQ(j["tiles"].size(), 2u);
  EXPECT_EQ(j["tiles"][0]["rank"], 1);
  ASSERT_EQ(j["tiles"][0]["tiles"].size(), 1u);
  EXPECT_EQ(j["tiles"][0]["tiles"][0], nlohmann::json({2, 0, 4, 2}));
  EXPECT_TRUE(j["tiles"][1]["tiles"].empty());
  EXPECT_EQ(j["tiles"][0]["dropped"], "");
  EXPECT_EQ(j["tiles"][1]["dropped"], "lost: silent for 10 s");  // the legend says so

  s.error_estimate = 0.125;
  s.rays_per_second = 1e6;
  s.finished = true;
  const nlohmann::json done = nlohmann::json::parse(StatusJson(s, 4, counts));
  EXPECT_DOUBLE_EQ(done["error_estimate"].get<double>(), 0.125);
  EXPECT_DOUBLE_EQ(done["rays_per_second"].get<double>(), 1e6);
  EXPECT_DOUBLE_EQ(done["seconds_left"].get<double>(), 0.0);
  EXPECT_TRUE(done["tiles"][0]["tiles"].empty());  // nothing is in flight once done
}

// Ctrl-C (or a scheduler's SIGTERM) ended the job: no time left to show, nothing in flight.
TEST(StatusJson, AnInterruptedJobHasNoTimeLeftAndNoTilesInFlight) {
  PreviewStatus s;
  s.spp = 2;
  s.samples_total = 4 * 2 * 2;
  s.samples_done = 8;
  s.elapsed_seconds = 2;
  s.tiles = {{1, {{0, 0, 2, 2}, {2, 0, 4, 2}}, ""}};
  EXPECT_EQ(nlohmann::json::parse(StatusJson(s, 4, {}))["interrupted"], false);
  s.interrupted = true;
  s.note = "interrupted (SIGINT): the frame so far is in out.exr";
  const nlohmann::json j = nlohmann::json::parse(StatusJson(s, 4, {}));
  EXPECT_EQ(j["interrupted"], true);
  EXPECT_EQ(j["finished"], false);
  EXPECT_EQ(j["failed"], false);
  EXPECT_TRUE(j["seconds_left"].is_null());
  EXPECT_EQ(j["note"], "interrupted (SIGINT): the frame so far is in out.exr");
  EXPECT_TRUE(j["tiles"][0]["tiles"].empty());
}

// A progressive render hands out each tile once a pass: a tile is no longer in flight when its
// pixels have its pass's samples (not yet the frame's spp), and a coarse round's tile (a range
// of pixel ranks) only looks at its own pixels.
TEST(StatusJson, ATileIsDoneAtItsOwnPassEndOnItsOwnPixels) {
  PreviewStatus s;
  s.spp = 16;
  s.samples_total = 16 * 16 * 16;
  render::Tile first_pass{0, 0, 16, 16};
  first_pass.sample_end = 4;
  render::Tile second_pass = first_pass;
  second_pass.sample_begin = 4;
  second_pass.sample_end = 8;
  render::Tile coarse{0, 0, 16, 16};
  coarse.sample_end = 1;
  coarse.rank_begin = 0;
  coarse.rank_end = 1;  // one pixel in each 16x16 square
  s.tiles = {{0, {first_pass, second_pass, coarse}, ""}};
  std::vector<uint32_t> counts(16 * 16, 4);  // every pixel has its first pass
  nlohmann::json j = nlohmann::json::parse(StatusJson(s, 16, counts));
  ASSERT_EQ(j["tiles"][0]["tiles"].size(), 1u);  // the second pass's, still in flight
  EXPECT_EQ(j["tiles"][0]["tiles"][0], nlohmann::json({0, 0, 16, 16}));

  std::fill(counts.begin(), counts.end(), 0u);
  for (int y = 0; y < 16; ++y)
    for (int x = 0; x < 16; ++x)
      if (coarse.HasRank(x, y)) counts[static_cast<size_t>(y * 16 + x)] = 1;
  j = nlohmann::json::parse(StatusJson(s, 16, counts));
  EXPECT_EQ(j["tiles"][0]["tiles"].size(), 2u);  // the coarse tile is done with its one pixel
}

// A resumed run's restored samples count as done, not as rendered at the frame's rate.
TEST(StatusJson, RestoredSamplesAreDoneButNotInTheRate) {
  PreviewStatus s;
  s.samples_total = 100;
  s.samples_restored = 60;
  s.samples_done = 20;
  s.elapsed_seconds = 2;
  const nlohmann::json j = nlohmann::json::parse(StatusJson(s, 0, {}));
  EXPECT_DOUBLE_EQ(j["progress"].get<double>(), 0.8);
  EXPECT_DOUBLE_EQ(j["samples_per_second"].get<double>(), 10.0);
  EXPECT_DOUBLE_EQ(j["seconds_left"].get<double>(), 2.0);  // 20 left at 10/s
}

// The note (what ended the frame early) is one JSON string, valid UTF-8 whatever bytes the
// error held (a WebSocket text message must be UTF-8): quotes, backslashes and control
// characters escaped, every byte of an overlong form, a surrogate or a code point past U+10FFFF
// replaced, and real UTF-8 kept.
TEST(StatusJson, TheNoteIsValidJsonAndUtf8WhateverTheBytes) {
  PreviewStatus s;
  s.note = "stopped: a\xe0\x80\xaf" "b\xed\xa0\x80" "c\xf4\x90\x80\x80" "d\xf0\x9f\x98\x80" "e\"\\\x01\xc3";
  const nlohmann::json j = nlohmann::json::parse(StatusJson(s, 0, {}));  // throws on bad UTF-8
  EXPECT_EQ(j["note"], "stopped: a???b???c????d\xf0\x9f\x98\x80" "e\"\\\x01?");
  EXPECT_EQ(j["failed"], false);
  s.note.clear();
  EXPECT_EQ(nlohmann::json::parse(StatusJson(s, 0, {}))["note"], "");
}

TEST(StatusJson, NothingDoneYetHasNoTimeLeft) {
  PreviewStatus s;
  s.samples_total = 100;
  const nlohmann::json j = nlohmann::json::parse(StatusJson(s, 0, {}));
  EXPECT_TRUE(j["seconds_left"].is_null());
  EXPECT_TRUE(j["samples_per_second"].is_null());
  EXPECT_DOUBLE_EQ(j["progress"].get<double>(), 0.0);
}

}  // namespace
}  // namespace raystack::master::preview
