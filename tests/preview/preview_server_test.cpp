#include "master/preview/preview_server.h"

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <sys/resource.h>
#include <unistd.h>

#include <atomic>
#include <chrono>
#include <cstring>
#include <filesystem>
#include <functional>
#include <thread>
#include <vector>

#include "common/image/png_writer.h"
#include "master/preview/preview_frame.h"
#include "tests/preview/http_client.h"

namespace raystack::master::preview {
namespace {

using testing::Get;
using testing::StatusOf;
using testing::WsViewer;
namespace asio = boost::asio;
namespace beast = boost::beast;
namespace http = beast::http;
using tcp = asio::ip::tcp;

std::unique_ptr<PreviewServer> StartOn(const std::string& bind) {
  ServerOptions options;
  options.bind = bind;
  Expected<std::unique_ptr<PreviewServer>> server = PreviewServer::Start(options);
  EXPECT_TRUE(server.ok()) << server.status().message();
  return server.ok() ? std::move(*server) : nullptr;
}

// Merges one sample into every pixel of `film`, sample index `n`, grey `v`.
void FillFilm(render::Film* film, uint32_t n, float v) {
  std::vector<render::SampleResult> batch(static_cast<size_t>(film->width()) * static_cast<size_t>(film->height()));
  for (size_t i = 0; i < batch.size(); ++i) {
    batch[i] = {};
    batch[i].pixel = static_cast<uint32_t>(i);
    batch[i].sample = n;
    batch[i].rgb[0] = batch[i].rgb[1] = batch[i].rgb[2] = v;
  }
  film->Merge(batch);
}

// Waits until `done` holds (true) or 10 s passed (false).
bool WaitUntil(const std::function<bool()>& done) {
  const auto give_up = std::chrono::steady_clock::now() + std::chrono::seconds(10);
  while (!done()) {
    if (std::chrono::steady_clock::now() > give_up) return false;
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  return true;
}

// File descriptors this process has open (the directory's own included, always the same).
int OpenFds() {
  int n = 0;
  for ([[maybe_unused]] const auto& entry : std::filesystem::directory_iterator("/proc/self/fd")) ++n;
  return n;
}

TEST(PreviewServer, ServesThePageAndNothingElse) {
  auto server = StartOn("127.0.0.1");
  ASSERT_TRUE(server);
  const uint16_t port = server->port();
  EXPECT_TRUE(server->token().empty());
  EXPECT_EQ(server->Url(), "http://127.0.0.1:" + std::to_string(port) + "/");
  EXPECT_EQ(Get(port, "/"), 200);
  EXPECT_EQ(Get(port, "/?exposure=1"), 200);
  EXPECT_EQ(Get(port, "/index.html"), 404);
  EXPECT_EQ(Get(port, "/../etc/passwd"), 404);
  EXPECT_EQ(Get(port, "/ws"), 404);  // the stream without an upgrade
  EXPECT_EQ(StatusOf(port, "POST / HTTP/1.1\r\nHost: 127.0.0.1\r\nContent-Length: 0\r\n\r\n"), 405);
  EXPECT_EQ(StatusOf(port, "garbage\r\n\r\n"), 400);
  // A request larger than kMaxRequestBytes is refused, not buffered.
  const std::string big(4 * kMaxRequestBytes, 'a');
  EXPECT_EQ(StatusOf(port, "GET / HTTP/1.1\r\nHost: 127.0.0.1\r\nX-Big: " + big + "\r\n\r\n"), 431);
  // A body (and a GET with one) is refused.
  EXPECT_EQ(StatusOf(port, "GET / HTTP/1.1\r\nHost: 127.0.0.1\r\nContent-Length: 5\r\n\r\nhello"), 400);
  EXPECT_GE(server->counters().refused, 7u);
  EXPECT_EQ(Get(port, "/"), 200);  // and it still serves
}

// The status the page shows, as JSON for scripts and curl (found by an operator, who had to
// write a WebSocket client to read a job's progress); guarded by the token as the page is.
TEST(PreviewServer, ServesTheStatusAsJson) {
  auto server = StartOn("127.0.0.1");
  ASSERT_TRUE(server);
  PreviewStatus status;
  status.frame = 2;
  status.frames = 5;
  status.samples_done = 1234;
  status.samples_total = 9999;
  server->Publish(status);
  std::string body;
  nlohmann::json json;
  ASSERT_TRUE(WaitUntil([&] {
    body.clear();
    if (Get(server->port(), "/status.json", "127.0.0.1", "", &body) != 200) return false;
    json = nlohmann::json::parse(body, nullptr, false);
    return !json.is_discarded() && json.value("samples_done", 0) == 1234;
  })) << body;
  EXPECT_EQ(json["frame"], 2);
  EXPECT_EQ(json["samples_total"], 9999);

  ServerOptions exposed;
  exposed.bind = "0.0.0.0";
  Expected<std::unique_ptr<PreviewServer>> open = PreviewServer::Start(exposed);
  ASSERT_TRUE(open.ok()) << open.status().message();
  EXPECT_EQ(Get((*open)->port(), "/status.json"), 403);
  EXPECT_EQ(Get((*open)->port(), "/status.json?token=" + (*open)->token()), 200);
}

// With no page open the server took no copy of the film, so /status.json listed the tiles a
// slave had finished as still in flight. A request now brings a copy (paced as the viewers'
// refreshes are), and the finished tile is left out.
TEST(PreviewServer, TheStatusAsJsonLeavesOutFinishedTilesWithoutAViewer) {
  auto server = StartOn("127.0.0.1");
  ASSERT_TRUE(server);
  render::Film film(8, 4);
  server->AttachFilm(&film, 0);
  std::vector<render::SampleResult> left_half;  // the pixels x < 4, one sample each
  for (uint32_t y = 0; y < 4; ++y)
    for (uint32_t x = 0; x < 4; ++x) {
      render::SampleResult s{};
      s.pixel = y * 8 + x;
      left_half.push_back(s);
    }
  film.Merge(left_half);
  PreviewStatus status;
  status.frames = 1;
  status.spp = 1;
  status.samples_total = 32;
  status.samples_done = 16;
  status.tiles = {{1, {{0, 0, 4, 4}, {4, 0, 8, 4}}, ""}};
  server->Publish(status);
  nlohmann::json json;
  std::string body;
  ASSERT_TRUE(WaitUntil([&] {
    body.clear();
    if (Get(server->port(), "/status.json", "127.0.0.1", "", &body) != 200) return false;
    json = nlohmann::json::parse(body, nullptr, false);
    return !json.is_discarded() && json["tiles"].size() == 1 && json["tiles"][0]["tiles"].size() == 1;
  })) << body;
  EXPECT_EQ(json["tiles"][0]["tiles"][0], nlohmann::json({4, 0, 8, 4}));  // in flight
  EXPECT_EQ(server->counters().viewers, 0);
  server->DetachFilm();
}

// A copy of the film costs the merging thread its lock (the whole film at 8K): the server takes
// none while no page is open, and none while the film does not change.
TEST(PreviewServer, CopiesTheFilmOnlyForViewersAndOnlyWhenItChanged) {
  auto server = StartOn("127.0.0.1");
  ASSERT_TRUE(server);
  render::Film film(16, 8);
  server->AttachFilm(&film, 0);
  for (uint32_t n = 0; n < 20; ++n) {
    FillFilm(&film, n, 0.5f);
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
  EXPECT_EQ(server->counters().snapshots, 0u) << "copies with no page open";
  WsViewer viewer;
  ASSERT_TRUE(viewer.Open(server->port()));
  ASSERT_TRUE(WaitUntil([&] { return server->counters().snapshots >= 1; }));
  std::this_thread::sleep_for(std::chrono::milliseconds(300));  // several refreshes, no merge
  const uint64_t paused = server->counters().snapshots;
  std::this_thread::sleep_for(std::chrono::milliseconds(300));
  EXPECT_EQ(server->counters().snapshots, paused) << "copies of a film that did not change";
  FillFilm(&film, 20, 0.5f);
  EXPECT_TRUE(WaitUntil([&] { return server->counters().snapshots > paused; }));
  server->DetachFilm();
}

TEST(PreviewServer, OnLoopbackRefusesForeignHostsAndOrigins) {
  auto server = StartOn("127.0.0.1");
  ASSERT_TRUE(server);
  const uint16_t port = server->port();
  EXPECT_EQ(Get(port, "/", "localhost:8080"), 200);  // e.g. through an SSH tunnel
  EXPECT_EQ(Get(port, "/", "[::1]:80"), 200);
  std::string body;
  EXPECT_EQ(Get(port, "/", "attacker.example", "", &body), 403);  // DNS rebinding
  // The refusal says what to open instead (this machine's name is not a loopback name).
  EXPECT_NE(body.find("http://127.0.0.1:" + std::to_string(port) + "/"), std::string::npos) << body;
  EXPECT_EQ(Get(port, "/", "127.0.0.1", "Origin: http://attacker.example\r\n", &body), 403);
  EXPECT_NE(body.find("another site"), std::string::npos) << body;
  EXPECT_EQ(Get(port, "/", "127.0.0.1", "Origin: http://127.0.0.1:1234\r\n"), 200);
}

TEST(PreviewServer, ExposedItRequiresTheToken) {
  auto server = StartOn("0.0.0.0");
  ASSERT_TRUE(server);
  const uint16_t port = server->port();
  const std::string token = server->token();
  ASSERT_EQ(token.size(), 32u);
  EXPECT_NE(server->Url().find("?token=" + token), std::string::npos);
  std::string body;
  EXPECT_EQ(Get(port, "/", "127.0.0.1", "", &body), 403);
  EXPECT_NE(body.find("needs its token"), std::string::npos) << body;
  EXPECT_EQ(Get(port, "/?token="), 403);
  EXPECT_EQ(Get(port, "/?token=" + std::string(32, '0')), 403);
  EXPECT_EQ(Get(port, "/?token=" + token + "x"), 403);
  EXPECT_EQ(Get(port, "/?token=" + token), 200);
  EXPECT_EQ(Get(port, "/?exposure=2&token=" + token), 200);
  EXPECT_EQ(Get(port, "/nothing?token=" + token), 404);
  WsViewer without, with;
  EXPECT_FALSE(without.Open(port));
  EXPECT_TRUE(with.Open(port, "?token=" + token));
  // Two servers, two tokens.
  auto other = StartOn("0.0.0.0");
  ASSERT_TRUE(other);
  EXPECT_NE(other->token(), token);
}

TEST(PreviewServer, BadAddressesAreErrorsNamingThem) {
  ServerOptions options;
  options.bind = "not-an-address";
  Expected<std::unique_ptr<PreviewServer>> bad = PreviewServer::Start(options);
  ASSERT_FALSE(bad.ok());
  EXPECT_NE(bad.status().message().find("not-an-address"), std::string::npos);
  auto first = StartOn("127.0.0.1");
  ASSERT_TRUE(first);
  options.bind = "127.0.0.1";
  options.port = first->port();
  Expected<std::unique_ptr<PreviewServer>> taken = PreviewServer::Start(options);
  ASSERT_FALSE(taken.ok());
  EXPECT_NE(taken.status().message().find("127.0.0.1:" + std::to_string(first->port())),
            std::string::npos) << taken.status().message();
  EXPECT_NE(taken.status().message().find("--preview any"), std::string::npos)
      << taken.status().message();
  options.bind = "localhost";  // a name, not an address: the error says which address it means
  options.port = 0;
  Expected<std::unique_ptr<PreviewServer>> named = PreviewServer::Start(options);
  ASSERT_FALSE(named.ok());
  EXPECT_NE(named.status().message().find("127.0.0.1"), std::string::npos) << named.status().message();
  // Not this machine's name (what the URL shows for 0.0.0.0): the address asked for.
  auto any = StartOn("0.0.0.0");
  ASSERT_TRUE(any);
  options.bind = "0.0.0.0";
  options.port = any->port();
  Expected<std::unique_ptr<PreviewServer>> busy = PreviewServer::Start(options);
  ASSERT_FALSE(busy.ok());
  EXPECT_NE(busy.status().message().find("cannot listen on 0.0.0.0:" + std::to_string(any->port())),
            std::string::npos) << busy.status().message();
  // The address as in a URL, as the ssh tunnel's hint uses it.
  EXPECT_EQ(first->address(), "127.0.0.1");
  auto v6 = StartOn("::1");
  ASSERT_TRUE(v6);
  EXPECT_EQ(v6->address(), "[::1]");
  EXPECT_EQ(v6->Url(), "http://[::1]:" + std::to_string(v6->port()) + "/");
}

// Idle connections (nothing ever sent) would each be kept until the request timeout: past
// kMaxConnections a new one takes the place of the one idle longest, so the server holds no
// more descriptors than kMaxConnections (the render needs its own to write its image), and
// clients that connect and send nothing cannot keep a viewer out.
TEST(PreviewServer, HoldsAtMostkMaxConnectionsAndIdleOnesMakeRoom) {
  auto server = StartOn("127.0.0.1");
  ASSERT_TRUE(server);
  asio::io_context ioc;
  tcp::socket(ioc).open(tcp::v4());  // the client's own descriptors (epoll's), before counting
  const int fds_before = OpenFds();
  constexpr int kClients = 3 * kMaxConnections;
  std::vector<tcp::socket> idle;
  for (int i = 0; i < kClients; ++i) {
    idle.emplace_back(ioc);
    idle.back().connect({asio::ip::make_address("127.0.0.1"), server->port()});
  }
  EXPECT_TRUE(WaitUntil([&] { return server->counters().evicted >= kClients - kMaxConnections; }))
      << server->counters().evicted << " evicted";
  const ServerCounters c = server->counters();
  EXPECT_EQ(c.connections, kMaxConnections);
  EXPECT_EQ(c.evicted, static_cast<uint64_t>(kClients - kMaxConnections));
  EXPECT_EQ(c.refused, 0u);
  // The server's own side of them: the ones it holds, the others closed.
  EXPECT_LE(OpenFds() - fds_before - kClients, kMaxConnections);
  // The oldest were closed, the newest are held.
  for (int i = 0; i < kClients; i += kClients / 12) {
    char byte;
    beast::error_code ec;
    idle[i].non_blocking(true);
    idle[i].read_some(asio::buffer(&byte, 1), ec);
    if (i < kClients - kMaxConnections)
      EXPECT_EQ(ec, asio::error::eof) << "client " << i << ": " << ec.message();
    else
      EXPECT_EQ(ec, asio::error::would_block) << "client " << i << ": " << ec.message();
  }
  EXPECT_EQ(Get(server->port(), "/"), 200) << "a request gets through the idle ones";
  EXPECT_EQ(server->counters().evicted, static_cast<uint64_t>(kClients - kMaxConnections + 1));
  idle.clear();
  EXPECT_TRUE(WaitUntil([&] { return server->counters().connections == 0; }));
  EXPECT_EQ(Get(server->port(), "/"), 200);
}

// Out of file descriptors, an accept fails and the connection stays pending: the server tries
// again every kAcceptRetryMs instead of at once (which spun a core), and serves it once
// descriptors are free again.
TEST(PreviewServer, AfterAFailedAcceptItWaitsBeforeTheNext) {
  auto server = StartOn("127.0.0.1");
  ASSERT_TRUE(server);
  asio::io_context ioc;
  tcp::socket pending(ioc);
  pending.open(tcp::v4());  // its descriptor now: connecting needs none
  rlimit normal{};
  ASSERT_EQ(getrlimit(RLIMIT_NOFILE, &normal), 0);
  const int lowest_free = dup(0);
  ASSERT_GE(lowest_free, 0);
  close(lowest_free);
  rlimit none_free = normal;
  none_free.rlim_cur = static_cast<rlim_t>(lowest_free);
  ASSERT_EQ(setrlimit(RLIMIT_NOFILE, &none_free), 0);
  beast::error_code ec;
  pending.connect({asio::ip::make_address("127.0.0.1"), server->port()}, ec);
  constexpr int kStarvedMs = 1000;
  std::this_thread::sleep_for(std::chrono::milliseconds(kStarvedMs));
  ASSERT_EQ(setrlimit(RLIMIT_NOFILE, &normal), 0);
  ASSERT_FALSE(ec) << ec.message();
  const uint64_t failures = server->counters().accept_failures;
  EXPECT_GE(failures, 1u);
  EXPECT_LE(failures, static_cast<uint64_t>(kStarvedMs / kAcceptRetryMs + 2));
  const std::string get = "GET / HTTP/1.1\r\nHost: 127.0.0.1\r\nConnection: close\r\n\r\n";
  asio::write(pending, asio::buffer(get), ec);
  beast::flat_buffer buffer;
  http::response<http::string_body> res;
  http::read(pending, buffer, res, ec);
  ASSERT_FALSE(ec) << ec.message();
  EXPECT_EQ(res.result_int(), 200u);
}

// Many upgrades at once: a viewer counts from the moment its upgrade is accepted, so at most
// kMaxViewers get 101, the others 503 (while the cap counted only finished handshakes, all
// the upgrades that arrived during one got 101); a place is free again once one closes.
TEST(PreviewServer, SimultaneousUpgradesGetNoMoreThankMaxViewers) {
  auto server = StartOn("127.0.0.1");
  ASSERT_TRUE(server);
  // A large final image: each new viewer's first frame is encoded on the server's thread as
  // its handshake ends, long enough for the other upgrades to arrive meanwhile.
  render::Film film(1024, 1024);
  FillFilm(&film, 0, 0.5f);
  server->AttachFilm(&film, 0);
  server->DetachFilm();
  std::this_thread::sleep_for(std::chrono::milliseconds(100));  // its Refresh, on the server's thread
  constexpr int kClients = kMaxConnections - 4;
  static_assert(kClients > 2 * kMaxViewers);
  const std::string upgrade = "GET /ws HTTP/1.1\r\nHost: 127.0.0.1\r\nUpgrade: websocket\r\n"
                              "Connection: Upgrade\r\nSec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\n"
                              "Sec-WebSocket-Version: 13\r\n\r\n";
  asio::io_context ioc;
  std::vector<tcp::socket> clients;
  for (int i = 0; i < kClients; ++i) {
    clients.emplace_back(ioc);
    clients.back().connect({asio::ip::make_address("127.0.0.1"), server->port()});
  }
  for (tcp::socket& c : clients) asio::write(c, asio::buffer(upgrade));
  int switched = 0, unavailable = 0;
  for (tcp::socket& c : clients) {
    std::string head;
    beast::error_code ec;
    asio::read_until(c, asio::dynamic_buffer(head), "\r\n\r\n", ec);
    ASSERT_FALSE(ec) << ec.message();
    if (head.starts_with("HTTP/1.1 101 ")) ++switched;
    if (head.starts_with("HTTP/1.1 503 ")) ++unavailable;
  }
  EXPECT_EQ(switched, kMaxViewers);
  EXPECT_EQ(unavailable, kClients - kMaxViewers);
  EXPECT_TRUE(WaitUntil([&] { return server->counters().viewers == kMaxViewers; }));
  WsViewer late, later;
  EXPECT_FALSE(late.Open(server->port()));
  clients.clear();
  EXPECT_TRUE(WaitUntil([&] { return server->counters().viewers == 0; }));
  EXPECT_TRUE(later.Open(server->port()));
}

TEST(PreviewServer, AViewerGetsTheStatusAndTheCurrentImageAndCanSetItsExposure) {
  auto server = StartOn("127.0.0.1");
  ASSERT_TRUE(server);
  render::Film film(8, 4);
  FillFilm(&film, 0, 0.25f);
  server->AttachFilm(&film, 3);
  PreviewStatus status;
  status.frame = 3;
  status.frames = 4;
  status.samples_total = 64;
  status.samples_done = 32;
  server->Publish(status);
  WsViewer viewer;
  ASSERT_TRUE(viewer.Open(server->port()));
  std::string message;
  bool binary = false;
  bool got_status = false, got_frame = false;
  while (!(got_status && got_frame)) {
    ASSERT_TRUE(viewer.Read(&message, &binary));
    if (!binary) {
      const nlohmann::json j = nlohmann::json::parse(message);
      EXPECT_EQ(j["frame"], 3);
      EXPECT_EQ(j["samples_done"], 32);
      got_status = true;
    } else {
      ASSERT_EQ(message.size(), kFrameHeaderBytes + 4 * 32);
      FrameHeader h;
      std::memcpy(&h, message.data(), sizeof h);
      EXPECT_EQ(h.frame, 3u);
      EXPECT_EQ(h.samples_merged, 32u);
      EXPECT_EQ(static_cast<uint8_t>(message[kFrameHeaderBytes]), image::LinearToSrgb8(0.25f));
      got_frame = true;
    }
  }
  // The viewer's exposure: the frame on show comes again, brighter.
  viewer.Write("exposure 1");
  do ASSERT_TRUE(viewer.Read(&message, &binary));
  while (!binary);
  EXPECT_EQ(static_cast<uint8_t>(message[kFrameHeaderBytes]), image::LinearToSrgb8(0.5f));
  // A message over the bound closes the stream.
  viewer.Write(std::string(kMaxViewerMessageBytes + 1, 'x'));
  while (viewer.Read(&message, &binary)) {
  }
  server->DetachFilm();
}

// A viewer sending its exposure every 2 ms costs at most one frame per tick (each used to be
// a full re-encode), and the last value it sent is the one its last frame shows.
TEST(PreviewServer, ExposureMessagesAreAppliedAtMostOncePerTick) {
  auto server = StartOn("127.0.0.1");
  ASSERT_TRUE(server);
  render::Film film(8, 4);
  FillFilm(&film, 0, 0.125f);
  server->AttachFilm(&film, 0);
  server->DetachFilm();
  WsViewer viewer;
  ASSERT_TRUE(viewer.Open(server->port()));
  ASSERT_TRUE(WaitUntil([&] { return server->counters().frames_sent == 1; }));
  constexpr int kMessages = 500, kEveryMs = 2;
  const auto start = std::chrono::steady_clock::now();
  for (int i = 1; i <= kMessages; ++i) {
    viewer.Write("exposure " + std::to_string((i + 2) % 4 - 1));  // ..., -1, 0, 1 last
    std::this_thread::sleep_for(std::chrono::milliseconds(kEveryMs));
  }
  const auto ticks = (std::chrono::steady_clock::now() - start) / std::chrono::milliseconds(kRefreshMs);
  std::this_thread::sleep_for(std::chrono::milliseconds(3 * kRefreshMs));  // the last one applied
  const uint64_t sent = server->counters().frames_sent;
  // The first frame, one a tick while they came (one more for a tick's phase), the last.
  EXPECT_LE(sent, static_cast<uint64_t>(1 + ticks + 1 + 1)) << ticks << " ticks";
  EXPECT_GE(sent, 2u);
  std::string message, last_frame;
  bool binary = false;
  for (uint64_t frames = 0; frames < sent;) {
    ASSERT_TRUE(viewer.Read(&message, &binary));
    if (binary) ++frames, last_frame = message;
  }
  EXPECT_EQ(static_cast<uint8_t>(last_frame[kFrameHeaderBytes]), image::LinearToSrgb8(0.25f));
}

// A viewer that never reads: the server skips its frames (at most one waits), the film keeps
// being published, other viewers keep getting frames, and the server still stops.
TEST(PreviewServer, AViewerThatNeverReadsBlocksNothing) {
  auto server = StartOn("127.0.0.1");
  ASSERT_TRUE(server);
  render::Film film(512, 512);  // 1 MB a frame
  server->AttachFilm(&film, 0);
  WsViewer stalled, reading;
  ASSERT_TRUE(stalled.Open(server->port(), "", 4096));
  ASSERT_TRUE(reading.Open(server->port()));
  std::atomic<bool> stop{false};
  std::atomic<int> frames_read{0};
  std::thread reader([&] {
    std::string m;
    bool binary;
    while (!stop.load() && reading.Read(&m, &binary))
      if (binary) frames_read.fetch_add(1);
  });
  // New samples keep coming, as from a render; every Publish returns at once whatever the
  // viewers do (this loop would hang otherwise).
  uint32_t n = 0;
  const auto give_up = std::chrono::steady_clock::now() + std::chrono::seconds(120);
  while ((server->counters().frames_skipped < 3 || frames_read.load() < 10) &&
         std::chrono::steady_clock::now() < give_up) {
    FillFilm(&film, n++, 0.5f);
    PreviewStatus s;
    s.samples_done = film.samples_merged();
    server->Publish(s);
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
  const ServerCounters c = server->counters();
  EXPECT_GE(c.frames_skipped, 3u);
  EXPECT_GE(frames_read.load(), 10);
  EXPECT_EQ(c.viewers, 2);
  server->DetachFilm();
  stop = true;
  server->Stop();  // closes both; the reader's read fails and it ends
  reader.join();
}

}  // namespace
}  // namespace raystack::master::preview
