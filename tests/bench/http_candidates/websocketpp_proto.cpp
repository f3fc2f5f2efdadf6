// websocketpp 0.8.2 on Boost.Asio: WebSocket fan-out, then stop with the clients connected.
#include <mutex>
#include <set>
#include <thread>
#include <websocketpp/config/asio_no_tls.hpp>
#include <websocketpp/server.hpp>

#include "common.hpp"

using Server = websocketpp::server<websocketpp::config::asio>;
using Hdl = websocketpp::connection_hdl;

int main(int argc, char** argv) {
    Server server;
    server.clear_access_channels(websocketpp::log::alevel::all);
    server.clear_error_channels(websocketpp::log::elevel::all);
    server.init_asio();
    server.set_reuse_addr(true);
    std::mutex mutex;
    std::set<Hdl, std::owner_less<Hdl>> clients;
    server.set_open_handler([&](Hdl h) {
        std::lock_guard l(mutex);
        clients.insert(h);
    });
    server.set_close_handler([&](Hdl h) {
        std::lock_guard l(mutex);
        clients.erase(h);
    });
    server.listen(boost::asio::ip::tcp::endpoint(boost::asio::ip::make_address("127.0.0.1"), portArg(argc, argv)));
    server.start_accept();
    std::thread io([&] { server.run(); });
    while (true) {
        {
            std::lock_guard l(mutex);
            if (clients.size() >= kClients) break;
        }
        std::this_thread::sleep_for(std::chrono::milliseconds(5));
    }
    const auto data = payload();
    const auto t0 = std::chrono::steady_clock::now();
    for (int m = 0; m < kMessages; ++m) {
        std::lock_guard l(mutex);
        for (const Hdl& h : clients) server.send(h, data.data(), data.size(), websocketpp::frame::opcode::binary);
    }
    std::printf("server: queued %d x %zu B to %d clients in %.1f ms\n", kMessages, data.size(), kClients, msSince(t0));
    std::this_thread::sleep_for(std::chrono::milliseconds(2000));
    const auto s0 = std::chrono::steady_clock::now();
    server.stop_listening();
    {
        std::lock_guard l(mutex);
        for (const Hdl& h : clients) {
            websocketpp::lib::error_code ec;
            server.close(h, websocketpp::close::status::going_away, "bye", ec);
        }
    }
    io.join();
    std::printf("server: stop with clients connected took %.1f ms\n", msSince(s0));
}
