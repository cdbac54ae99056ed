// `raystack render --preview` as a user runs it, watched by a real headless Chromium: the
// canvas equals the film at the end (one process and under mpirun), a viewer that connects
// mid-render gets the current image, an exposed preview needs its token, and a viewer that
// never reads does not hold the render up.

#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <memory>
#include <vector>

#include "common/image/exr_io.h"
#include "common/image/srgb8.h"
#include "master/preview/preview_server.h"
#include "tests/preview/background_process.h"
#include "tests/preview/headless_chromium.h"
#include "tests/preview/http_client.h"
#include "tests/support/store_dir_fixture.h"

namespace raystack::master::preview {
namespace {

using prep::testing::ProcessResult;
using prep::testing::RunProcess;
using prep::testing::Slurp;
using testing::BackgroundProcess;
using testing::DecodeBase64;
using testing::HeadlessChromium;
using testing::WsViewer;

constexpr auto kPatience = std::chrono::seconds(300);  // against hangs only, never a measurement

#define SKIP_WITHOUT_CHROMIUM()                                                                  \
  if (!HeadlessChromium::Installed())                                                             \
  GTEST_SKIP() << HeadlessChromium::kBinary << " is missing (Debian package chromium; CI installs it)"

class PreviewCli : public raystack::testing::StoreDirFixture {
 protected:
  void SetUp() override { MakeStore("spheres:20000"); }

  std::string Scene(int width, int height, int spp) {
    const std::string path = dir_->File("scene.json");
    std::ofstream(path) << R"({ "store": "store",
      "camera": { "position": [0, 2, 6], "look_at": [0, 0, 0], "fov_y_deg": 45, "width": )"
                        << width << R"(, "height": )" << height << R"( },
      "lights": [ { "type": "point", "position": [4, 9, 6], "intensity": [160, 150, 140] } ],
      "materials": { "default": { "type": "diffuse", "albedo": [0.75, 0.72, 0.68] } },
      "background": [0.05, 0.06, 0.09],
      "integrator": { "type": "path", "max_depth": 3, "spp": )" << spp << R"(, "seed": 3 },
      "output": "out.exr" })";
    return path;
  }

  // `raystack render` (under `mpirun -np np` when np > 0) with the given extra options.
  std::vector<std::string> Command(int np, const std::string& scene, std::vector<std::string> extra) {
    std::vector<std::string> argv;
    if (np > 0) argv = {RAYSTACK_MPIRUN, "--allow-run-as-root", "--oversubscribe", "-np", std::to_string(np)};
    for (const std::string& a : {raystack::testing::kRaystackBinary, std::string("render"), scene,
                                 std::string("--cache-mb"), std::string("1"), std::string("-q")})
      argv.push_back(a);
    argv.insert(argv.end(), extra.begin(), extra.end());
    return argv;
  }

  std::string Profile(const std::string& name = "chromium-profile") {
    const std::string path = dir_->File(name);
    std::filesystem::create_directories(path);
    return path;
  }
};

uint16_t PortOf(const std::string& url) {
  const size_t colon = url.rfind(':');
  return static_cast<uint16_t>(std::stoi(url.substr(colon + 1)));
}

// The canvas the page shows, as RGBA8.
std::vector<uint8_t> Canvas(HeadlessChromium* browser, std::string* error) {
  const nlohmann::json v = browser->Evaluate("preview.pixels()", error);
  return v.is_string() ? DecodeBase64(v.get<std::string>()) : std::vector<uint8_t>();
}

// Largest difference, in 8-bit codes, between the canvas and the EXR tone-mapped as the PNG is.
int MaxDifference(const std::vector<uint8_t>& canvas, const image::ImageLayers& exr, float exposure) {
  int worst = 0;
  const float scale = std::exp2(exposure);
  for (size_t i = 0; i < exr.pixel_count(); ++i) {
    for (size_t c = 0; c < 3; ++c)
      worst = std::max(worst, std::abs(int{canvas[4 * i + c]} - int{image::LinearToSrgb8(exr.rgba[4 * i + c] * scale)}));
    worst = std::max(worst, 255 - int{canvas[4 * i + 3]});  // every pixel opaque at the end
  }
  return worst;
}

class PreviewCliRanks : public PreviewCli, public ::testing::WithParamInterface<int> {};

// After the render, the canvas equals the film, tone-mapped at the job's --exposure, within
// 1 of 255 per channel (it is the PNG's own tone map, so in fact exactly).
TEST_P(PreviewCliRanks, TheCanvasMatchesTheFilmAfterTheRender) {
  SKIP_WITHOUT_CHROMIUM();
  const int np = GetParam();
  constexpr int kWidth = 96, kHeight = 64;
  BackgroundProcess render(Command(np, Scene(kWidth, kHeight, 4),
                                   {"--threads", "2", "--exposure", "1", "--preview", "any",
                                    "--preview-hold", "600"}),
                           dir_->path());
  ASSERT_TRUE(render.WaitForOutput("preview: http", kPatience)) << render.out() << render.err();
  const std::string url = render.LineAfter("preview: ");
  HeadlessChromium browser;
  std::string error;
  ASSERT_TRUE(browser.Start(Profile(), &error)) << error;
  ASSERT_TRUE(browser.Open(url, &error)) << error;
  ASSERT_TRUE(browser.WaitFor("window.preview !== undefined && preview.status !== null && "
                              "preview.status.finished && preview.frame !== null && "
                              "preview.frame.samples === preview.status.samples_total",
                              kPatience, &error)) << error;
  ASSERT_TRUE(render.WaitForOutput("showing the last image", kPatience)) << render.out() << render.err();
  EXPECT_EQ(browser.Evaluate("preview.frame.exposure", &error), 1.0);
  EXPECT_EQ(browser.Evaluate("document.getElementById('rays').textContent === '—'", &error), false)
      << "rays/s is known once the frame is done";
  const std::vector<uint8_t> canvas = Canvas(&browser, &error);
  ASSERT_EQ(canvas.size(), 4u * kWidth * kHeight) << error;
  Expected<image::ImageLayers> exr = image::ReadExr(dir_->File("out.exr"));
  ASSERT_TRUE(exr.ok()) << exr.status().message();
  EXPECT_LE(MaxDifference(canvas, *exr, 1.0f), 1);
  // Ends the hold: the master's SIGTERM handler. Under mpirun it goes to rank 0 alone, which
  // then ends the job as after any hold. Sent to mpirun, it is forwarded to every rank: the
  // slaves, which have no handler, die of it, and mpirun (Open MPI 4.1) was seen hanging in
  // its abort path with all three ranks exited, until ctest's timeout.
  if (np == 0) {
    render.Signal(SIGTERM);
  } else {
    ASSERT_TRUE(render.SignalRank(0, SIGTERM));
  }
  EXPECT_EQ(render.Wait(), 0) << render.err();
}

// Ctrl-C mid-render: the page says the job was interrupted and where the frame so far is (as
// the terminal does), keeps the image so far, and says so when the stream closes; it did not
// change at all before (the last progress stayed up, as if the render had stalled).
TEST_P(PreviewCliRanks, CtrlCSaysOnThePageWhereTheFrameSoFarIs) {
  SKIP_WITHOUT_CHROMIUM();
  const int np = GetParam();
  // Slow on purpose (one thread, many samples): interrupted long before its end.
  BackgroundProcess render(Command(np, Scene(160, 120, 512), {"--threads", "1", "--preview", "any",
                                                              "--preview-hold", "600", "--no-png"}),
                           dir_->path());
  ASSERT_TRUE(render.WaitForOutput("preview: http", kPatience)) << render.out() << render.err();
  HeadlessChromium browser;
  std::string error;
  ASSERT_TRUE(browser.Start(Profile(), &error)) << error;
  ASSERT_TRUE(browser.Open(render.LineAfter("preview: "), &error)) << error;
  ASSERT_TRUE(browser.WaitFor("window.preview !== undefined && preview.frames > 0 && "
                              "preview.status !== null && preview.status.samples_done > 0",
                              kPatience, &error)) << error;
  if (np == 0) {
    render.Signal(SIGINT);
  } else {
    ASSERT_TRUE(render.SignalRank(0, SIGINT));  // see TheCanvasMatchesTheFilmAfterTheRender
  }
  ASSERT_TRUE(browser.WaitFor("preview.status.interrupted === true", kPatience, &error))
      << error << "\n" << render.err();
  EXPECT_EQ(browser.Evaluate("document.getElementById('frame').textContent", &error), "0 (interrupted)");
  const nlohmann::json note = browser.Evaluate("document.getElementById('note').textContent", &error);
  ASSERT_TRUE(note.is_string()) << error;
  // Either where the frame so far is, or (no pixel has all its samples yet, as is likely with
  // these passes) that nothing is kept: the terminal's words either way.
  EXPECT_NE(note.get<std::string>().find("interrupted (SIGINT)"), std::string::npos) << note;
  EXPECT_NE(note.get<std::string>().find("--resume"), std::string::npos) << note;
  EXPECT_EQ(browser.Evaluate("document.getElementById('left').textContent", &error), "—");
  EXPECT_TRUE(browser.WaitFor("document.getElementById('connection').textContent.includes("
                              "'the job was interrupted')", kPatience, &error)) << error;
  const int code = render.Wait();
  if (np == 0) {
    EXPECT_EQ(code, 128 + SIGINT) << render.err();
  }
  EXPECT_NE(render.err().find("raystack render: " + note.get<std::string>()), std::string::npos)
      << render.err();
}

INSTANTIATE_TEST_SUITE_P(OneProcessAndMpirun, PreviewCliRanks, ::testing::Values(0, 3),
                         [](const ::testing::TestParamInfo<int>& p) { return p.param ? "mpirun_np3" : "one_process"; });

// A viewer that connects while the frame renders gets the image as it is (samples merged so
// far, part of the frame), then newer ones.
TEST_F(PreviewCli, AViewerConnectingMidRenderGetsTheCurrentImage) {
  SKIP_WITHOUT_CHROMIUM();
  // Slow on purpose (one thread, many samples); the test ends it once it has seen enough.
  BackgroundProcess render(Command(0, Scene(160, 120, 512), {"--threads", "1", "--preview", "any",
                                                             "--checkpoint-s", "1", "--no-png"}),
                           dir_->path());
  ASSERT_TRUE(render.WaitForOutput("preview: http", kPatience)) << render.out() << render.err();
  // The first checkpoint proves the render has been going for a second before anyone watches.
  const auto deadline = std::chrono::steady_clock::now() + kPatience;
  while (!std::filesystem::exists(dir_->File("out.exr")) && std::chrono::steady_clock::now() < deadline)
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
  ASSERT_TRUE(std::filesystem::exists(dir_->File("out.exr")));
  HeadlessChromium browser;
  std::string error;
  ASSERT_TRUE(browser.Start(Profile(), &error)) << error;
  ASSERT_TRUE(browser.Open(render.LineAfter("preview: "), &error)) << error;
  ASSERT_TRUE(browser.WaitFor("window.preview !== undefined && preview.frames > 0 && preview.status !== null",
                              kPatience, &error)) << error;
  const nlohmann::json first = browser.Evaluate("preview.frame", &error);
  const uint64_t total = browser.Evaluate("preview.status.samples_total", &error).get<uint64_t>();
  EXPECT_EQ(total, 160u * 120u * 512u);
  const uint64_t samples = first["samples"].get<uint64_t>();
  EXPECT_GT(samples, 0u) << "the first image a late viewer gets is the current one, not a blank";
  EXPECT_LT(samples, total) << "the render should still be going (it takes minutes)";
  const std::vector<uint8_t> canvas = Canvas(&browser, &error);
  ASSERT_EQ(canvas.size(), 4u * 160 * 120) << error;
  size_t opaque = 0;
  for (size_t i = 3; i < canvas.size(); i += 4) opaque += canvas[i] == 255;
  EXPECT_GT(opaque, 0u);
  // And it refines.
  EXPECT_TRUE(browser.WaitFor("preview.frame.samples > " + std::to_string(samples), kPatience, &error))
      << error;
  // Rays per second are shown while it renders, not only once the frame is done.
  EXPECT_TRUE(browser.WaitFor("preview.status.rays_per_second > 0 && !preview.status.finished && "
                              "document.getElementById('rays').textContent !== '—'",
                              kPatience, &error))
      << error;
  EXPECT_EQ(browser.Evaluate("document.getElementById('legend').textContent.includes('this process')", &error),
            true) << "the tiles in flight are listed";
}

// A frame wider than the window is shown scaled down to fit it (it was shown 1:1, most of it
// off the page); unchecking "fit to window" shows it 1:1. The canvas keeps every pixel.
TEST_F(PreviewCli, AFrameWiderThanTheWindowIsFittedToIt) {
  SKIP_WITHOUT_CHROMIUM();
  constexpr int kWidth = 2000, kHeight = 60;
  BackgroundProcess render(Command(0, Scene(kWidth, kHeight, 1), {"--preview", "any", "--preview-hold", "600",
                                                                  "--no-png"}),
                           dir_->path());
  ASSERT_TRUE(render.WaitForOutput("showing the last image", kPatience)) << render.out() << render.err();
  HeadlessChromium browser;
  std::string error;
  ASSERT_TRUE(browser.Start(Profile(), &error)) << error;
  ASSERT_TRUE(browser.Open(render.LineAfter("preview: "), &error)) << error;
  ASSERT_TRUE(browser.WaitFor("window.preview !== undefined && preview.frame !== null && "
                              "preview.frame.width === 2000", kPatience, &error)) << error;
  const auto shown_width = [&] {
    return browser.Evaluate("document.getElementById('image').getBoundingClientRect().width", &error)
        .get<double>();
  };
  const double window_width = browser.Evaluate("window.innerWidth", &error).get<double>();
  ASSERT_LT(window_width, kWidth) << "the test needs a window narrower than the frame";
  EXPECT_LE(shown_width(), window_width);
  EXPECT_GT(shown_width(), window_width / 2) << "fitted, not shrunk further";
  // The overlay of tiles stays on the image.
  EXPECT_EQ(browser.Evaluate("document.getElementById('tiles').getBoundingClientRect().width", &error),
            shown_width());
  browser.Evaluate("document.getElementById('fit').click()", &error);
  EXPECT_EQ(shown_width(), kWidth);
  EXPECT_EQ(Canvas(&browser, &error).size(), 4u * kWidth * kHeight) << error;
  render.Signal(SIGTERM);  // ends the hold
  EXPECT_EQ(render.Wait(), 0) << render.err();
}

// Bound to another address than loopback, the preview needs the token printed at start.
TEST_F(PreviewCli, AnExposedPreviewRefusesRequestsWithoutTheToken) {
  SKIP_WITHOUT_CHROMIUM();
  BackgroundProcess render(Command(0, Scene(48, 32, 2), {"--threads", "2", "--preview", "any",
                                                         "--preview-bind", "0.0.0.0",
                                                         "--preview-hold", "600"}),
                           dir_->path());
  ASSERT_TRUE(render.WaitForOutput("(token=", kPatience)) << render.out() << render.err();
  const std::string url = render.LineAfter("preview: http");
  const uint16_t port = PortOf(url.substr(0, url.find('/', 3)));
  const std::string token = render.LineAfter("(token=").substr(0, 32);
  ASSERT_EQ(token.size(), 32u) << render.out();
  EXPECT_EQ(testing::Get(port, "/"), 403);
  EXPECT_EQ(testing::Get(port, "/?token=0123"), 403);
  EXPECT_EQ(testing::Get(port, "/?token=" + token), 200);
  EXPECT_EQ(testing::Get(port, "/favicon.ico?token=" + token), 404);
  WsViewer no_token;
  EXPECT_FALSE(no_token.Open(port));

  HeadlessChromium browser;
  std::string error;
  ASSERT_TRUE(browser.Start(Profile(), &error)) << error;
  const std::string base = "http://127.0.0.1:" + std::to_string(port) + "/";
  ASSERT_TRUE(browser.Open(base, &error)) << error;
  ASSERT_TRUE(browser.WaitFor("location.port === '" + std::to_string(port) +
                              "' && document.readyState === 'complete'", kPatience, &error)) << error;
  EXPECT_EQ(browser.Evaluate("window.preview === undefined && document.body.innerText.includes('forbidden')", &error),
            true);
  HeadlessChromium with_token;
  ASSERT_TRUE(with_token.Start(Profile("chromium-profile-2"), &error)) << error;
  ASSERT_TRUE(with_token.Open(base + "?token=" + token, &error)) << error;
  ASSERT_TRUE(with_token.WaitFor("window.preview !== undefined && preview.status !== null && "
                                 "preview.status.finished && preview.frame !== null && "
                                 "preview.frame.samples === preview.status.samples_total",
                                 kPatience, &error)) << error;
  render.Signal(SIGTERM);
  EXPECT_EQ(render.Wait(), 0) << render.err();
}

// A viewer that never reads (a tiny receive buffer, never emptied) is skipped: the render
// finishes and its image is the image of a render nobody watched, bit for bit.
TEST_F(PreviewCli, AViewerThatNeverReadsDoesNotHoldTheRender) {
  // 1 MB frames: the viewer's kernel buffers fill within a few frames.
  const std::string scene = Scene(512, 512, 4);
  const ProcessResult plain = RunProcess(
      Command(0, scene, {"--threads", "2", "--output", dir_->File("plain.exr"), "--no-png"}), dir_->path());
  ASSERT_EQ(plain.exit_code, 0) << plain.err;
  BackgroundProcess render(Command(0, scene, {"--threads", "2", "--preview", "any", "--no-png"}),
                           dir_->path());
  ASSERT_TRUE(render.WaitForOutput("preview: http", kPatience)) << render.out() << render.err();
  WsViewer stalled;
  ASSERT_TRUE(stalled.Open(PortOf(render.LineAfter("preview: ").substr(0, render.LineAfter("preview: ").size() - 1)),
                           "", 4096));
  EXPECT_EQ(render.Wait(), 0) << render.err();
  const std::string a = Slurp(dir_->File("plain.exr")), b = Slurp(dir_->File("out.exr"));
  ASSERT_FALSE(a.empty());
  EXPECT_TRUE(a == b);
  std::printf("%s", render.out().c_str());  // how many frames were skipped, for the log
}

// The messages name what was asked: port 0 is refused (it turned the preview off silently),
// and bound to ::1 the tunnel's hint names [::1] (127.0.0.1 cannot reach it).
TEST_F(PreviewCli, MessagesNameWhatWasAsked) {
  const std::string scene = Scene(16, 16, 1);
  const ProcessResult zero = RunProcess(Command(0, scene, {"--preview", "0"}), dir_->path());
  EXPECT_NE(zero.exit_code, 0);
  EXPECT_NE(zero.err.find("--preview: '0' is not a port number (1 to 65535)"), std::string::npos) << zero.err;
  const ProcessResult off = RunProcess(Command(0, scene, {"--preview-bind", "0.0.0.0"}), dir_->path());
  EXPECT_EQ(off.exit_code, 2);  // taken and doing nothing, before
  EXPECT_NE(off.err.find("--preview-bind needs the preview on"), std::string::npos) << off.err;
  const ProcessResult unknown =
      RunProcess({raystack::testing::kRaystackBinary, std::string("rendr")}, dir_->path());
  EXPECT_EQ(unknown.exit_code, 2);
  EXPECT_NE(unknown.err.find("raystack: unknown command 'rendr'"), std::string::npos) << unknown.err;
  const ProcessResult v6 = RunProcess(Command(0, scene, {"--preview", "any", "--preview-bind", "::1"}),
                                      dir_->path());
  ASSERT_EQ(v6.exit_code, 0) << v6.err;
  const size_t at = v6.out.find("preview: http://[::1]:");
  ASSERT_NE(at, std::string::npos) << v6.out;
  const std::string port = std::to_string(PortOf(v6.out.substr(at, v6.out.find('/', at + 16) - at)));
  EXPECT_NE(v6.out.find("ssh -L " + port + ":[::1]:" + port + " "), std::string::npos) << v6.out;
}

// A render that fails says so on the page, with the error, and keeps it up for the hold time
// (it showed "(done)" and closed at once); the exposure slider reaches an --exposure beyond
// its range.
TEST_F(PreviewCli, AFailedRenderSaysWhyOnThePageForTheHoldTime) {
  SKIP_WITHOUT_CHROMIUM();
  BackgroundProcess render(Command(0, Scene(64, 48, 4),
                                   {"--fault-fail-read", "2", "--exposure", "12", "--preview", "any",
                                    "--preview-hold", "600"}),
                           dir_->path());
  ASSERT_TRUE(render.WaitForOutput("preview: http", kPatience)) << render.out() << render.err();
  const std::string url = render.LineAfter("preview: ");
  ASSERT_TRUE(render.WaitForOutput("showing the last image", kPatience)) << render.out() << render.err();
  // Said at the terminal before the hold, not only as the job ends.
  EXPECT_NE(render.err().find("raystack render: failed: "), std::string::npos) << render.err();
  HeadlessChromium browser;
  std::string error;
  ASSERT_TRUE(browser.Start(Profile(), &error)) << error;
  ASSERT_TRUE(browser.Open(url, &error)) << error;
  ASSERT_TRUE(browser.WaitFor("window.preview !== undefined && preview.status !== null && "
                              "preview.status.failed && preview.frame !== null",
                              kPatience, &error)) << error;
  const nlohmann::json note = browser.Evaluate("document.getElementById('note').textContent", &error);
  ASSERT_TRUE(note.is_string()) << error;
  EXPECT_NE(note.get<std::string>().find("failed: "), std::string::npos) << note;
  EXPECT_NE(note.get<std::string>().find("read failed (injected fault)"), std::string::npos) << note;
  EXPECT_EQ(browser.Evaluate("document.getElementById('frame').textContent", &error), "0 (failed)");
  EXPECT_EQ(browser.Evaluate("document.getElementById('left').textContent", &error), "—");
  EXPECT_EQ(browser.Evaluate("Number(document.getElementById('exposure').value)", &error), 12);
  render.Signal(SIGTERM);  // ends the hold
  EXPECT_EQ(render.Wait(), 1) << render.err();
  EXPECT_NE(render.err().find("read failed (injected fault)"), std::string::npos) << render.err();
}

// A 17th viewer's page is told that the viewers may be too many, not that the render may be
// over (the server's 503 is invisible to a page's WebSocket).
TEST_F(PreviewCli, APageRefusedAStreamSaysTheViewersMayBeTooMany) {
  SKIP_WITHOUT_CHROMIUM();
  BackgroundProcess render(Command(0, Scene(32, 24, 1), {"--preview", "any", "--preview-hold", "600"}),
                           dir_->path());
  ASSERT_TRUE(render.WaitForOutput("showing the last image", kPatience)) << render.out() << render.err();
  const std::string url = render.LineAfter("preview: ");
  std::vector<std::unique_ptr<WsViewer>> watching;
  for (int i = 0; i < kMaxViewers; ++i) {
    watching.push_back(std::make_unique<WsViewer>());
    ASSERT_TRUE(watching.back()->Open(PortOf(url))) << "viewer " << i;
  }
  HeadlessChromium browser;
  std::string error;
  ASSERT_TRUE(browser.Start(Profile(), &error)) << error;
  ASSERT_TRUE(browser.Open(url, &error)) << error;
  ASSERT_TRUE(browser.WaitFor("document.getElementById('connection') !== null && "
                              "document.getElementById('connection').textContent.includes('16 viewers')",
                              kPatience, &error)) << error;
  render.Signal(SIGTERM);
  EXPECT_EQ(render.Wait(), 0) << render.err();
}

// Clients that open connections and send nothing, more of them than the render may open
// files (ulimit -n): the preview holds only kMaxConnections of them, so the render still
// writes its image (it failed with "Too many open files" when the server kept them all).
TEST_F(PreviewCli, IdleConnectionsDoNotTakeTheRendersFileDescriptors) {
  constexpr int kFileLimit = 256, kClients = 2 * kFileLimit;
  // Slow on purpose (one thread, many samples), and cut after 3 s: its image is written while
  // the connections, held up to 10 s each before, are open.
  std::vector<std::string> argv = {"/bin/sh", "-c", "ulimit -n " + std::to_string(kFileLimit) +
                                                        " && exec \"$0\" \"$@\""};
  for (std::string& a : Command(0, Scene(160, 120, 512), {"--threads", "1", "--time-limit", "3",
                                                           "--preview", "any", "--no-png"}))
    argv.push_back(std::move(a));
  BackgroundProcess render(argv, dir_->path());
  ASSERT_TRUE(render.WaitForOutput("preview: http", kPatience)) << render.out() << render.err();
  const std::string url = render.LineAfter("preview: ");
  const uint16_t port = PortOf(url.substr(0, url.size() - 1));
  boost::asio::io_context ioc;
  std::vector<boost::asio::ip::tcp::socket> idle;
  for (int i = 0; i < kClients; ++i) {
    idle.emplace_back(ioc);
    boost::system::error_code ec;
    idle.back().connect({boost::asio::ip::make_address("127.0.0.1"), port}, ec);
  }
  EXPECT_EQ(render.Wait(), 0) << render.out() << render.err();
  EXPECT_TRUE(std::filesystem::exists(dir_->File("out.exr")));
  EXPECT_NE(render.out().find("requests refused"), std::string::npos) << render.out();
}

}  // namespace
}  // namespace raystack::master::preview
