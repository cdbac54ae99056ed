// The render loop's side of the preview: a failed job says why on the page and keeps showing
// the image so far for the hold time, as a job that ends well does; an interrupted job, and
// one with no hold, close only once the viewers have the last status and image.

#include "master/preview/live_preview.h"

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <cstring>
#include <string>
#include <thread>
#include <vector>

#include "tests/preview/http_client.h"

namespace raystack::master::preview {
namespace {

TEST(LivePreview, AFailedJobSaysWhyForTheHoldTime) {
  LivePreviewOptions options;
  options.enabled = true;
  options.hold_seconds = 1;
  Expected<LivePreview> preview = LivePreview::Start(options);
  ASSERT_TRUE(preview.ok()) << preview.status().message();
  render::Film film(4, 2);
  preview->BeginFrame(&film, 0, 1, 4, 0);
  testing::WsViewer viewer;
  ASSERT_TRUE(viewer.Open(preview->server()->port()));
  std::thread fail([&] {
    preview->Fail(Status::Error("blocks.bin: block 3 at offset 96: read failed \"x\"\xff"));
  });
  std::string message;
  bool binary = false, told = false;
  while (!told && viewer.Read(&message, &binary)) {
    if (binary) continue;
    const nlohmann::json j = nlohmann::json::parse(message);  // valid JSON, and UTF-8
    if (!j["failed"].get<bool>()) continue;
    EXPECT_EQ(j["note"], "failed: blocks.bin: block 3 at offset 96: read failed \"x\"?");
    EXPECT_TRUE(j["seconds_left"].is_null());
    EXPECT_EQ(j["finished"], false);
    told = true;
  }
  EXPECT_TRUE(told) << "the page was never told the job failed";
  fail.join();  // after the hold
}

// What a viewer reads until the server closes the stream.
struct Received {
  std::vector<nlohmann::json> statuses;
  int frames = 0;
  uint64_t last_frame_samples = 0;  // the last frame's header: samples merged
};
Received ReadUntilClosed(testing::WsViewer* viewer) {
  Received r;
  std::string message;
  bool binary = false;
  while (viewer->Read(&message, &binary)) {
    if (binary) {
      ++r.frames;
      if (message.size() >= 32) std::memcpy(&r.last_frame_samples, message.data() + 24, 8);
    } else {
      r.statuses.push_back(nlohmann::json::parse(message));
    }
  }
  return r;
}

// A film large enough that writing one frame to a viewer takes several turns of the server's
// loop: closed at once, the stream would end before the last frame was out.
void FillFilm(render::Film* film) {
  std::vector<render::SampleResult> batch;
  for (uint32_t y = 0; y < static_cast<uint32_t>(film->height()); ++y)
    for (uint32_t x = 0; x < static_cast<uint32_t>(film->width()); ++x) {
      render::SampleResult r{};
      r.pixel = y * static_cast<uint32_t>(film->width()) + x;
      r.rgb[0] = r.rgb[1] = r.rgb[2] = static_cast<float>((x * 7 + y * 13) % 97) / 97.0f;
      batch.push_back(r);
    }
  film->Merge(batch);
}

TEST(LivePreview, AnInterruptedJobSaysSoWithTheImageSoFarBeforeItCloses) {
  LivePreviewOptions options;
  options.enabled = true;
  options.hold_seconds = 600;  // not for an interrupted job: it ends within a second
  Expected<LivePreview> preview = LivePreview::Start(options);
  ASSERT_TRUE(preview.ok()) << preview.status().message();
  render::Film film(1024, 768);
  preview->BeginFrame(&film, 0, 1, 4, 0);
  testing::WsViewer viewer;
  ASSERT_TRUE(viewer.Open(preview->server()->port()));
  FillFilm(&film);
  std::thread interrupt([&] {
    preview->Interrupted("interrupted (SIGINT): the frame so far is in out.exr");
  });
  const Received r = ReadUntilClosed(&viewer);
  interrupt.join();
  ASSERT_FALSE(r.statuses.empty());
  const nlohmann::json& last = r.statuses.back();
  EXPECT_EQ(last["interrupted"], true);
  EXPECT_EQ(last["finished"], false);
  EXPECT_EQ(last["note"], "interrupted (SIGINT): the frame so far is in out.exr");
  EXPECT_EQ(last["samples_done"], 1024 * 768);
  EXPECT_GE(r.frames, 1) << "the image so far never reached the viewer";
}

TEST(LivePreview, WithNoHoldTheViewersStillGetTheFinalImage) {
  LivePreviewOptions options;
  options.enabled = true;  // hold_seconds 0
  Expected<LivePreview> preview = LivePreview::Start(options);
  ASSERT_TRUE(preview.ok()) << preview.status().message();
  render::Film film(1024, 768);
  preview->BeginFrame(&film, 0, 1, 1, 0);
  testing::WsViewer viewer;
  ASSERT_TRUE(viewer.Open(preview->server()->port()));
  std::thread render([&] {
    FillFilm(&film);
    preview->EndFrame(1e6);
    preview->Finish();
  });
  const Received r = ReadUntilClosed(&viewer);
  render.join();
  ASSERT_FALSE(r.statuses.empty());
  EXPECT_EQ(r.statuses.back()["finished"], true);
  EXPECT_EQ(r.statuses.back()["samples_done"], 1024 * 768);
  // The final image (DetachFilm's copy, sent before or after the final status) arrived.
  EXPECT_GE(r.frames, 1);
  EXPECT_EQ(r.last_frame_samples, 1024u * 768u) << "the stream closed before the final image was sent";
}

}  // namespace
}  // namespace raystack::master::preview
