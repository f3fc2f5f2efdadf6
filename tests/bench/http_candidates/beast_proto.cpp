// Boost.Beast (Boost 1.81): a synchronous WebSocket server, one thread per client, fan-out through a mailbox.
#include <boost/asio.hpp>
#include <boost/beast/core.hpp>
#include <boost/beast/websocket.hpp>
#include <condition_variable>
#include <list>
#include <mutex>
#include <thread>

#include "common.hpp"

namespace net = boost::asio;
namespace ws = boost::beast::websocket;
using tcp = net::ip::tcp;

std::mutex g_mutex;
std::condition_variable g_cv;
int g_seq = 0, g_connected = 0;
bool g_stopping = false;

int main(int argc, char** argv) {
    net::io_context ioc;
    tcp::acceptor acceptor(ioc, {net::ip::make_address("127.0.0.1"), static_cast<unsigned short>(portArg(argc, argv))});
    const auto data = payload();
    std::list<std::thread> sessions;
    std::list<ws::stream<tcp::socket>> streams;
    std::thread accept_thread([&] {
        for (int i = 0; i < kClients; ++i) {
            tcp::socket socket(ioc);
            acceptor.accept(socket);
            std::lock_guard l(g_mutex);
            streams.emplace_back(std::move(socket));
            ws::stream<tcp::socket>& s = streams.back();
            sessions.emplace_back([&s, &data] {
                boost::beast::error_code ec;
                s.binary(true);
                s.accept(ec);
                if (ec) return;
                int sent = 0;
                {
                    std::lock_guard l2(g_mutex);
                    ++g_connected;
                }
                while (true) {
                    std::unique_lock l2(g_mutex);
                    g_cv.wait(l2, [&] { return g_stopping || g_seq > sent; });
                    if (g_stopping) break;
                    sent = g_seq;
                    l2.unlock();
                    s.write(net::buffer(data), ec);
                    if (ec) return;
                }
                s.close(ws::close_code::going_away, ec);
            });
        }
    });
    while (true) {
        {
            std::lock_guard l(g_mutex);
            if (g_connected >= kClients) break;
        }
        std::this_thread::sleep_for(std::chrono::milliseconds(5));
    }
    const auto t0 = std::chrono::steady_clock::now();
    for (int m = 0; m < kMessages; ++m) {
        {
            std::lock_guard l(g_mutex);
            ++g_seq;
        }
        g_cv.notify_all();
        std::this_thread::sleep_for(std::chrono::milliseconds(2));
    }
    std::printf("server: announced %d snapshots to %d clients in %.1f ms\n", kMessages, kClients, msSince(t0));
    std::this_thread::sleep_for(std::chrono::milliseconds(2000));
    const auto s0 = std::chrono::steady_clock::now();
    {
        std::lock_guard l(g_mutex);
        g_stopping = true;
    }
    g_cv.notify_all();
    accept_thread.join();
    for (auto& t : sessions) t.join();
    std::printf("server: stop with clients connected took %.1f ms\n", msSince(s0));
}
