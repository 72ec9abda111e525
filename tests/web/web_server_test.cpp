// WebServer over real loopback sockets: files over HTTP, WebSocket pages that get their full
// state before any broadcast, texts from pages, slow pages that overflow, pages that leave.

#include "slamd/web/web_server.hpp"

#include <arpa/inet.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <unistd.h>

#include <chrono>
#include <thread>

#include <gtest/gtest.h>

namespace slamd::web {
namespace {

/// A blocking loopback TCP connection with a receive timeout.
class Connection {
 public:
  explicit Connection(int port) {
    fd_ = socket(AF_INET, SOCK_STREAM, 0);
    sockaddr_in address{};
    address.sin_family = AF_INET;
    address.sin_port = htons(static_cast<std::uint16_t>(port));
    address.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    timeval timeout{5, 0};
    setsockopt(fd_, SOL_SOCKET, SO_RCVTIMEO, &timeout, sizeof(timeout));
    connected_ = connect(fd_, reinterpret_cast<sockaddr*>(&address), sizeof(address)) == 0;
  }
  ~Connection() { close(fd_); }
  bool connected() const { return connected_; }
  void send(const std::string& bytes) {
    ASSERT_EQ(::send(fd_, bytes.data(), bytes.size(), MSG_NOSIGNAL),
              static_cast<ssize_t>(bytes.size()));
  }
  /// Exactly `size` bytes, or fewer on timeout or close.
  std::string receive(std::size_t size) {
    std::string out;
    char buffer[65536];
    while (out.size() < size) {
      const ssize_t n = recv(fd_, buffer, std::min(sizeof(buffer), size - out.size()), 0);
      if (n <= 0) break;
      out.append(buffer, static_cast<std::size_t>(n));
    }
    return out;
  }
  std::string receiveAll() {
    std::string out;
    char buffer[65536];
    ssize_t n;
    while ((n = recv(fd_, buffer, sizeof(buffer), 0)) > 0) out.append(buffer, n);
    return out;
  }
  std::string receiveHeaders() {
    std::string out;
    while (out.find("\r\n\r\n") == std::string::npos) {
      const std::string byte = receive(1);
      if (byte.empty()) break;
      out += byte;
    }
    return out;
  }

 private:
  int fd_ = -1;
  bool connected_ = false;
};

std::string httpGet(int port, const std::string& method, const std::string& path) {
  Connection connection(port);
  EXPECT_TRUE(connection.connected());
  connection.send(method + " " + path +
                  " HTTP/1.1\r\nHost: localhost\r\nConnection: close\r\n\r\n");
  return connection.receiveAll();
}

/// A WebSocket page: handshake, then frames.
class Page {
 public:
  explicit Page(int port) : connection_(port) {
    connection_.send(
        "GET /ws HTTP/1.1\r\nHost: localhost\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n"
        "Sec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\nSec-WebSocket-Version: 13\r\n\r\n");
    handshake_ = connection_.receiveHeaders();
  }
  bool upgraded() const { return handshake_.rfind("HTTP/1.1 101", 0) == 0; }

  struct Frame {
    int opcode = -1;  ///< -1: nothing arrived
    std::string payload;
  };
  Frame receiveFrame() {
    const std::string head = connection_.receive(2);
    if (head.size() < 2) return {};
    Frame frame;
    frame.opcode = static_cast<std::uint8_t>(head[0]) & 0xf;
    std::uint64_t size = static_cast<std::uint8_t>(head[1]) & 0x7f;
    if (size >= 126) {
      const std::string extended = connection_.receive(size == 126 ? 2 : 8);
      size = 0;
      for (char byte : extended) size = (size << 8) | static_cast<std::uint8_t>(byte);
    }
    frame.payload = connection_.receive(size);
    return frame;
  }
  void sendText(const std::string& text) {
    std::string frame;
    frame.push_back(static_cast<char>(0x81));
    frame.push_back(static_cast<char>(0x80 | text.size()));  // short texts only; masked
    const char mask[4] = {0x11, 0x22, 0x33, 0x44};
    frame.append(mask, 4);
    for (std::size_t i = 0; i < text.size(); ++i) frame.push_back(text[i] ^ mask[i % 4]);
    connection_.send(frame);
  }

 private:
  Connection connection_;
  std::string handshake_;
};

std::map<std::string, StaticFile> testFiles() {
  return {{"/", {"text/html; charset=utf-8", "<html>slamd</html>"}},
          {"/viewer.js", {"text/javascript", "console.log(1);"}}};
}

WebServer::Options anyPort() {
  WebServer::Options options;
  options.port = 0;
  return options;
}

template <typename Predicate>
bool waitUntil(Predicate predicate) {
  for (int i = 0; i < 500; ++i) {
    if (predicate()) return true;
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  return false;
}

OutgoingMessage textMessage(const std::string& payload) {
  return {OutgoingMessage::Kind::kText, payload};
}

TEST(WebServer, ServesItsFilesAndNothingElse) {
  WebServer server(anyPort(), testFiles());
  ASSERT_GT(server.port(), 0);
  const std::string page = httpGet(server.port(), "GET", "/");
  EXPECT_EQ(page.rfind("HTTP/1.1 200", 0), 0u) << page;
  EXPECT_NE(page.find("Content-Type: text/html"), std::string::npos);
  EXPECT_NE(page.find("<html>slamd</html>"), std::string::npos);
  EXPECT_NE(httpGet(server.port(), "GET", "/viewer.js").find("console.log(1);"), std::string::npos);
  EXPECT_EQ(httpGet(server.port(), "GET", "/../etc/passwd").find("root:"), std::string::npos);
  EXPECT_EQ(httpGet(server.port(), "GET", "/missing.js").rfind("HTTP/1.1 404", 0), 0u);
  EXPECT_EQ(httpGet(server.port(), "POST", "/").rfind("HTTP/1.1 405", 0), 0u);
  EXPECT_EQ(server.url(), "http://127.0.0.1:" + std::to_string(server.port()) + "/");
}

TEST(WebServer, APageGetsItsFullStateBeforeAnyBroadcastAndCanTalkBack) {
  WebServer server(anyPort(), testFiles());
  server.broadcast(textMessage("before anyone connected"));
  Page page(server.port());
  ASSERT_TRUE(page.upgraded());
  std::vector<ClientId> new_pages;
  ASSERT_TRUE(waitUntil([&] {
    auto taken = server.takeClientsNeedingFullState();
    new_pages.insert(new_pages.end(), taken.begin(), taken.end());
    return !new_pages.empty();
  }));
  ASSERT_EQ(new_pages.size(), 1u);
  server.broadcast(textMessage("not for a page without its state"));
  server.sendTo(new_pages[0], {textMessage("hello"), OutgoingMessage{OutgoingMessage::Kind::kBinary,
                                                                     std::string(200000, '\x01')}});
  server.broadcast(textMessage("change 1"));

  Page::Frame frame = page.receiveFrame();
  EXPECT_EQ(frame.opcode, 1);
  EXPECT_EQ(frame.payload, "hello");
  frame = page.receiveFrame();
  EXPECT_EQ(frame.opcode, 2);
  EXPECT_EQ(frame.payload.size(), 200000u);
  frame = page.receiveFrame();
  EXPECT_EQ(frame.payload, "change 1");

  page.sendText("{\"type\":\"request_full\"}");
  std::vector<ClientText> texts;
  ASSERT_TRUE(waitUntil([&] {
    texts = server.takeClientTexts();
    return !texts.empty();
  }));
  EXPECT_EQ(texts[0].client, new_pages[0]);
  EXPECT_EQ(texts[0].text, "{\"type\":\"request_full\"}");
  EXPECT_EQ(server.clientCount(), 1u);
}

TEST(WebServer, APageThatStopsReadingIsResentItsStateInsteadOfABacklog) {
  WebServer::Options options = anyPort();
  options.max_queue_bytes = 1u << 20;
  WebServer server(options, testFiles());
  Page stalled(server.port());
  ASSERT_TRUE(stalled.upgraded());
  std::vector<ClientId> pages;
  ASSERT_TRUE(waitUntil([&] {
    pages = server.takeClientsNeedingFullState();
    return !pages.empty();
  }));
  server.sendTo(pages[0], {textMessage("state")});
  // Far more than the socket buffers hold; the page reads nothing.
  const OutgoingMessage chunk{OutgoingMessage::Kind::kBinary, std::string(256 << 10, 'x')};
  for (int i = 0; i < 400 && server.overflows() == 0; ++i) {
    server.broadcast(chunk);
    std::this_thread::sleep_for(std::chrono::milliseconds(1));
  }
  EXPECT_GE(server.overflows(), 1u);
  EXPECT_EQ(server.takeClientsNeedingFullState(), pages);
}

TEST(WebServer, APageThatLeavesIsForgotten) {
  WebServer server(anyPort(), testFiles());
  {
    Page page(server.port());
    ASSERT_TRUE(page.upgraded());
    ASSERT_TRUE(waitUntil([&] { return server.clientCount() == 1; }));
    const auto pages = server.takeClientsNeedingFullState();
    ASSERT_EQ(pages.size(), 1u);
    server.sendTo(pages[0], {textMessage("state")});
  }
  EXPECT_TRUE(waitUntil([&] { return server.clientCount() == 0; }));
  server.broadcast(textMessage("to nobody"));
}

TEST(WebServer, AnAddressInUseIsAClearError) {
  WebServer first(anyPort(), testFiles());
  WebServer::Options same = anyPort();
  same.port = first.port();
  try {
    WebServer second(same, testFiles());
    FAIL() << "a second server listened on the same port";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("127.0.0.1:" + std::to_string(first.port())),
              std::string::npos)
        << e.what();
  }
}

}  // namespace
}  // namespace slamd::web
