#pragma once
// The live preview (issue 5): an HTTP page and a WebSocket stream served by Boost.Beast on a
// thread of its own. Open http://HOST:PORT/ and watch the film refine; the page fills pixels
// not computed yet from their nearest computed quadtree ancestor (thesis Fig. VI.11).
//
// The render never waits for a viewer: it only hands over a status (Publish: a small copy
// under a lock that no I/O ever holds) and the film to look at (AttachFilm/DetachFilm, once
// per frame). The server's thread copies the film every kRefreshMs while someone watches (less
// often on a film so large that copying it would hold the film's lock over 5% of the time), and each viewer holds at most one frame waiting to be sent: a newer one replaces
// it, so a slow or stalled viewer skips frames and costs nothing else.
//
// Served: exactly "/" (the page) and "/ws" (the stream); everything else is 404, requests over
// kMaxRequestBytes are refused (431), viewer messages over kMaxViewerMessageBytes close the
// stream. The server holds at most kMaxConnections connections at a time, whatever their state
// (a request being read or answered, a stream), so that clients cannot take the file
// descriptors the render needs to write its image: beyond them a new one takes the place of
// the one idle longest (connected, its request not sent), or is closed at once if none is.
// Bound to a loopback address, a request must name a loopback host (no DNS
// rebinding); on any other address a random token printed at start is required on both
// (?token=...), and a request without it gets 403.

#include <cstdint>
#include <memory>
#include <string>

#include "common/base/status.h"
#include "common/render/film.h"
#include "master/preview/preview_status.h"

namespace raystack::master::preview {

inline constexpr int kRefreshMs = 200;
inline constexpr size_t kMaxRequestBytes = 8192;
inline constexpr size_t kMaxViewerMessageBytes = 256;
inline constexpr int kMaxViewers = 16;
inline constexpr int kMaxConnections = 64;  // of which at most kMaxViewers streams
// After a failed accept (e.g. out of file descriptors), wait this long before the next one:
// the pending connection stays pending, so trying again at once would spin.
inline constexpr int kAcceptRetryMs = 100;

struct ServerOptions {
  std::string bind = "127.0.0.1";
  uint16_t port = 0;      // 0: a free port chosen by the system (see port())
  float exposure = 0;     // EV a new viewer starts with (the page can change its own)
};

// Figures for tests and the end-of-job log.
struct ServerCounters {
  uint64_t snapshots = 0;       // film copies taken
  uint64_t frames_sent = 0;     // frame messages written to viewers
  uint64_t frames_skipped = 0;  // replaced while waiting for a slow viewer
  uint64_t refused = 0;         // requests answered 403, 404, 405, 431 or 503, and
                                // connections closed at once beyond kMaxConnections
  uint64_t evicted = 0;         // idle connections closed to make room for new ones
  uint64_t accept_failures = 0;  // accepts that failed (each followed by kAcceptRetryMs)
  int viewers = 0;              // open streams now
  int connections = 0;          // connections held now (streams included)
};

class PreviewServer {
 public:
  // Listens and starts the server's thread. Fails (naming the address) when the address is
  // not an IP address or cannot be bound.
  static Expected<std::unique_ptr<PreviewServer>> Start(const ServerOptions& options);
  ~PreviewServer();  // Stop()

  uint16_t port() const;
  // Empty when the bind address is loopback (no token needed).
  const std::string& token() const;
  // The address listened on, as in a URL ("127.0.0.1", "[::1]", "0.0.0.0").
  const std::string& address() const;
  // The address to open, with the token when one is needed.
  std::string Url() const;

  // The film of frame `frame` to show from now on (it must stay alive until DetachFilm).
  // Waits at most for one copy in progress. Any thread.
  void AttachFilm(const render::Film* film, uint32_t frame);
  // Takes the film's final copy (shown until the next AttachFilm) and lets go of it.
  void DetachFilm();
  // The latest status; cheap and never blocks on a viewer. Any thread.
  void Publish(const PreviewStatus& status);
  // Keeps serving for `seconds`, or until SIGINT or SIGTERM (to leave the final image up).
  void Hold(double seconds);
  // Waits until every viewer has been sent the latest status and image, or `seconds` at most
  // (a slow viewer is not waited for longer): before Stop, so the end reaches the pages.
  void Drain(double seconds);
  // Closes every connection and joins the server's thread. Idempotent.
  void Stop();

  ServerCounters counters() const;

 private:
  class Impl;
  explicit PreviewServer(std::unique_ptr<Impl> impl);
  std::unique_ptr<Impl> impl_;
};

}  // namespace raystack::master::preview
