// The viewer's HTTP API as plain functions of (method, path, body) -> reply, so it is tested
// without sockets; view_server.h binds it to cpp-httplib. docs/viewer.md §2 lists the endpoints.
//
// Every error is a JSON body {"error": message} with a status that says what went wrong:
// 400 malformed JSON or a bad field (named), 404 an unknown camera, result or route, 405 a wrong
// method, 409 a job already running or a close-up name taken, 413 a frame or body over the
// limits, 500 a failure while rendering or writing. No request can stop the server.
#pragma once

#include <string>
#include <utility>
#include <vector>

#include "enhance/view/view_session.h"

namespace macro::enhance::view {

struct Reply {
  int status = 200;
  std::string content_type = "application/json";
  std::string body;
  std::vector<std::pair<std::string, std::string>> headers;
};

// Requests larger than this are refused (413) before they are parsed.
inline constexpr size_t kMaxRequestBytes = 1 << 20;

Reply handle_api(ViewSession& session, const std::string& method, const std::string& path,
                 const std::string& body);

Reply error_reply(int status, const std::string& message);

}  // namespace macro::enhance::view
