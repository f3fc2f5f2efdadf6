// cpp-httplib 0.11.4 (no WebSocket): server-sent events announce each snapshot, the browser GETs its bytes.
#include <httplib.h>

#include <condition_variable>
#include <thread>

#include "common.hpp"

std::mutex g_mutex;
std::condition_variable g_cv;
int g_seq = 0, g_connected = 0;
bool g_stopping = false;

int main(int argc, char** argv) {
    httplib::Server server;
    // Each SSE stream holds a pool thread for its lifetime: the default pool (8) would starve with 10 browsers.
    server.new_task_queue = [] { return new httplib::ThreadPool(32); };
    const auto data = payload();
    server.Get("/snap", [&](const httplib::Request&, httplib::Response& res) {
        res.set_content(reinterpret_cast<const char*>(data.data()), data.size(), "application/octet-stream");
    });
    server.Get("/events", [&](const httplib::Request&, httplib::Response& res) {
        {
            std::lock_guard l(g_mutex);
            ++g_connected;
        }
        auto sent = std::make_shared<int>(0);
        res.set_chunked_content_provider("text/event-stream", [sent](size_t, httplib::DataSink& sink) {
            std::unique_lock l(g_mutex);
            g_cv.wait(l, [&] { return g_stopping || g_seq > *sent; });
            if (g_stopping) {
                sink.done();
                return false;
            }
            *sent = g_seq;
            const std::string ev = "data: " + std::to_string(*sent) + "\n\n";
            l.unlock();
            return sink.write(ev.data(), ev.size());
        });
    });
    std::thread t([&] { server.listen("127.0.0.1", portArg(argc, argv)); });
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
    server.stop();
    t.join();
    std::printf("server: stop with clients connected took %.1f ms\n", msSince(s0));
}
