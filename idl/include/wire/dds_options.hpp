// The DDS options every facescan program takes, parsed and described in one place so that each program (agent,
// server, client, viewer and later ones) accepts the same flags with the same checks and help text:
//   --profile loopback|lan|FILE.xml   --domain N   --security DIR/NAME
#pragma once

#include <string>

#include "recon/status.hpp"
#include "wire/dds.hpp"

namespace facescan::wire {

// True for --profile, --domain and --security (each takes a value).
bool isDdsOption(const std::string& flag);

// Applies one of them to `config`. InvalidArgument naming the option when its value is wrong. The identity of
// --security is checked when the program joins the domain (Participant::create), with messages naming the file.
Status applyDdsOption(DomainConfig& config, const std::string& flag, const std::string& value);

// One line for a program's start-up output: "DDS Security: identity agent (role agent, site lab), valid until
// 2027-11-23 03:08 UTC", or that DDS Security is off (anyone on the domain can read and send).
std::string securitySummary(const DomainConfig& config);

// Why no peer may answer on this domain, for "no server answered" messages: secured and unsecured programs never
// see each other, nor do identities of different sites or revoked ones. `other_participants` (the number of
// other DDS participants discovered on the domain; -1: not known) sharpens the guess.
std::string noPeerHint(const DomainConfig& config, int other_participants = -1);

// The help lines of the three options, "  --profile P" padded to `column` characters, then the description.
std::string ddsOptionsHelp(size_t column);

}  // namespace facescan::wire
