// `macro view`'s HTTP server (cpp-httplib, Debian's libcpp-httplib): binds 127.0.0.1 only, serves
// the page from data/viewer/ (index.html, viewer.js, viewer.css; found through find_bundled_data,
// nothing fetched at run time) and the API of view_api.h. SIGINT / SIGTERM stop it cleanly: the
// listener closes, a running enhance job is waited for, and serve_view returns OK.
#pragma once

#include <functional>
#include <string>

#include "attention/runtime/status.h"
#include "enhance/view/view_session.h"

namespace macro::enhance::view {

struct ServeOptions {
  int port = 8080;         // 0 = any free port
  std::string viewer_dir;  // the page's files; empty = find_bundled_data("data/viewer")
  // Called once the socket listens, with the port (the CLI prints the address).
  std::function<void(int port)> on_listening;
};

// The folder holding the page (index.html), or an error naming where it was looked for.
Result<std::string> find_viewer_dir();

Status serve_view(ViewSession& session, const ServeOptions& options);

}  // namespace macro::enhance::view
