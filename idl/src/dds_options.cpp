#include "wire/dds_options.hpp"

#include <charconv>

#include "wire/security.hpp"

namespace facescan::wire {
namespace {

struct OptionHelp {
    const char* flag;
    const char* text;
};
constexpr OptionHelp kOptions[] = {
    {"--profile P", "DDS network profile: loopback, lan (default) or a Cyclone FILE.xml"},
    {"--domain N", "DDS domain id 0..232 (default 0); agent, server and client must agree"},
    {"--security DIR/NAME",
     "DDS Security with this identity of a site (deploy/security/site.sh): only enrolled\n"
     "machines join, everything is encrypted, each role does only its job (default: off)"},
};

}  // namespace

bool isDdsOption(const std::string& flag) { return flag == "--profile" || flag == "--domain" || flag == "--security"; }

Status applyDdsOption(DomainConfig& config, const std::string& flag, const std::string& value) {
    if (flag == "--profile") {
        if (value.empty()) return invalidArgument("--profile takes loopback, lan or a path to a Cyclone FILE.xml");
        config.profile = value;
    } else if (flag == "--domain") {
        uint32_t id = 0;
        const auto [end, ec] = std::from_chars(value.data(), value.data() + value.size(), id);
        if (ec != std::errc() || end != value.data() + value.size() || id > 232) {
            return invalidArgument("--domain must be a number 0..232, got '" + value + "'");
        }
        config.domain_id = id;
    } else if (flag == "--security") {
        if (value.empty()) return invalidArgument("--security takes an identity folder DIR/NAME made by site.sh");
        config.security = value;
    } else {
        return invalidArgument("not a DDS option: " + flag);
    }
    return Status::ok();
}

std::string securitySummary(const DomainConfig& config) {
    if (config.security.empty()) {
        return "DDS Security off: anyone on the domain can read and send (see --security and deploy/security/site.sh)";
    }
    auto identity = checkIdentity(config.security);
    return identity.isOk() ? "DDS Security: " + identity->describe() : identity.status().message();
}

std::string noPeerHint(const DomainConfig& config, int other_participants) {
    if (config.security.empty()) {
        if (other_participants > 0) {
            return std::to_string(other_participants) +
                   " other DDS participant(s) are on this domain but none answers: they probably run with DDS "
                   "Security, which never talks to a program without it; start this one with --security DIR/NAME "
                   "(an identity of their site, deploy/security/site.sh)";
        }
        return "(if the site runs DDS Security, programs without --security DIR/NAME never see it)";
    }
    return "(with DDS Security, peers without --security, with an identity of another site, or revoked in this "
           "identity's crl.pem are never seen: check their start-up lines)";
}

std::string ddsOptionsHelp(size_t column) {
    std::string out;
    for (const OptionHelp& option : kOptions) {
        std::string line = "  " + std::string(option.flag);
        line.resize(std::max(column, line.size() + 2), ' ');
        for (const char c : std::string(option.text)) {
            line += c;
            if (c == '\n') line += std::string(column, ' ');
        }
        out += line + "\n";
    }
    return out;
}

}  // namespace facescan::wire
