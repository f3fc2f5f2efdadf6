#include "wire/dds.hpp"

#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <map>
#include <mutex>
#include <optional>
#include <regex>
#include <sstream>
#include <thread>
#include <vector>

#include "wire/data_files.hpp"

namespace facescan::wire {
namespace fs = std::filesystem;

Status ddsStatus(dds_return_t code, const std::string& what) {
    const std::string text = what + " failed: " + dds_strretcode(code);
    switch (code) {
        case DDS_RETCODE_TIMEOUT: return deadlineExceeded(text);
        case DDS_RETCODE_BAD_PARAMETER: return invalidArgument(text);
        case DDS_RETCODE_OUT_OF_RESOURCES: return resourceExhausted(text);
        default: return internalError(text);
    }
}

Status DomainConfig::validate() const {
    // DDS maps domain ids to UDP ports (7400 + 250 * id); above 232 they overflow the port range.
    if (domain_id > 232) return invalidArgument("domain id must be 0..232, got " + std::to_string(domain_id));
    if (profile.empty()) return invalidArgument("profile must be loopback, lan or a path to a Cyclone XML file");
    return Status::ok();
}

namespace {

std::optional<std::string> readFile(const fs::path& path) {
    std::ifstream in(path, std::ios::binary);
    if (!in) return std::nullopt;
    std::ostringstream text;
    text << in.rdbuf();
    return text.str();
}

// Cyclone's memory sizes: B, kB/KiB (1024), MB/MiB, GB/GiB.
std::optional<uint64_t> parseMemSize(const std::string& text) {
    static const std::regex kSize(R"(^\s*([0-9]+)\s*(B|kB|KiB|MB|MiB|GB|GiB)?\s*$)");
    std::smatch m;
    if (!std::regex_match(text, m, kSize)) return std::nullopt;
    uint64_t value = std::stoull(m[1].str());
    const std::string unit = m[2].str();
    if (unit == "kB" || unit == "KiB") value <<= 10;
    if (unit == "MB" || unit == "MiB") value <<= 20;
    if (unit == "GB" || unit == "GiB") value <<= 30;
    return value;
}

std::mutex g_domains_mutex;
std::map<uint32_t, std::weak_ptr<Entity>> g_domains;

}  // namespace

StatusOr<fs::path> findProfileFile(const std::string& profile) {
    if (profile.find('/') != std::string::npos || profile.ends_with(".xml")) return fs::path(profile);
    if (profile != "loopback" && profile != "lan") {
        return invalidArgument("unknown DDS profile '" + profile + "': use loopback, lan or a path to FILE.xml");
    }
    // FACESCAN_PROFILE_DIR (a folder of profiles) overrides; then the share/facescan/profiles of the installed or
    // build tree (wire/data_files.hpp).
    if (const char* env = std::getenv("FACESCAN_PROFILE_DIR"); env && *env) return fs::path(env) / (profile + ".xml");
    return findShareFile("profiles/" + profile + ".xml");
}

StatusOr<std::string> loadProfileXml(const std::string& profile) {
    ASSIGN_OR_RETURN(const fs::path path, findProfileFile(profile));
    auto text = readFile(path);
    if (!text) return notFound("cannot read DDS profile file '" + path.string() + "'");
    return *text;
}

Status checkSocketBuffers(const std::string& profile_xml) {
    static const std::regex kMin(R"(<SocketReceiveBufferSize[^>]*\bmin\s*=\s*\"([^\"]+)\")");
    std::smatch m;
    if (!std::regex_search(profile_xml, m, kMin) || m[1].str() == "default") return Status::ok();
    const auto wanted = parseMemSize(m[1].str());
    if (!wanted) return invalidArgument("cannot parse SocketReceiveBufferSize min=\"" + m[1].str() + "\"");
    const auto limit_text = readFile("/proc/sys/net/core/rmem_max");
    if (!limit_text) return Status::ok();  // not Linux, or no procfs: let Cyclone decide
    const uint64_t limit = std::stoull(*limit_text);
    if (limit >= *wanted) return Status::ok();
    return unavailable(
        "the DDS profile asks for a " + std::to_string(*wanted) +
        " byte socket receive buffer but the kernel allows at most net.core.rmem_max = " + std::to_string(limit) +
        ". Raise the limit: sudo sysctl -w net.core.rmem_max=" + std::to_string(*wanted) +
        " (to keep it: echo 'net.core.rmem_max=" + std::to_string(*wanted) +
        "' | sudo tee /etc/sysctl.d/60-facescan.conf), or lower SocketReceiveBufferSize min in the "
        "profile");
}

void Entity::reset() {
    if (handle_ > 0) dds_delete(handle_);
    handle_ = 0;
}

StatusOr<Participant> Participant::create(const DomainConfig& config) {
    RETURN_IF_ERROR(config.validate());
    Participant participant;
    participant.domain_id_ = config.domain_id;
    {
        std::lock_guard lock(g_domains_mutex);
        participant.domain_ = g_domains[config.domain_id].lock();
        if (!participant.domain_) {
            ASSIGN_OR_RETURN(const std::string xml, loadProfileXml(config.profile));
            RETURN_IF_ERROR(checkSocketBuffers(xml));
            const dds_entity_t domain = dds_create_domain(config.domain_id, xml.c_str());
            if (domain < 0) {
                return ddsStatus(domain, "create DDS domain " + std::to_string(config.domain_id) + " with profile '" +
                                             config.profile + "'");
            }
            participant.domain_ = std::make_shared<Entity>(domain);
            g_domains[config.domain_id] = participant.domain_;
        }
    }
    const dds_entity_t h = dds_create_participant(config.domain_id, nullptr, nullptr);
    if (h < 0) return ddsStatus(h, "create DDS participant in domain " + std::to_string(config.domain_id));
    participant.entity_ = Entity(h);
    return participant;
}

bool pollUntil(const std::function<bool()>& done, std::chrono::milliseconds timeout) {
    const auto deadline = std::chrono::steady_clock::now() + timeout;
    while (!done()) {
        if (std::chrono::steady_clock::now() >= deadline) return false;
        std::this_thread::sleep_for(std::chrono::milliseconds(5));
    }
    return true;
}

}  // namespace facescan::wire
