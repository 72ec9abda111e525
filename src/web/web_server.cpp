#include "slamd/web/web_server.hpp"

#include <civetweb.h>

#include <algorithm>
#include <stdexcept>

#include "slamd/common/log.hpp"

namespace slamd::web {

struct WebServer::Client {
  ClientId id = 0;
  mg_connection* connection = nullptr;
  std::deque<OutgoingMessage> queue;
  std::size_t queued_bytes = 0;
  bool full_state_sent = false;  ///< broadcasts are queued only after the full state
  bool closing = false;          ///< the connection is going: the sender stops
  std::condition_variable wake;
  std::thread sender;
};

namespace {

/// civetweb's library state is process-wide; initialised once for every server.
void initialiseCivetweb() {
  static const bool initialised = [] {
    mg_init_library(MG_FEATURES_WEBSOCKET);
    return true;
  }();
  (void)initialised;
}

}  // namespace

WebServer::WebServer(const Options& options, std::map<std::string, StaticFile> files)
    : options_(options), files_(std::move(files)) {
  initialiseCivetweb();
  const std::string listening = options_.bind_address + ":" + std::to_string(options_.port);
  const std::string threads = std::to_string(options_.max_clients + 4);
  // A page sends client_stats every second, so a read timeout means a page that has gone; the
  // ping keeps an idle but alive page connected.
  const char* configuration[] = {"listening_ports",
                                 listening.c_str(),
                                 "num_threads",
                                 threads.c_str(),
                                 "websocket_timeout_ms",
                                 "10000",
                                 "enable_websocket_ping_pong",
                                 "yes",
                                 "request_timeout_ms",
                                 "10000",
                                 nullptr};
  mg_callbacks callbacks{};
  mg_init_data init{};
  init.callbacks = &callbacks;
  init.user_data = this;
  init.configuration_options = configuration;
  char error_text[256] = "";
  unsigned error_code = 0;
  mg_error_data error{};
  error.code = &error_code;
  error.text = error_text;
  error.text_buffer_size = sizeof(error_text);
  context_ = mg_start2(&init, &error);
  if (context_ == nullptr) {
    throw std::runtime_error("cannot serve HTTP on " + listening + ": " +
                             (error_text[0] ? error_text : "civetweb failed to start"));
  }
  mg_server_port ports[4] = {};
  if (mg_get_server_ports(context_, 4, ports) > 0) port_ = ports[0].port;
  mg_set_request_handler(context_, "/", &WebServer::handleHttp, this);
  mg_set_websocket_handler(context_, "/ws", &WebServer::handleWebSocketConnect,
                           &WebServer::handleWebSocketReady, &WebServer::handleWebSocketData,
                           &WebServer::handleWebSocketClose, this);
}

WebServer::~WebServer() {
  // Closes every connection; each close handler stops and joins its page's sender.
  mg_stop(context_);
}

std::string WebServer::url() const {
  const std::string host =
      options_.bind_address == "0.0.0.0" ? std::string("localhost") : options_.bind_address;
  return "http://" + host + ":" + std::to_string(port_) + "/";
}

int WebServer::handleHttp(mg_connection* connection, void* server_pointer) {
  auto* server = static_cast<WebServer*>(server_pointer);
  const mg_request_info* request = mg_get_request_info(connection);
  {
    std::lock_guard<std::mutex> lock(server->mutex_);
    ++server->http_requests_;
  }
  const std::string method = request->request_method ? request->request_method : "";
  const std::string path = request->local_uri ? request->local_uri : "";
  if (method != "GET" && method != "HEAD") {
    mg_send_http_error(connection, 405, "%s", "only GET and HEAD are served\n");
    return 405;
  }
  const auto file = server->files_.find(path == "/index.html" ? "/" : path);
  if (file == server->files_.end()) {
    mg_send_http_error(connection, 404, "%s is not served here\n", path.c_str());
    return 404;
  }
  mg_printf(connection,
            "HTTP/1.1 200 OK\r\nContent-Type: %s\r\nContent-Length: %zu\r\n"
            "Cache-Control: no-cache\r\nConnection: close\r\n\r\n",
            file->second.content_type.c_str(), file->second.body.size());
  if (method == "GET") mg_write(connection, file->second.body.data(), file->second.body.size());
  return 200;
}

int WebServer::handleWebSocketConnect(const mg_connection*, void* server_pointer) {
  auto* server = static_cast<WebServer*>(server_pointer);
  std::lock_guard<std::mutex> lock(server->mutex_);
  if (server->clients_.size() >= server->options_.max_clients) {
    SLAMD_LOG_WARN("slamd-web") << "refused a page: " << server->options_.max_clients
                                << " are connected already";
    return 1;  // non-zero: refuse
  }
  return 0;
}

void WebServer::handleWebSocketReady(mg_connection* connection, void* server_pointer) {
  auto* server = static_cast<WebServer*>(server_pointer);
  auto client = std::make_shared<Client>();
  client->connection = connection;
  std::lock_guard<std::mutex> lock(server->mutex_);
  client->id = server->next_client_id_++;
  server->clients_[connection] = client;
  server->needing_full_state_.push_back(client->id);
  client->sender = std::thread([server, raw = client.get()] { server->runSender(raw); });
}

int WebServer::handleWebSocketData(mg_connection* connection, int flags, char* data,
                                   std::size_t size, void* server_pointer) {
  auto* server = static_cast<WebServer*>(server_pointer);
  const int opcode = flags & 0xf;
  if (opcode == MG_WEBSOCKET_OPCODE_CONNECTION_CLOSE) return 0;
  if (opcode != MG_WEBSOCKET_OPCODE_TEXT) return 1;  // pings, pongs and binary: nothing to do
  std::lock_guard<std::mutex> lock(server->mutex_);
  const auto client = server->clients_.find(connection);
  if (client == server->clients_.end()) return 1;
  if (size > server->options_.max_client_text_bytes || server->client_texts_.size() > 1000) {
    return 1;  // a page that floods is ignored, not obeyed
  }
  server->client_texts_.push_back(ClientText{client->second->id, std::string(data, size)});
  return 1;
}

void WebServer::handleWebSocketClose(const mg_connection* connection, void* server_pointer) {
  auto* server = static_cast<WebServer*>(server_pointer);
  std::shared_ptr<Client> client;
  {
    std::lock_guard<std::mutex> lock(server->mutex_);
    const auto found = server->clients_.find(connection);
    if (found == server->clients_.end()) return;
    client = found->second;
    server->clients_.erase(found);
    client->closing = true;
    client->wake.notify_all();
  }
  // The connection is valid until this handler returns: its sender must be done with it first.
  if (client->sender.joinable()) client->sender.join();
}

void WebServer::runSender(Client* client) {
  std::unique_lock<std::mutex> lock(mutex_);
  while (true) {
    client->wake.wait(lock, [client] { return client->closing || !client->queue.empty(); });
    if (client->closing) return;
    OutgoingMessage message = std::move(client->queue.front());
    client->queue.pop_front();
    client->queued_bytes -= message.payload.size();
    lock.unlock();
    const int opcode = message.kind == OutgoingMessage::Kind::kBinary ? MG_WEBSOCKET_OPCODE_BINARY
                                                                      : MG_WEBSOCKET_OPCODE_TEXT;
    const int written = mg_websocket_write(client->connection, opcode, message.payload.data(),
                                           message.payload.size());
    lock.lock();
    if (written <= 0) {
      // The page has gone; civetweb's read loop notices too and calls the close handler.
      client->wake.wait(lock, [client] { return client->closing; });
      return;
    }
  }
}

void WebServer::enqueueLocked(Client& client, const OutgoingMessage& message) {
  if (client.queued_bytes + message.payload.size() > options_.max_queue_bytes) {
    // The page cannot keep up: drop its backlog and send it the whole state again instead.
    client.queue.clear();
    client.queued_bytes = 0;
    client.full_state_sent = false;
    ++overflows_;
    if (std::find(needing_full_state_.begin(), needing_full_state_.end(), client.id) ==
        needing_full_state_.end()) {
      needing_full_state_.push_back(client.id);
    }
    return;
  }
  client.queue.push_back(message);
  client.queued_bytes += message.payload.size();
  client.wake.notify_all();
}

std::vector<ClientId> WebServer::takeClientsNeedingFullState() {
  std::lock_guard<std::mutex> lock(mutex_);
  std::vector<ClientId> clients;
  clients.swap(needing_full_state_);
  return clients;
}

void WebServer::sendTo(ClientId id, const std::vector<OutgoingMessage>& messages) {
  std::lock_guard<std::mutex> lock(mutex_);
  for (auto& [connection, client] : clients_) {
    if (client->id != id) continue;
    client->full_state_sent = true;
    for (const OutgoingMessage& message : messages) {
      enqueueLocked(*client, message);
      if (!client->full_state_sent) break;  // overflowed: it is listed for a full state again
    }
    return;
  }
}

void WebServer::broadcast(const OutgoingMessage& message) {
  std::lock_guard<std::mutex> lock(mutex_);
  for (auto& [connection, client] : clients_) {
    if (client->full_state_sent) enqueueLocked(*client, message);
  }
}

std::vector<ClientText> WebServer::takeClientTexts() {
  std::lock_guard<std::mutex> lock(mutex_);
  std::vector<ClientText> texts;
  texts.swap(client_texts_);
  return texts;
}

std::size_t WebServer::clientCount() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return clients_.size();
}

std::uint64_t WebServer::overflows() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return overflows_;
}

std::uint64_t WebServer::httpRequests() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return http_requests_;
}

}  // namespace slamd::web
