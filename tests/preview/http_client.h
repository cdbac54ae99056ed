#pragma once
// A few blocking HTTP and WebSocket client calls for the preview server's tests (Beast).

#include <boost/asio.hpp>
#include <boost/beast/core.hpp>
#include <boost/beast/http.hpp>
#include <boost/beast/websocket.hpp>

#include <cstdint>
#include <memory>
#include <string>

namespace raystack::master::preview::testing {

namespace asio = boost::asio;
namespace beast = boost::beast;
namespace http = beast::http;
namespace websocket = beast::websocket;
using tcp = asio::ip::tcp;

// Sends `raw` (a whole request, as bytes) to 127.0.0.1:port and returns the response's status
// code, or -1 when the server closed without one.
inline int StatusOf(uint16_t port, const std::string& raw, std::string* body = nullptr) {
  asio::io_context ioc;
  tcp::socket socket(ioc);
  beast::error_code ec;
  socket.connect({asio::ip::make_address("127.0.0.1"), port}, ec);
  if (ec) return -1;
  asio::write(socket, asio::buffer(raw), ec);
  beast::flat_buffer buffer;
  http::response<http::string_body> res;
  http::read(socket, buffer, res, ec);
  if (body) *body = res.body();
  return ec ? -1 : static_cast<int>(res.result_int());
}

inline int Get(uint16_t port, const std::string& target, const std::string& host = "127.0.0.1",
               const std::string& extra_headers = "", std::string* body = nullptr) {
  return StatusOf(port, "GET " + target + " HTTP/1.1\r\nHost: " + host + "\r\n" + extra_headers +
                            "Connection: close\r\n\r\n", body);
}

// A WebSocket viewer on 127.0.0.1:port/ws (+ query). Open() false when the upgrade is refused.
class WsViewer {
 public:
  // `receive_buffer` > 0: a small kernel buffer, so that a viewer that never reads stalls the
  // server's writes after a few kilobytes instead of megabytes.
  bool Open(uint16_t port, const std::string& query = "", int receive_buffer = 0) {
    beast::error_code ec;
    ws_.next_layer().open(tcp::v4(), ec);
    if (receive_buffer > 0)
      ws_.next_layer().set_option(asio::socket_base::receive_buffer_size(receive_buffer), ec);
    ws_.next_layer().connect({asio::ip::make_address("127.0.0.1"), port}, ec);
    if (ec) return false;
    ws_.handshake("127.0.0.1:" + std::to_string(port), "/ws" + query, ec);
    return !ec;
  }
  // Reads one message; false on error. `binary` tells which kind it was.
  bool Read(std::string* text, bool* binary) {
    beast::flat_buffer b;
    beast::error_code ec;
    ws_.read(b, ec);
    if (ec) return false;
    *binary = ws_.got_binary();
    *text = beast::buffers_to_string(b.data());
    return true;
  }
  void Write(const std::string& text) {
    beast::error_code ec;
    ws_.text(true);
    ws_.write(asio::buffer(text), ec);
  }

 private:
  asio::io_context ioc_;
  websocket::stream<tcp::socket> ws_{ioc_};
};

}  // namespace raystack::master::preview::testing
