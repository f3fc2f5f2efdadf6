// A private DDS domain per test process. Tests run in parallel (ctest -j) and each starts real DDS peers: two
// processes that picked the same domain would answer each other's commands. Each domain id (100..219) is claimed
// with an exclusive flock on /tmp/facescan-test-domain-N.lock, held until the process (and its forked or spawned
// children, which inherit the descriptor) exits, so no two running test processes ever share one.
#pragma once

#include <fcntl.h>
#include <sys/file.h>
#include <unistd.h>

#include <cstdint>
#include <map>
#include <mutex>
#include <stdexcept>
#include <string>

namespace facescan::testing {

// The same salt gives the same domain within one process; different salts give different domains.
inline uint32_t privateDomain(uint32_t salt = 0) {
    static std::mutex mutex;
    static std::map<uint32_t, uint32_t> claimed;
    std::lock_guard lock(mutex);
    if (auto it = claimed.find(salt); it != claimed.end()) return it->second;
    const uint32_t start = (static_cast<uint32_t>(getpid()) * 7 + salt * 13) % 120;
    for (uint32_t i = 0; i < 120; ++i) {
        const uint32_t domain = 100 + (start + i) % 120;
        const std::string path = "/tmp/facescan-test-domain-" + std::to_string(domain) + ".lock";
        const int fd = ::open(path.c_str(), O_CREAT | O_RDWR, 0666);
        if (fd < 0) continue;
        if (::flock(fd, LOCK_EX | LOCK_NB) == 0) {
            claimed[salt] = domain;  // fd stays open on purpose: the claim lasts as long as the process
            return domain;
        }
        ::close(fd);
    }
    throw std::runtime_error("no free test DDS domain in 100..219 (120 test processes running?)");
}

}  // namespace facescan::testing
