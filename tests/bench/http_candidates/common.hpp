// Shared by the four HTTP/WebSocket candidate prototypes (see run.sh): the payload, the client count, timing.
#pragma once
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <string>
#include <vector>

inline constexpr int kClients = 10;
inline constexpr int kMessages = 40;
inline constexpr size_t kPayloadBytes = 600 * 1024;  // a face snapshot in Draco is 0.3-1 MB
inline std::vector<unsigned char> payload() {
    std::vector<unsigned char> p(kPayloadBytes);
    for (size_t i = 0; i < p.size(); ++i) p[i] = static_cast<unsigned char>(i * 2654435761u >> 13);
    return p;
}
inline double msSince(std::chrono::steady_clock::time_point t) {
    return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t).count();
}
inline int portArg(int argc, char** argv) { return argc > 1 ? std::atoi(argv[1]) : 18080; }
