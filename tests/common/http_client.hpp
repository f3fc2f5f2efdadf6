// A small HTTP and WebSocket client for the web viewer's tests, over a real socket to 127.0.0.1, on CivetWeb's
// client API (the same package the viewer serves with: no HTTP parsing of our own), plus a raw exchange for
// malformed requests.
#pragma once

#include <arpa/inet.h>
#include <civetweb.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <unistd.h>

#include <chrono>
#include <condition_variable>
#include <map>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

namespace facescan::testing {

// CivetWeb's client functions need the library initialised once per process (it counts its users).
inline void initCivetweb() {
    static std::once_flag once;
    std::call_once(once, [] { mg_init_library(0); });
}

struct HttpResponse {
    int status = 0;                              // 0: no connection or no response
    std::map<std::string, std::string> headers;  // names as sent
    std::string body;
    std::string error;

    // A header's value ("" when absent).
    std::string header(const std::string& name) const {
        const auto it = headers.find(name);
        return it == headers.end() ? std::string() : it->second;
    }
};

// One request (GET unless told) with `Connection: close`; waits up to `timeout_ms` for the response.
inline HttpResponse httpRequest(uint16_t port, const std::string& path, const std::string& method = "GET",
                                const std::string& extra_headers = "", int timeout_ms = 30000) {
    initCivetweb();
    HttpResponse response;
    char error[256] = {};
    mg_connection* conn = mg_connect_client("127.0.0.1", port, 0, error, sizeof(error));
    if (!conn) {
        response.error = error;
        return response;
    }
    mg_printf(conn, "%s %s HTTP/1.1\r\nHost: 127.0.0.1:%u\r\nConnection: close\r\n%s\r\n", method.c_str(), path.c_str(),
              port, extra_headers.c_str());
    if (mg_get_response(conn, error, sizeof(error), timeout_ms) < 0) {
        response.error = error;
        mg_close_connection(conn);
        return response;
    }
    const mg_response_info* info = mg_get_response_info(conn);
    response.status = info->status_code;
    for (int i = 0; i < info->num_headers; ++i)
        response.headers[info->http_headers[i].name] = info->http_headers[i].value;
    char buf[65536];
    int n = 0;
    while ((n = mg_read(conn, buf, sizeof(buf))) > 0) response.body.append(buf, static_cast<size_t>(n));
    mg_close_connection(conn);
    return response;
}

// Sends `bytes` as they are over TCP and returns what comes back until the server closes (or `timeout_ms`).
inline std::string rawExchange(uint16_t port, const std::string& bytes, int timeout_ms = 5000) {
    const int fd = ::socket(AF_INET, SOCK_STREAM, 0);
    sockaddr_in addr{};
    addr.sin_family = AF_INET;
    addr.sin_port = htons(port);
    addr.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    std::string reply;
    if (::connect(fd, reinterpret_cast<sockaddr*>(&addr), sizeof(addr)) == 0) {
        timeval tv{timeout_ms / 1000, (timeout_ms % 1000) * 1000};
        ::setsockopt(fd, SOL_SOCKET, SO_RCVTIMEO, &tv, sizeof(tv));
        if (::send(fd, bytes.data(), bytes.size(), MSG_NOSIGNAL) == static_cast<ssize_t>(bytes.size())) {
            ::shutdown(fd, SHUT_WR);
            char buf[4096];
            ssize_t n = 0;
            while ((n = ::recv(fd, buf, sizeof(buf), 0)) > 0) reply.append(buf, static_cast<size_t>(n));
        }
    }
    ::close(fd);
    return reply;
}

// A WebSocket client that collects the messages it receives.
class WsClient {
 public:
    struct Message {
        bool binary = false;
        std::string data;
        std::chrono::steady_clock::time_point received;
    };

    explicit WsClient(uint16_t port, const char* origin = nullptr) {
        initCivetweb();
        char error[256] = {};
        conn_ = mg_connect_websocket_client("127.0.0.1", port, 0, error, sizeof(error), "/ws", origin, onData, onClose,
                                            this);
        if (!conn_) error_ = error;
    }
    ~WsClient() {
        if (conn_) mg_close_connection(conn_);
    }
    WsClient(const WsClient&) = delete;
    WsClient& operator=(const WsClient&) = delete;

    bool connected() const { return conn_ != nullptr; }
    const std::string& error() const { return error_; }
    bool send(const std::string& text) {
        return mg_websocket_client_write(conn_, MG_WEBSOCKET_OPCODE_TEXT, text.data(), text.size()) > 0;
    }
    // Waits until `done(messages)` holds or the timeout passes; returns whether it held.
    template <typename Pred>
    bool waitFor(Pred done, std::chrono::milliseconds timeout) {
        std::unique_lock lock(mutex_);
        return cv_.wait_for(lock, timeout, [&] { return done(messages_); });
    }
    std::vector<Message> messages() const {
        std::lock_guard lock(mutex_);
        return messages_;
    }
    bool closed() const {
        std::lock_guard lock(mutex_);
        return closed_;
    }
    bool waitClosed(std::chrono::milliseconds timeout) {
        std::unique_lock lock(mutex_);
        return cv_.wait_for(lock, timeout, [&] { return closed_; });
    }

 private:
    static int onData(mg_connection*, int flags, char* data, size_t size, void* self) {
        auto* client = static_cast<WsClient*>(self);
        const int opcode = flags & 0xf;
        if (opcode == MG_WEBSOCKET_OPCODE_TEXT || opcode == MG_WEBSOCKET_OPCODE_BINARY) {
            std::lock_guard lock(client->mutex_);
            client->messages_.push_back(
                {opcode == MG_WEBSOCKET_OPCODE_BINARY, std::string(data, size), std::chrono::steady_clock::now()});
        }
        client->cv_.notify_all();
        return opcode == MG_WEBSOCKET_OPCODE_CONNECTION_CLOSE ? 0 : 1;
    }
    static void onClose(const mg_connection*, void* self) {
        auto* client = static_cast<WsClient*>(self);
        {
            std::lock_guard lock(client->mutex_);
            client->closed_ = true;
        }
        client->cv_.notify_all();
    }

    mg_connection* conn_ = nullptr;
    std::string error_;
    mutable std::mutex mutex_;
    std::condition_variable cv_;
    std::vector<Message> messages_;
    bool closed_ = false;
};

// Polls `done` every 10 ms until it holds or the timeout passes.
template <typename Pred>
bool pollUntilTrue(Pred done, std::chrono::milliseconds timeout) {
    const auto deadline = std::chrono::steady_clock::now() + timeout;
    while (!done()) {
        if (std::chrono::steady_clock::now() > deadline) return false;
        std::this_thread::sleep_for(std::chrono::milliseconds(10));
    }
    return true;
}

}  // namespace facescan::testing
