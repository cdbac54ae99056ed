// The render loop's side of the preview: a failed job says why on the page and keeps showing
// the image so far for the hold time, as a job that ends well does.

#include "master/preview/live_preview.h"

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

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
  preview->BeginFrame(&film, 0, 1, 4);
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

}  // namespace
}  // namespace raystack::master::preview
