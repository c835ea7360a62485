// cpp-httplib binding of the viewer API, the page's static files and the clean stop on SIGINT
// (see view_server.h).
#include "enhance/view/view_server.h"

#include <fcntl.h>
#include <poll.h>
#include <unistd.h>

#include <httplib.h>
#include <csignal>
#include <cstring>
#include <thread>

#include "attention/runtime/bundled_data.h"
#include "attention/runtime/file_io.h"
#include "enhance/view/view_api.h"

namespace macro::enhance::view {
namespace {

// The self-pipe of the stop signal: the handler writes one byte (async-signal-safe), a watcher
// thread reads it and stops the server.
int g_stop_pipe[2] = {-1, -1};

void on_stop_signal(int) {
  const char b = 1;
  const ssize_t ignored = ::write(g_stop_pipe[1], &b, 1);
  (void)ignored;
}

struct StaticFile {
  const char* name;
  const char* type;
};
constexpr StaticFile kFiles[] = {{"index.html", "text/html; charset=utf-8"},
                                 {"viewer.js", "text/javascript; charset=utf-8"},
                                 {"viewer.css", "text/css; charset=utf-8"}};

void send(const Reply& r, httplib::Response& res) {
  res.status = r.status;
  for (const auto& [k, v] : r.headers) res.set_header(k, v);
  res.set_content(r.body, r.content_type);
}

}  // namespace

Result<std::string> find_viewer_dir() {
  const std::string dir =
      find_bundled_data("data/viewer", "MACRO_VIEWER_DIR",
                        [](const std::string& d) { return file_exists(d + "/index.html"); });
  if (!file_exists(dir + "/index.html"))
    return Status::error(
        "the viewer page was not found (looked for data/viewer/index.html beside "
        "the executable and above it; MACRO_VIEWER_DIR names another folder)");
  return dir;
}

Status serve_view(ViewSession& session, const ServeOptions& o) {
  std::string dir = o.viewer_dir;
  if (dir.empty()) {
    MACRO_ASSIGN_OR_RETURN(dir, find_viewer_dir());
  }
  // The page's files are read once: what is served cannot change under a running server.
  std::vector<std::pair<std::string, std::string>> files;
  for (const StaticFile& f : kFiles) {
    auto text = read_text_file(dir + "/" + f.name, 1 << 24);
    if (!text) return text.status().with_context("viewer page");
    files.push_back({f.name, *text});
  }
  if (o.port < 0 || o.port > 65535)
    return Status::error("--port: expected 0..65535, found " + std::to_string(o.port));

  httplib::Server server;
  server.set_payload_max_length(kMaxRequestBytes);
  server.set_read_timeout(10, 0);
  server.set_write_timeout(30, 0);
  for (size_t i = 0; i < files.size(); ++i) {
    const std::string route = i == 0 ? "/" : "/" + files[i].first;
    const std::string type = kFiles[i].type;
    const std::string* body = &files[i].second;
    server.Get(route, [body, type](const httplib::Request&, httplib::Response& res) {
      res.set_header("Cache-Control", "no-store");
      res.set_content(*body, type);
    });
  }
  auto api = [&session](const httplib::Request& req, httplib::Response& res) {
    try {
      send(handle_api(session, req.method, req.path, req.body), res);
    } catch (const std::exception& e) {  // a library bug must not take the server down
      send(error_reply(500, std::string("internal error: ") + e.what()), res);
    }
  };
  server.Get(R"(/api/.*)", api);
  server.Post(R"(/api/.*)", api);
  server.Put(R"(/api/.*)", api);
  server.Delete(R"(/api/.*)", api);
  server.set_error_handler([](const httplib::Request& req, httplib::Response& res) {
    if (!res.body.empty()) return;
    const char* what = res.status == 413   ? "request body over the limit"
                       : res.status == 404 ? "no such page"
                                           : "bad request";
    send(error_reply(res.status, req.method + " " + req.path + ": " + what), res);
  });

  const int port = o.port == 0 ? server.bind_to_any_port("127.0.0.1")
                               : (server.bind_to_port("127.0.0.1", o.port) ? o.port : -1);
  if (port <= 0)
    return Status::error("--port " + std::to_string(o.port) +
                         ": cannot listen on 127.0.0.1 (in use, or not allowed)");

  // Stop on SIGINT / SIGTERM: the handlers are ours while the server runs.
  if (::pipe(g_stop_pipe) != 0) return Status::error("view: cannot create a pipe");
  struct sigaction sa {
  }, old_int{}, old_term{};
  sa.sa_handler = on_stop_signal;
  sigemptyset(&sa.sa_mask);
  ::sigaction(SIGINT, &sa, &old_int);
  ::sigaction(SIGTERM, &sa, &old_term);
  const int quit_read = g_stop_pipe[0];
  int wake[2];
  if (::pipe(wake) != 0) return Status::error("view: cannot create a pipe");
  std::thread watcher([&server, quit_read, &wake] {
    pollfd fds[2] = {{quit_read, POLLIN, 0}, {wake[0], POLLIN, 0}};
    while (::poll(fds, 2, -1) < 0 && errno == EINTR) {
    }
    server.stop();
  });
  if (o.on_listening) o.on_listening(port);
  const bool ok = server.listen_after_bind();
  // listen returned (stopped by the watcher, or failed): release the watcher either way.
  const char b = 1;
  const ssize_t ignored = ::write(wake[1], &b, 1);
  (void)ignored;
  watcher.join();
  session.join_job();
  ::sigaction(SIGINT, &old_int, nullptr);
  ::sigaction(SIGTERM, &old_term, nullptr);
  for (int fd : {g_stop_pipe[0], g_stop_pipe[1], wake[0], wake[1]}) ::close(fd);
  g_stop_pipe[0] = g_stop_pipe[1] = -1;
  (void)ok;
  return Status::ok();
}

}  // namespace macro::enhance::view
