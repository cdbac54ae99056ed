#include "master/preview/preview_server.h"

#include <algorithm>
#include <atomic>
#include <chrono>
#include <condition_variable>
#include <csignal>
#include <future>
#include <cstdlib>
#include <mutex>
#include <optional>
#include <random>
#include <string_view>
#include <thread>
#include <utility>
#include <vector>

#include <boost/asio.hpp>
#include <boost/beast/core.hpp>
#include <boost/beast/http.hpp>
#include <boost/beast/websocket.hpp>

#include "common/base/log.h"
#include "master/preview/page.h"
#include "master/preview/preview_frame.h"

namespace raystack::master::preview {
namespace {

namespace asio = boost::asio;
namespace beast = boost::beast;
namespace http = beast::http;
namespace websocket = beast::websocket;
using tcp = asio::ip::tcp;
using beast::error_code;

constexpr auto kRequestTimeout = std::chrono::seconds(10);

// 128 random bits from the system's generator, as hex.
std::string RandomToken() {
  std::random_device rd;
  std::string token;
  for (int i = 0; i < 4; ++i) token += StrFormat("%08x", static_cast<unsigned>(rd()));
  return token;
}

// Compares in time independent of where the strings differ.
bool SameToken(std::string_view a, std::string_view b) {
  if (a.size() != b.size()) return false;
  unsigned diff = 0;
  for (size_t i = 0; i < a.size(); ++i) diff |= static_cast<unsigned>(a[i] ^ b[i]);
  return diff == 0;
}

// The value of `key` in a query string "a=1&token=..." (no decoding: tokens are hex).
std::string_view QueryValue(std::string_view query, std::string_view key) {
  while (!query.empty()) {
    const size_t amp = query.find('&');
    const std::string_view pair = query.substr(0, amp);
    if (pair.size() > key.size() && pair.substr(0, key.size()) == key && pair[key.size()] == '=')
      return pair.substr(key.size() + 1);
    if (amp == std::string_view::npos) break;
    query.remove_prefix(amp + 1);
  }
  return {};
}

// "localhost:8080", "127.0.0.1", "[::1]:80", "http://localhost:8080": a loopback name?
bool IsLoopbackHost(std::string_view host) {
  if (const size_t scheme = host.find("://"); scheme != std::string_view::npos)
    host.remove_prefix(scheme + 3);
  if (host.starts_with('[')) {
    const size_t close = host.find(']');
    if (close == std::string_view::npos) return false;
    host = host.substr(1, close - 1);
  } else if (const size_t colon = host.find(':'); colon != std::string_view::npos) {
    host = host.substr(0, colon);
  }
  if (host == "localhost") return true;
  error_code ec;
  const asio::ip::address a = asio::ip::make_address(std::string(host), ec);
  return !ec && a.is_loopback();
}

// A place in a bounded count of things held (connections, viewers), given back when its holder goes.
// The count is shared with the holders: a handler dropped with the io_context, after the
// server has gone, still gives its place back.
class Slot {
 public:
  using Count = std::shared_ptr<std::atomic<int>>;

  Slot() = default;
  // A place in `count`, or none (false) when it already holds `max`. One thread takes places.
  static Slot Take(const Count& count, int max) {
    if (count->load() >= max) return Slot();
    count->fetch_add(1);
    return Slot(count);
  }
  Slot(Slot&& other) noexcept = default;  // leaves `other` empty
  Slot& operator=(Slot&& other) noexcept {
    Slot(std::move(other)).count_.swap(count_);
    return *this;
  }
  ~Slot() {
    if (count_) count_->fetch_sub(1);
  }
  explicit operator bool() const { return count_ != nullptr; }

 private:
  explicit Slot(Count count) : count_(std::move(count)) {}
  Count count_;
};

}  // namespace

class PreviewServer::Impl {
 public:
  class Viewer;
  class Request;

  Impl(const ServerOptions& options, const asio::ip::address& address)
      : options_(options), acceptor_(ioc_), accept_retry_(ioc_), tick_(ioc_) {
    if (!address.is_loopback()) token_ = RandomToken();
    address_text_ = address.is_v6() ? "[" + address.to_string() + "]" : address.to_string();
    // 0.0.0.0 or :: is no address to open: name this machine instead.
    bind_text_ = address.is_unspecified() ? asio::ip::host_name() : address_text_;
  }

  Status Listen(const asio::ip::address& address) {
    error_code ec;
    const tcp::endpoint endpoint(address, options_.port);
    acceptor_.open(endpoint.protocol(), ec);
    if (!ec) acceptor_.set_option(asio::socket_base::reuse_address(true), ec);
    if (!ec) acceptor_.bind(endpoint, ec);
    if (!ec) acceptor_.listen(asio::socket_base::max_listen_connections, ec);
    if (ec)
      // The address asked for (not this machine's name): that is what could not be bound.
      return Status::Error(StrFormat("preview: cannot listen on %s:%u: %s%s", address_text_.c_str(),
                                     options_.port, ec.message().c_str(),
                                     ec == asio::error::address_in_use
                                         ? " (another program has the port: pick another, or "
                                           "--preview any for a free one)"
                                         : ""));
    port_ = acceptor_.local_endpoint().port();
    return OkStatus();
  }

  void Run() {
    Accept();
    ArmTick();
    thread_ = std::thread([this] {
      // A handler never throws (errors are codes); this catches allocation failure only, and
      // keeps it inside the server's thread.
      try {
        ioc_.run();
      } catch (const std::exception& e) {
        LOG_ERROR("preview", "server stopped: %s", e.what());
      }
    });
  }

  void Stop() {
    if (!thread_.joinable()) return;
    asio::post(ioc_, [this] {
      error_code ec;
      acceptor_.close(ec);
      accept_retry_.cancel();
      tick_.cancel();
      CloseViewers();
      // What is left (requests being read, handlers of closed sockets) is dropped with the
      // io_context; none of it refers to the server (their slots share only the count).
      ioc_.stop();
    });
    thread_.join();
  }

  void AttachFilm(const render::Film* film, uint32_t frame) {
    if (!Streamed(film->width(), film->height())) {
      LOG_WARNING("preview", "a %dx%d frame is larger than the preview streams (%llu pixels); "
                  "only its status is shown", film->width(), film->height(),
                  static_cast<unsigned long long>(kMaxFramePixels));
      film = nullptr;
    }
    std::lock_guard lock(film_mu_);
    film_ = film;
    film_frame_ = frame;
    last_merged_ = UINT64_MAX;
  }

  void DetachFilm() {
    std::lock_guard lock(film_mu_);
    if (film_ == nullptr) return;
    final_ = std::make_shared<const FilmSnapshot>(TakeSnapshot(*film_, film_frame_));
    snapshots_.fetch_add(1);
    film_ = nullptr;
    asio::post(ioc_, [this] { Refresh(); });
  }

  void Publish(const PreviewStatus& status) {
    {
      std::lock_guard lock(status_mu_);
      status_ = status;
      status_dirty_ = true;
    }
    if (status.finished || status.failed || status.interrupted) asio::post(ioc_, [this] { Refresh(); });
  }

  void Drain(double seconds);

  void Hold(double seconds) {
    if (seconds <= 0) return;
    std::mutex mu;
    std::condition_variable cv;
    bool interrupted = false;
    auto signals = std::make_shared<asio::signal_set>(ioc_, SIGINT, SIGTERM);
    signals->async_wait([&](const error_code& ec, int) {
      if (ec) return;
      std::lock_guard lock(mu);
      interrupted = true;
      cv.notify_all();
    });
    {
      std::unique_lock lock(mu);
      cv.wait_for(lock, std::chrono::duration<double>(seconds), [&] { return interrupted; });
    }
    // Cancel on the server's thread, and wait for it: the handler refers to this frame.
    std::promise<void> cancelled;
    asio::post(ioc_, [&] {
      error_code ec;
      signals->cancel(ec);
      cancelled.set_value();
    });
    if (thread_.joinable()) cancelled.get_future().wait();
  }

  ServerCounters counters() const {
    return {snapshots_.load(), frames_sent_.load(), frames_skipped_.load(), refused_.load(),
            evicted_.load(), accept_failures_.load(), viewers_.load(), connections_->load()};
  }

  uint16_t port() const { return port_; }
  const std::string& token() const { return token_; }
  const std::string& address() const { return address_text_; }
  std::string Url() const {
    return StrFormat("http://%s:%u/%s", bind_text_.c_str(), port_,
                     token_.empty() ? "" : ("?token=" + token_).c_str());
  }

  // --- on the server's thread only, from here on ---

  // Checks a request's right to be served: the token when one is set, else a loopback Host
  // (and Origin, for the stream) so that a web page elsewhere cannot read the image through
  // a DNS name that resolves to 127.0.0.1.
  // Why the request is refused (the body of the 403, so whoever opened the page knows what to
  // do), or empty when it is allowed.
  std::string Refusal(const http::request<http::empty_body>& req, std::string_view query) const {
    if (!token_.empty())
      return SameToken(QueryValue(query, "token"), token_)
                 ? std::string()
                 : "forbidden: this preview needs its token, as in the address the render printed "
                   "when it started (...?token=...)\n";
    if (!IsLoopbackHost(std::string_view(req[http::field::host].data(), req[http::field::host].size())))
      return StrFormat("forbidden: this preview serves loopback names only: open "
                       "http://127.0.0.1:%u/ or http://localhost:%u/ (from another machine through "
                       "the ssh -L tunnel the render printed), or render with --preview-bind and "
                       "the token it prints\n", port_, port_);
    const auto origin = req.find(http::field::origin);
    if (origin != req.end() && !IsLoopbackHost(std::string_view(origin->value().data(), origin->value().size())))
      return "forbidden: requests from another site's page are refused\n";
    return std::string();
  }

  void CountRefused() { refused_.fetch_add(1); }
  void CountSent() { frames_sent_.fetch_add(1); }
  void CountSkipped() { frames_skipped_.fetch_add(1); }
  // A viewer's place from the moment its upgrade is accepted: counting only the handshakes
  // done let any number of simultaneous upgrades through. None (false) when kMaxViewers hold.
  Slot TakeViewerSlot() { return Slot::Take(viewer_slots_, kMaxViewers); }
  const Srgb8Encoder& encoder() const { return encoder_; }
  float exposure() const { return options_.exposure; }

  void AddViewer(const std::shared_ptr<Viewer>& v);
  void RemoveViewer(const Viewer* v);

 private:
  void Accept();
  void Accepted(tcp::socket socket);
  // The place of the connection that has waited longest without sending its request, which
  // is closed; none (false) when every connection has sent one (16 streams and answers).
  Slot EvictOldestIdle();
  void AcceptFailed(const error_code& ec);
  // Copying the film holds its lock (a merge waits meanwhile): on a large film, refresh
  // less often, so that copies hold it at most 1/kMaxCopyShare of the time.
  std::chrono::steady_clock::duration CopyPace() const {
    return std::max<std::chrono::steady_clock::duration>(std::chrono::milliseconds(kRefreshMs),
                                                         last_copy_ * kMaxCopyShare);
  }
  void ArmTick() {
    tick_.expires_after(CopyPace());
    tick_.async_wait([this](const error_code& ec) {
      if (ec) return;
      Refresh();
      ArmTick();
    });
  }
  // Takes a new copy of the film if someone watches and it changed, and sends it and the
  // status to every viewer (each keeps only the newest).
  void Refresh();
  // The status as the viewers get it (the server's thread). The tiles still in flight are told
  // by the film's sample counts: the viewers' copy, or, with none watching (no copy is taken
  // then, and every tile given lately was listed, finished ones too), a copy of the counts
  // alone (4 bytes a pixel), at most one per CopyPace() whatever the requests.
  std::string CurrentStatusJson() {
    PreviewStatus status;
    {
      std::lock_guard lock(status_mu_);
      status = status_;
    }
    if (!viewers_list_.empty() && latest_ && latest_->frame == status.frame)
      return StatusJson(status, latest_->width, latest_->counts) + "\n";
    CopyCounts();
    const bool same_frame = counts_frame_ == status.frame && !counts_.empty();
    return StatusJson(status, same_frame ? counts_width_ : 0,
                      same_frame ? counts_ : std::vector<uint32_t>()) + "\n";
  }
  void CopyCounts() {
    const auto now = std::chrono::steady_clock::now();
    std::lock_guard lock(film_mu_);
    if (film_ == nullptr) return;
    const bool fresh = counts_frame_ == film_frame_ && !counts_.empty() && now - counts_at_ < CopyPace();
    if (fresh) return;
    film_->ResolveColour(nullptr, &counts_);
    counts_width_ = film_->width();
    counts_frame_ = film_frame_;
    counts_at_ = now;
  }
  void CloseViewers();

  ServerOptions options_;
  asio::io_context ioc_{1};
  tcp::acceptor acceptor_;
  asio::steady_timer accept_retry_;
  asio::steady_timer tick_;
  std::thread thread_;
  std::string token_, address_text_, bind_text_;
  uint16_t port_ = 0;
  const Srgb8Encoder encoder_;

  // Shared with the render's threads.
  std::mutex film_mu_;  // held while copying the film, never by I/O
  const render::Film* film_ = nullptr;
  uint32_t film_frame_ = 0;
  uint64_t last_merged_ = UINT64_MAX;
  std::shared_ptr<const FilmSnapshot> final_;
  std::mutex status_mu_;  // held for a copy only
  PreviewStatus status_;
  bool status_dirty_ = false;
  std::atomic<uint64_t> snapshots_{0}, frames_sent_{0}, frames_skipped_{0}, refused_{0};
  std::atomic<uint64_t> accept_failures_{0}, evicted_{0};
  std::atomic<int> viewers_{0};
  const Slot::Count connections_ = std::make_shared<std::atomic<int>>(0);
  const Slot::Count viewer_slots_ = std::make_shared<std::atomic<int>>(0);  // open or opening

  // The server's thread only.
  static constexpr int kMaxCopyShare = 20;
  std::chrono::steady_clock::duration last_copy_{};
  std::vector<std::shared_ptr<Viewer>> viewers_list_;
  // CurrentStatusJson's counts without a viewer.
  std::vector<uint32_t> counts_;
  int counts_width_ = 0;
  uint32_t counts_frame_ = 0;
  std::chrono::steady_clock::time_point counts_at_{};
  std::shared_ptr<const FilmSnapshot> latest_;
  std::shared_ptr<const std::string> latest_status_;
  bool said_full_ = false, said_accept_failed_ = false, said_evicting_ = false;  // each warned of once
  // Connections in the order they came, for EvictOldestIdle: those that ended or sent their
  // request are expired or no longer reading, and pruned as the list grows (Accepted).
  std::vector<std::weak_ptr<Request>> arrivals_;
};

// One WebSocket viewer. Sends the newest status and frame, one message at a time; a message
// that arrives while one is being written replaces the one waiting (frames are skipped, never
// queued). Reads the viewer's exposure ("exposure EV"), applied at the next tick.
class PreviewServer::Impl::Viewer : public std::enable_shared_from_this<Viewer> {
 public:
  Viewer(tcp::socket socket, Slot connection, Slot viewer, Impl* server)
      : connection_(std::move(connection)), viewer_(std::move(viewer)), ws_(std::move(socket)),
        server_(server), exposure_(server->exposure()) {}

  void Start(http::request<http::empty_body> req) {
    websocket::stream_base::timeout timeout{};
    timeout.handshake_timeout = std::chrono::seconds(10);
    // Pings at half of this; a viewer that stops answering (or reading) is closed.
    timeout.idle_timeout = std::chrono::seconds(60);
    timeout.keep_alive_pings = true;
    ws_.set_option(timeout);
    ws_.read_message_max(kMaxViewerMessageBytes);
    ws_.set_option(websocket::stream_base::decorator([](websocket::response_type& res) {
      res.set(http::field::server, "raystack-preview");
    }));
    ws_.async_accept(req, [self = shared_from_this()](const error_code& ec) {
      if (ec) return;
      self->open_ = true;
      self->server_->AddViewer(self);
      self->Read();
    });
  }

  void QueueFrame(std::shared_ptr<const FilmSnapshot> frame) {
    if (pending_frame_) server_->CountSkipped();
    pending_frame_ = std::move(frame);
    Pump();
  }
  void QueueStatus(std::shared_ptr<const std::string> status) {
    pending_status_ = std::move(status);
    Pump();
  }
  // On every tick: a changed exposure re-sends the frame on show (unless a newer one, which
  // will have it, is waiting). So a viewer costs at most one encoding per tick however often
  // it sends its exposure; the latest value wins.
  void ApplyExposure() {
    if (!exposure_changed_ || pending_frame_ || !shown_) return;
    pending_frame_ = shown_;
    Pump();
  }
  // Nothing is being written or waits to be (or the stream is closed).
  bool Sent() const { return !open_ || (!writing_ && !pending_status_ && !pending_frame_); }
  void Close() {
    open_ = false;
    error_code ec;
    beast::get_lowest_layer(ws_).socket().close(ec);
  }

 private:
  void Pump() {
    if (!open_ || writing_) return;
    if (pending_status_) {
      out_text_ = std::move(pending_status_);
      ws_.text(true);
      writing_ = true;
      ws_.async_write(asio::buffer(*out_text_), [self = shared_from_this()](const error_code& ec, size_t) {
        self->Written(ec, false);
      });
    } else if (pending_frame_) {
      shown_ = std::move(pending_frame_);
      EncodeFrame(*shown_, exposure_, server_->encoder(), &out_);
      exposure_changed_ = false;
      ws_.binary(true);
      writing_ = true;
      ws_.async_write(asio::buffer(out_), [self = shared_from_this()](const error_code& ec, size_t) {
        self->Written(ec, true);
      });
    }
  }
  void Written(const error_code& ec, bool frame) {
    writing_ = false;
    if (ec) return Drop();
    if (frame) server_->CountSent();
    Pump();
  }
  void Read() {
    ws_.async_read(in_, [self = shared_from_this()](const error_code& ec, size_t) {
      if (ec) return self->Drop();  // closed, timed out, or over kMaxViewerMessageBytes
      self->Heard(beast::buffers_to_string(self->in_.data()));
      self->in_.consume(self->in_.size());
      self->Read();
    });
  }
  // "exposure EV": noted only; re-encoding here cost a full frame per message.
  void Heard(const std::string& text) {
    constexpr std::string_view kExposure = "exposure ";
    if (!text.starts_with(kExposure)) return;
    char* end = nullptr;
    const float ev = std::strtof(text.c_str() + kExposure.size(), &end);
    if (end == text.c_str() + kExposure.size() || !(ev >= -32 && ev <= 32)) return;
    exposure_ = ev;
    exposure_changed_ = true;
  }
  void Drop() {
    if (!open_) return;
    Close();
    viewer_ = Slot();  // its handlers may linger a moment; its place is free at once
    server_->RemoveViewer(this);
  }

  Slot connection_;  // before ws_: given back once its socket is closed
  Slot viewer_;      // given back when dropped, or with the viewer if its handshake fails
  websocket::stream<beast::tcp_stream> ws_;
  Impl* server_;
  float exposure_;
  bool open_ = false, writing_ = false;
  bool exposure_changed_ = false;  // since the frame on show was encoded
  beast::flat_buffer in_;
  std::vector<uint8_t> out_;
  std::shared_ptr<const std::string> out_text_, pending_status_;
  std::shared_ptr<const FilmSnapshot> pending_frame_, shown_;
};

// One HTTP request: the page, the stream's upgrade, or a refusal; then the connection closes.
class PreviewServer::Impl::Request : public std::enable_shared_from_this<Request> {
 public:
  Request(tcp::socket socket, Slot connection, Impl* server)
      : connection_(std::move(connection)), stream_(std::move(socket)), server_(server) {}

  bool reading() const { return reading_; }

  // Closes the connection while it waits for its request, and hands over its place.
  Slot Evict() {
    reading_ = false;
    beast::close_socket(stream_);  // the pending read ends with operation_aborted
    return std::move(connection_);
  }

  void Start() {
    parser_.header_limit(kMaxRequestBytes);
    parser_.body_limit(0);  // GET only: a body is refused
    stream_.expires_after(kRequestTimeout);
    http::async_read(stream_, buffer_, parser_, [self = shared_from_this()](const error_code& ec, size_t) {
      self->Read(ec);
    });
  }

 private:
  void Read(const error_code& ec) {
    reading_ = false;
    if (ec == http::error::header_limit || ec == http::error::buffer_overflow)
      return Respond(http::status::request_header_fields_too_large, "request too large\n");
    if (ec == http::error::end_of_stream || ec == beast::error::timeout ||
        ec == asio::error::operation_aborted)
      return;
    if (ec) return Respond(http::status::bad_request, "bad request\n");
    Route(parser_.release());
  }

  void Route(http::request<http::empty_body> req) {
    const std::string_view target(req.target().data(), req.target().size());
    const size_t q = target.find('?');
    const std::string_view path = target.substr(0, q);
    const std::string_view query = q == std::string_view::npos ? std::string_view() : target.substr(q + 1);
    if (req.method() != http::verb::get)
      return Respond(http::status::method_not_allowed, "only GET\n");
    if (std::string why = server_->Refusal(req, query); !why.empty())
      return Respond(http::status::forbidden, std::move(why));
    if (path == "/") return Respond(http::status::ok, std::string(PageHtml()), "text/html; charset=utf-8");
    // The status the page shows, for scripts and curl (an operator had to write a WebSocket
    // client to read a job's progress).
    if (path == "/status.json")
      return Respond(http::status::ok, server_->CurrentStatusJson(), "application/json");
    if (path == "/ws" && websocket::is_upgrade(req)) {
      Slot viewer = server_->TakeViewerSlot();
      if (!viewer) return Respond(http::status::service_unavailable, "too many viewers\n");
      stream_.expires_never();  // the stream has timeouts of its own
      std::make_shared<Viewer>(stream_.release_socket(), std::move(connection_), std::move(viewer),
                               server_)
          ->Start(std::move(req));
      return;
    }
    Respond(http::status::not_found, "not found\n");
  }

  void Respond(http::status status, std::string body, const char* type = "text/plain; charset=utf-8") {
    if (status != http::status::ok) server_->CountRefused();
    response_.result(status);
    response_.version(11);
    response_.set(http::field::server, "raystack-preview");
    response_.set(http::field::content_type, type);
    response_.set(http::field::cache_control, "no-store");
    response_.set("X-Content-Type-Options", "nosniff");
    response_.set("Referrer-Policy", "no-referrer");  // the token stays out of Referer headers
    // The page runs its own inline script and talks to its own server, nothing else; no
    // other site may frame it.
    response_.set("Content-Security-Policy",
                  "default-src 'none'; script-src 'unsafe-inline'; style-src 'unsafe-inline'; "
                  "connect-src 'self'; base-uri 'none'; form-action 'none'; frame-ancestors 'none'");
    response_.set(http::field::connection, "close");
    response_.body() = std::move(body);
    response_.prepare_payload();
    stream_.expires_after(kRequestTimeout);
    http::async_write(stream_, response_, [self = shared_from_this()](const error_code&, size_t) {
      error_code ignored;
      self->stream_.socket().shutdown(tcp::socket::shutdown_send, ignored);
    });
  }

  Slot connection_;  // before stream_: given back once its socket is closed
  beast::tcp_stream stream_;
  Impl* server_;
  bool reading_ = true;  // its request not read yet (nor evicted)
  beast::flat_buffer buffer_{kMaxRequestBytes};
  http::request_parser<http::empty_body> parser_;
  http::response<http::string_body> response_;
};

void PreviewServer::Impl::Accept() {
  acceptor_.async_accept([this](const error_code& ec, tcp::socket socket) {
    if (ec == asio::error::operation_aborted) return;  // closing
    if (ec) return AcceptFailed(ec);
    Accepted(std::move(socket));
    Accept();
  });
}

// Every connection takes a file descriptor until it closes, in whatever state it is, so the
// server holds at most kMaxConnections, and clients never take the descriptors the render
// needs to write its image. Past them, a new connection takes the place of the one that has
// waited longest without sending its request (idle ones are otherwise kept up to
// kRequestTimeout): clients that connect and send nothing cannot keep viewers out. Only when
// every connection held has sent its request is a new one closed at once.
void PreviewServer::Impl::Accepted(tcp::socket socket) {
  Slot slot = Slot::Take(connections_, kMaxConnections);
  if (!slot) slot = EvictOldestIdle();
  if (!slot) {
    CountRefused();
    if (!std::exchange(said_full_, true))
      LOG_WARNING("preview", "%d connections open, the most the preview holds, all of them served: "
                  "further ones are closed at once (counted as refused)", kMaxConnections);
    error_code ignored;
    socket.close(ignored);
    return;
  }
  auto request = std::make_shared<Request>(std::move(socket), std::move(slot), this);
  if (arrivals_.size() >= 2 * static_cast<size_t>(kMaxConnections)) {
    std::erase_if(arrivals_, [](const std::weak_ptr<Request>& w) {
      const auto r = w.lock();
      return !r || !r->reading();
    });
  }
  arrivals_.push_back(request);
  request->Start();
}

Slot PreviewServer::Impl::EvictOldestIdle() {
  for (std::weak_ptr<Request>& w : arrivals_) {
    const auto r = w.lock();
    if (!r || !r->reading()) continue;
    w.reset();
    evicted_.fetch_add(1);
    if (!std::exchange(said_evicting_, true))
      LOG_WARNING("preview", "%d connections open, the most the preview holds: the one idle longest "
                  "is closed to make room for each new one", kMaxConnections);
    return r->Evict();
  }
  return Slot();
}

// The connection that failed (out of file descriptors, most likely) is still waiting, so
// accepting again at once would fail again at once, and spin: wait a little first.
void PreviewServer::Impl::AcceptFailed(const error_code& ec) {
  accept_failures_.fetch_add(1);
  if (!std::exchange(said_accept_failed_, true))
    LOG_WARNING("preview", "cannot accept a connection: %s; trying again every %d ms",
                ec.message().c_str(), kAcceptRetryMs);
  accept_retry_.expires_after(std::chrono::milliseconds(kAcceptRetryMs));
  accept_retry_.async_wait([this](const error_code& wait_ec) {
    if (!wait_ec) Accept();
  });
}

void PreviewServer::Impl::AddViewer(const std::shared_ptr<Viewer>& v) {
  viewers_list_.push_back(v);
  viewers_.store(static_cast<int>(viewers_list_.size()));
  // A new viewer gets what the others have: the current image, at once.
  if (latest_status_) v->QueueStatus(latest_status_);
  if (latest_) v->QueueFrame(latest_);
}

void PreviewServer::Impl::RemoveViewer(const Viewer* v) {
  std::erase_if(viewers_list_, [v](const std::shared_ptr<Viewer>& p) { return p.get() == v; });
  viewers_.store(static_cast<int>(viewers_list_.size()));
}

void PreviewServer::Impl::CloseViewers() {
  const std::vector<std::shared_ptr<Viewer>> all = std::move(viewers_list_);
  viewers_list_.clear();
  for (const auto& v : all) v->Close();
  viewers_.store(0);
}

void PreviewServer::Impl::Refresh() {
  std::shared_ptr<const FilmSnapshot> fresh;
  {
    std::lock_guard lock(film_mu_);
    if (final_) {
      fresh = std::move(final_);
      final_.reset();
    } else if (film_ != nullptr && !viewers_list_.empty()) {
      // Only when it changed: a paused render costs nothing.
      const uint64_t merged = film_->samples_merged();
      if (merged != last_merged_) {
        // The film's lock only (not the new snapshot's allocation, which merges do not wait
        // for: counting it slowed a 960 x 540 preview to a frame every 1.5-3 s here).
        fresh = std::make_shared<const FilmSnapshot>(TakeSnapshot(*film_, film_frame_, &last_copy_));
        snapshots_.fetch_add(1);
        last_merged_ = merged;
      }
    }
  }
  if (fresh) latest_ = fresh;
  std::optional<PreviewStatus> status;
  {
    std::lock_guard lock(status_mu_);
    if (status_dirty_) status = status_;
    status_dirty_ = false;
  }
  if (status) {
    const bool same_frame = latest_ && latest_->frame == status->frame;
    latest_status_ = std::make_shared<const std::string>(
        StatusJson(*status, same_frame ? latest_->width : 0,
                   same_frame ? latest_->counts : std::vector<uint32_t>()));
  }
  // Copied: a write that fails removes its viewer from the list.
  const std::vector<std::shared_ptr<Viewer>> all = viewers_list_;
  for (const auto& v : all) {
    if (status) v->QueueStatus(latest_status_);
    if (fresh) v->QueueFrame(fresh);
    v->ApplyExposure();
  }
}

void PreviewServer::Impl::Drain(double seconds) {
  if (!thread_.joinable()) return;
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::duration<double>(seconds);
  asio::post(ioc_, [this] { Refresh(); });  // what was published last is queued first
  for (;;) {
    // Shared: a server thread that is gone (or late) must not answer into a finished call.
    auto sent = std::make_shared<std::promise<bool>>();
    std::future<bool> answer = sent->get_future();
    asio::post(ioc_, [this, sent] {
      sent->set_value(std::all_of(viewers_list_.begin(), viewers_list_.end(),
                                  [](const std::shared_ptr<Viewer>& v) { return v->Sent(); }));
    });
    if (answer.wait_until(deadline) != std::future_status::ready || answer.get()) return;
    if (std::chrono::steady_clock::now() >= deadline) return;
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
}

// ---------------------------------------------------------------------------------------------

Expected<std::unique_ptr<PreviewServer>> PreviewServer::Start(const ServerOptions& options) {
  error_code ec;
  const asio::ip::address address = asio::ip::make_address(options.bind, ec);
  if (ec)
    return Status::Error("--preview-bind: '" + options.bind + "' is not an IP address (" +
                         (options.bind == "localhost" ? std::string("127.0.0.1 or ::1")
                                                      : std::string("e.g. 127.0.0.1, 0.0.0.0 or ::")) +
                         ")");
  auto impl = std::make_unique<Impl>(options, address);
  RAYSTACK_RETURN_IF_ERROR(impl->Listen(address));
  impl->Run();
  return std::unique_ptr<PreviewServer>(new PreviewServer(std::move(impl)));
}

PreviewServer::PreviewServer(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
PreviewServer::~PreviewServer() { Stop(); }
uint16_t PreviewServer::port() const { return impl_->port(); }
const std::string& PreviewServer::token() const { return impl_->token(); }
const std::string& PreviewServer::address() const { return impl_->address(); }
std::string PreviewServer::Url() const { return impl_->Url(); }
void PreviewServer::AttachFilm(const render::Film* film, uint32_t frame) { impl_->AttachFilm(film, frame); }
void PreviewServer::DetachFilm() { impl_->DetachFilm(); }
void PreviewServer::Publish(const PreviewStatus& status) { impl_->Publish(status); }
void PreviewServer::Hold(double seconds) { impl_->Hold(seconds); }
void PreviewServer::Drain(double seconds) { impl_->Drain(seconds); }
void PreviewServer::Stop() { impl_->Stop(); }
ServerCounters PreviewServer::counters() const { return impl_->counters(); }

}  // namespace raystack::master::preview
