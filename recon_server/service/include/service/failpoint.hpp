// Fault injection for the cluster tests, as etcd's gofail or FreeBSD's fail(9): FACESCAN_FAILPOINT=NAME:ARG makes
// one named place of the server misbehave as a real fault would (a thread that stops, a step that takes long).
// Unset in production; the server says at start when it is set.
#pragma once

#include <cstdlib>
#include <optional>
#include <string>
#include <string_view>

namespace facescan::service {

// ARG when FACESCAN_FAILPOINT is NAME:ARG, else nothing.
inline std::optional<std::string> failpointArg(std::string_view name) {
    const char* fp = std::getenv("FACESCAN_FAILPOINT");
    if (fp == nullptr) return std::nullopt;
    const std::string_view spec(fp);
    if (spec.size() <= name.size() || spec.substr(0, name.size()) != name || spec[name.size()] != ':') {
        return std::nullopt;
    }
    return std::string(spec.substr(name.size() + 1));
}

}  // namespace facescan::service
