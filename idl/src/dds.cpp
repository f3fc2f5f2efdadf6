#include "wire/dds.hpp"

#include <unistd.h>

#include <cstring>
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
#include "wire/peer_identity.hpp"
#include "wire/security.hpp"

namespace facescan::wire {
namespace fs = std::filesystem;

Status ddsStatus(dds_return_t code, const std::string& what) {
    const std::string text = what + " failed: " + dds_strretcode(code);
    switch (code) {
        case DDS_RETCODE_TIMEOUT: return deadlineExceeded(text);
        case DDS_RETCODE_BAD_PARAMETER: return invalidArgument(text);
        case DDS_RETCODE_OUT_OF_RESOURCES: return resourceExhausted(text);
        case DDS_RETCODE_NOT_ALLOWED_BY_SECURITY:
            return permissionDenied(what + " is not allowed by this identity's DDS Security permissions");
        default: return internalError(text);
    }
}

Status DomainConfig::validate() const {
    // DDS maps domain ids to UDP ports (7400 + 250 * id); above 232 they overflow the port range.
    if (domain_id > 232) return invalidArgument("domain id must be 0..232, got " + std::to_string(domain_id));
    if (profile.empty()) return invalidArgument("profile must be loopback, lan or a path to a Cyclone XML file");
    // The governance and permissions documents of DDS Security name domain ids 0..230 only.
    if (!security.empty() && domain_id > 230) {
        return invalidArgument("DDS Security covers domain ids 0..230, got " + std::to_string(domain_id));
    }
    return Status::ok();
}

std::string DomainConfig::describe() const {
    return "domain " + std::to_string(domain_id) + " (profile " + profile +
           (security.empty() ? std::string(", no DDS Security") : ", DDS Security identity " + security) + ")";
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

// The domains this process has created, by id, with the configuration each was made with (one per id: Cyclone
// keeps one configuration per domain and process).
struct DomainEntry {
    std::weak_ptr<Entity> entity;
    std::string profile;
    std::string security;
};
std::mutex g_domains_mutex;
std::map<uint32_t, DomainEntry> g_domains;

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

double profileLeaseS(const std::string& profile_xml) {
    constexpr double kCycloneDefaultS = 10.0;
    static const std::regex kLease(R"(<LeaseDuration>\s*([0-9]*\.?[0-9]+)\s*(ms|s|min|hr)?\s*</LeaseDuration>)");
    std::smatch m;
    if (!std::regex_search(profile_xml, m, kLease)) return kCycloneDefaultS;
    const double value = std::stod(m[1].str());
    const std::string unit = m[2].str();
    const double s = unit == "ms" ? value * 1e-3 : unit == "min" ? value * 60 : unit == "hr" ? value * 3600 : value;
    return s > 0 ? s : kCycloneDefaultS;
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
        DomainEntry& entry = g_domains[config.domain_id];
        participant.domain_ = entry.entity.lock();
        if (participant.domain_ && (entry.profile != config.profile || entry.security != config.security)) {
            return invalidArgument("this process already uses " +
                                   DomainConfig{config.domain_id, entry.profile, entry.security}.describe() +
                                   "; one process has one configuration per domain");
        }
        if (!participant.domain_) {
            ASSIGN_OR_RETURN(std::string xml, loadProfileXml(config.profile));
            RETURN_IF_ERROR(checkSocketBuffers(xml));
            // DDS Security is configuration: the identity's files are checked and named in a <Security> element.
            if (!config.security.empty()) {
                ASSIGN_OR_RETURN(xml, addSecurity(xml, config.security));
            }
            if (config.writer_linger) {
                // A second configuration fragment: Cyclone reads a comma-separated list, later ones on top.
                xml += ",<CycloneDDS><Domain Id=\"any\"><Internal><WriterLingerDuration>" +
                       std::to_string(config.writer_linger->count()) +
                       "ms</WriterLingerDuration></Internal></Domain></CycloneDDS>";
            }
            const dds_entity_t domain = dds_create_domain(config.domain_id, xml.c_str());
            if (domain < 0) return ddsStatus(domain, "create DDS " + config.describe());
            participant.domain_ = std::make_shared<Entity>(domain);
            entry = {participant.domain_, config.profile, config.security};
        }
    }
    // With an identity, the participant announces its certificate in USER_DATA: peers bind it to the GUID that
    // authentication fixed, to know who sent a command (wire/peer_identity.hpp).
    Qos qos;
    if (!config.security.empty()) {
        ASSIGN_OR_RETURN(const std::string user_data, identityUserData(config.security));
        dds_qset_userdata(qos.get(), user_data.data(), user_data.size());
    }
    const dds_entity_t h = dds_create_participant(config.domain_id, qos.get(), nullptr);
    if (h < 0) {
        // The identity's files were checked before; what is left is the plugins' own refusal (in Cyclone's log).
        if (!config.security.empty()) {
            return permissionDenied("DDS Security refused to create a participant in " + config.describe() +
                                    " although its files check out (Cyclone's own message above says why)");
        }
        return ddsStatus(h, "create DDS participant in " + config.describe());
    }
    participant.entity_ = Entity(h);
    return participant;
}

StatusOr<Entity> partitionParent(dds_entity_t participant, const std::string& partition, bool publisher) {
    if (partition.empty()) return Entity();
    Qos qos;
    dds_qset_partition1(qos.get(), partition.c_str());
    const dds_entity_t h = publisher ? dds_create_publisher(participant, qos.get(), nullptr)
                                     : dds_create_subscriber(participant, qos.get(), nullptr);
    if (h < 0)
        return ddsStatus(h, "create " + std::string(publisher ? "publisher" : "subscriber") + " of " + partition);
    return Entity(h);
}

int Participant::otherParticipants() const {
    const dds_entity_t reader =
        dds_create_reader(entity_.handle(), DDS_BUILTIN_TOPIC_DCPSPARTICIPANT, nullptr, nullptr);
    if (reader < 0) return -1;
    const Entity owned(reader);
    dds_guid_t self{};
    if (dds_get_guid(entity_.handle(), &self) < 0) return -1;
    constexpr int kMax = 64;
    void* samples[kMax] = {};
    dds_sample_info_t infos[kMax];
    const dds_return_t n = dds_read(reader, samples, infos, kMax, kMax);
    if (n < 0) return -1;
    int others = 0;
    for (int i = 0; i < n; ++i) {
        const auto* p = static_cast<const dds_builtintopic_participant_t*>(samples[i]);
        if (infos[i].valid_data && std::memcmp(&p->key, &self, sizeof(self)) != 0) ++others;
    }
    if (n > 0) dds_return_loan(reader, samples, n);
    return others;
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
