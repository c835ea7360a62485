// A minimal Chrome DevTools protocol client for the browser test: one WebSocket (RFC 6455,
// client side: text frames, masked; no extensions) to a page target, JSON commands by id.
// Events are read and dropped.
#pragma once

#include <arpa/inet.h>
#include <netinet/in.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <chrono>
#include <cstring>
#include <nlohmann/json.hpp>
#include <random>
#include <string>

namespace macro::test {

class DevTools {
 public:
  ~DevTools() {
    if (fd_ >= 0) ::close(fd_);
  }
  // ws://127.0.0.1:PORT/devtools/page/ID
  bool connect(const std::string& url, std::string* error) {
    const std::string prefix = "ws://127.0.0.1:";
    if (url.rfind(prefix, 0) != 0) return fail(error, "unexpected DevTools URL " + url);
    const int port = std::atoi(url.c_str() + prefix.size());
    const std::string path = url.substr(url.find('/', prefix.size()));
    fd_ = ::socket(AF_INET, SOCK_STREAM, 0);
    sockaddr_in a{};
    a.sin_family = AF_INET;
    a.sin_port = htons(uint16_t(port));
    a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    if (::connect(fd_, reinterpret_cast<sockaddr*>(&a), sizeof a) != 0)
      return fail(error, "cannot connect to " + url);
    const std::string req = "GET " + path + " HTTP/1.1\r\nHost: 127.0.0.1:" + std::to_string(port) +
                            "\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n"
                            "Sec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\n"
                            "Sec-WebSocket-Version: 13\r\n\r\n";
    if (!send_all(req.data(), req.size())) return fail(error, "handshake send failed");
    std::string head;
    while (head.find("\r\n\r\n") == std::string::npos) {
      char c;
      if (!recv_all(&c, 1, 10000)) return fail(error, "no handshake reply");
      head += c;
    }
    if (head.find(" 101 ") == std::string::npos) return fail(error, "handshake refused: " + head);
    return true;
  }

  // Sends a command and waits for its reply (the "result" object, or an "error" one).
  nlohmann::json call(const std::string& method,
                      const nlohmann::json& params = nlohmann::json::object(),
                      int timeout_ms = 20000) {
    const int id = ++next_id_;
    const std::string msg =
        nlohmann::json({{"id", id}, {"method", method}, {"params", params}}).dump();
    if (!send_frame(msg)) return {{"error", "send failed"}};
    const auto end = std::chrono::steady_clock::now() + std::chrono::milliseconds(timeout_ms);
    for (;;) {
      const int left = int(std::chrono::duration_cast<std::chrono::milliseconds>(
                               end - std::chrono::steady_clock::now())
                               .count());
      if (left <= 0) return {{"error", "timeout waiting for " + method}};
      std::string text;
      if (!recv_message(&text, left)) return {{"error", "connection lost during " + method}};
      auto j = nlohmann::json::parse(text, nullptr, false);
      if (j.is_discarded() || !j.contains("id") || j["id"] != id) continue;  // an event
      if (j.contains("error")) return {{"error", j["error"].dump()}};
      return j["result"];
    }
  }

  // Runtime.evaluate of an expression (promises awaited); the value, or {"error": ...}.
  nlohmann::json eval(const std::string& expr, int timeout_ms = 20000) {
    nlohmann::json r =
        call("Runtime.evaluate",
             {{"expression", expr}, {"returnByValue", true}, {"awaitPromise", true}}, timeout_ms);
    if (r.contains("error")) return r;
    if (r.contains("exceptionDetails")) return {{"error", r["exceptionDetails"].dump()}};
    return r["result"].contains("value") ? r["result"]["value"] : nlohmann::json();
  }

  // Polls `expr` until it is true (every 50 ms, up to timeout).
  bool wait_true(const std::string& expr, int timeout_ms) {
    const auto end = std::chrono::steady_clock::now() + std::chrono::milliseconds(timeout_ms);
    while (std::chrono::steady_clock::now() < end) {
      const nlohmann::json v = eval("!!(" + expr + ")");
      if (v.is_boolean() && v.get<bool>()) return true;
      ::usleep(50000);
    }
    return false;
  }

 private:
  static bool fail(std::string* error, const std::string& m) {
    if (error) *error = m;
    return false;
  }
  bool send_all(const void* p, size_t n) {
    const char* c = static_cast<const char*>(p);
    while (n) {
      const ssize_t w = ::send(fd_, c, n, MSG_NOSIGNAL);
      if (w <= 0) return false;
      c += w;
      n -= size_t(w);
    }
    return true;
  }
  bool recv_all(void* p, size_t n, int timeout_ms) {
    char* c = static_cast<char*>(p);
    while (n) {
      pollfd pfd{fd_, POLLIN, 0};
      if (::poll(&pfd, 1, timeout_ms) <= 0) return false;
      const ssize_t r = ::recv(fd_, c, n, 0);
      if (r <= 0) return false;
      c += r;
      n -= size_t(r);
    }
    return true;
  }
  bool send_frame(const std::string& payload) {
    std::string f;
    f += char(0x81);  // FIN, text
    const size_t n = payload.size();
    if (n < 126) {
      f += char(0x80 | n);
    } else if (n < 65536) {
      f += char(0x80 | 126);
      f += char(n >> 8);
      f += char(n & 0xff);
    } else {
      f += char(0x80 | 127);
      for (int i = 7; i >= 0; --i) f += char((uint64_t(n) >> (8 * i)) & 0xff);
    }
    uint8_t mask[4];
    for (uint8_t& m : mask) m = uint8_t(rng_());
    f.append(reinterpret_cast<char*>(mask), 4);
    for (size_t i = 0; i < n; ++i) f += char(payload[i] ^ mask[i % 4]);
    return send_all(f.data(), f.size());
  }
  // One whole message (fragments joined); control frames answered or skipped.
  bool recv_message(std::string* out, int timeout_ms) {
    out->clear();
    for (;;) {
      uint8_t h[2];
      if (!recv_all(h, 2, timeout_ms)) return false;
      const int opcode = h[0] & 0x0f;
      uint64_t n = h[1] & 0x7f;
      if (n == 126) {
        uint8_t e[2];
        if (!recv_all(e, 2, timeout_ms)) return false;
        n = (uint64_t(e[0]) << 8) | e[1];
      } else if (n == 127) {
        uint8_t e[8];
        if (!recv_all(e, 8, timeout_ms)) return false;
        n = 0;
        for (uint8_t b : e) n = (n << 8) | b;
      }
      uint8_t mask[4] = {0, 0, 0, 0};
      const bool masked = h[1] & 0x80;
      if (masked && !recv_all(mask, 4, timeout_ms)) return false;
      std::string data(size_t(n), '\0');
      if (n && !recv_all(data.data(), size_t(n), timeout_ms)) return false;
      if (masked)
        for (size_t i = 0; i < data.size(); ++i) data[i] = char(data[i] ^ mask[i % 4]);
      if (opcode == 8) return false;              // close
      if (opcode == 9 || opcode == 10) continue;  // ping / pong: Chromium sends none unasked
      *out += data;
      if (h[0] & 0x80) return true;
    }
  }
  int fd_ = -1;
  int next_id_ = 0;
  std::mt19937 rng_{12345};
};

}  // namespace macro::test
