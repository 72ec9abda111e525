#pragma once
// WebServer: slamd-web's HTTP and WebSocket server (civetweb, Debian's libcivetweb-dev).
//
// HTTP GET serves a fixed set of files held in memory (the page, and three.js read from Debian's
// libjs-three at start). WebSocket connections on /ws receive what the owner sends them.
//
// Threads: civetweb's workers accept connections, serve files and read WebSocket frames; every
// page has a sender thread of its own that writes its queue, so a slow or stalled page delays
// only itself. When a page's queue holds more than max_queue_bytes, the queue is dropped and the
// page is listed by takeClientsNeedingFullState() again, as a new page is: it is sent the whole
// state instead of an unbounded backlog.
//
// The owner (one thread) calls, in its loop:
//   for (ClientId id : server.takeClientsNeedingFullState()) server.sendTo(id, model.fullState());
//   for (auto& message : model.takeBroadcast()) server.broadcast(message);
//   for (const ClientText& t : server.takeClientTexts()) ... (e.g. {"type":"request_full"})
// A page only receives broadcasts after its full state, so it never sees a change before the
// state it applies to.

#include <condition_variable>
#include <cstdint>
#include <deque>
#include <map>
#include <memory>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include "slamd/web/viewer_model.hpp"

struct mg_context;
struct mg_connection;

namespace slamd::web {

struct StaticFile {
  std::string content_type;
  std::string body;
};

using ClientId = std::uint64_t;

struct ClientText {
  ClientId client = 0;
  std::string text;
};

class WebServer {
 public:
  struct Options {
    std::string bind_address = "127.0.0.1";
    int port = 8080;  ///< 0: any free port (port() says which)
    std::size_t max_queue_bytes = 64u << 20;
    std::size_t max_clients = 16;
    std::size_t max_client_text_bytes = 64u << 10;  ///< longer texts from a page are dropped
  };

  /// Starts serving `files` (URL path -> file, e.g. "/" and "/viewer.js").
  /// Throws std::runtime_error naming the address when it cannot listen.
  WebServer(const Options& options, std::map<std::string, StaticFile> files);
  ~WebServer();
  WebServer(const WebServer&) = delete;
  WebServer& operator=(const WebServer&) = delete;

  int port() const { return port_; }
  std::string url() const;

  /// Pages that connected, or overflowed their queue, since the previous call.
  std::vector<ClientId> takeClientsNeedingFullState();
  /// Queues messages for one page (ignored if it has gone).
  void sendTo(ClientId client, const std::vector<OutgoingMessage>& messages);
  /// Queues a message for every page that has been sent its full state.
  void broadcast(const OutgoingMessage& message);
  /// Text frames the pages sent since the previous call.
  std::vector<ClientText> takeClientTexts();

  std::size_t clientCount() const;
  /// Pages whose queue overflowed since start.
  std::uint64_t overflows() const;
  std::uint64_t httpRequests() const;

 private:
  struct Client;

  static int handleHttp(mg_connection* connection, void* server);
  static int handleWebSocketConnect(const mg_connection* connection, void* server);
  static void handleWebSocketReady(mg_connection* connection, void* server);
  static int handleWebSocketData(mg_connection* connection, int flags, char* data, std::size_t size,
                                 void* server);
  static void handleWebSocketClose(const mg_connection* connection, void* server);
  void runSender(Client* client);
  void enqueueLocked(Client& client, const OutgoingMessage& message);

  Options options_;
  std::map<std::string, StaticFile> files_;
  mg_context* context_ = nullptr;
  int port_ = 0;

  mutable std::mutex mutex_;  // guards everything below; never held while writing to a socket
  std::map<const mg_connection*, std::shared_ptr<Client>> clients_;
  std::vector<ClientId> needing_full_state_;
  std::vector<ClientText> client_texts_;
  ClientId next_client_id_ = 1;
  std::uint64_t overflows_ = 0;
  std::uint64_t http_requests_ = 0;
};

}  // namespace slamd::web
