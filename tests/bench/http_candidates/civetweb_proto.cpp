// civetweb 1.15: WebSocket fan-out of binary snapshots to kClients browsers, then mg_stop with them connected.
#include <civetweb.h>

#include <mutex>
#include <set>
#include <thread>

#include "common.hpp"

std::mutex g_mutex;
std::set<mg_connection*> g_clients;

int main(int argc, char** argv) {
    mg_init_library(0);
    const std::string port = "127.0.0.1:" + std::to_string(portArg(argc, argv));
    const char* options[] = {"listening_ports", port.c_str(), "num_threads", "32", nullptr};
    mg_callbacks callbacks{};
    mg_context* ctx = mg_start(&callbacks, nullptr, options);
    if (!ctx) return 1;
    mg_set_websocket_handler(
        ctx, "/ws", [](const mg_connection*, void*) { return 0; },
        [](mg_connection* c, void*) {
            std::lock_guard l(g_mutex);
            g_clients.insert(c);
        },
        [](mg_connection*, int flags, char*, size_t, void*) {
            return (flags & 0xf) == MG_WEBSOCKET_OPCODE_CONNECTION_CLOSE ? 0 : 1;
        },
        [](const mg_connection* c, void*) {
            std::lock_guard l(g_mutex);
            g_clients.erase(const_cast<mg_connection*>(c));
        },
        nullptr);
    while (true) {
        {
            std::lock_guard l(g_mutex);
            if (g_clients.size() >= kClients) break;
        }
        std::this_thread::sleep_for(std::chrono::milliseconds(5));
    }
    const auto data = payload();
    const auto t0 = std::chrono::steady_clock::now();
    for (int m = 0; m < kMessages; ++m) {
        std::lock_guard l(g_mutex);
        for (mg_connection* c : g_clients) {
            mg_lock_connection(c);
            mg_websocket_write(c, MG_WEBSOCKET_OPCODE_BINARY, reinterpret_cast<const char*>(data.data()), data.size());
            mg_unlock_connection(c);
        }
    }
    std::printf("server: pushed %d x %zu B to %d clients in %.1f ms\n", kMessages, data.size(), kClients, msSince(t0));
    std::this_thread::sleep_for(std::chrono::milliseconds(300));
    const auto s0 = std::chrono::steady_clock::now();
    {
        std::lock_guard l(g_mutex);  // a close frame first: the browsers' read loops end at once
        for (mg_connection* c : g_clients) mg_websocket_write(c, MG_WEBSOCKET_OPCODE_CONNECTION_CLOSE, "", 0);
    }
    mg_stop(ctx);
    std::printf("server: stop with clients connected took %.1f ms\n", msSince(s0));
}
