// Who wrote a sample, as DDS Security authenticated it: the subject of the remote participant's identity
// certificate, for the server's audit trail (a client id inside a message is whatever the sender typed).
//
// Cyclone DDS (0.10) gives the application no call for a remote participant's authenticated certificate. What it
// does guarantee: its authentication plugin (DDS:Auth:PKI-DH) accepts a remote participant only when the first 48
// bits of its GUID are SHA-256 of the DER subject of the certificate it proved to own in the handshake (DDS
// Security 1.1, 9.3.3 "adjusted" participant GUID; Cyclone's validate_pdata refuses "c.pdata contains incorrect
// participant guid"). So every facescan participant with an identity puts its certificate into its participant
// USER_DATA (public data: the subject already travels in its identity token), and a reader of it trusts the
// subject only when the certificate verifies against the site's identity CA and revocation list and its subject
// hashes to the writer's participant GUID. What this protects: an enrolled identity A cannot be recorded as B by
// claiming B (a client id, or B's certificate in its own USER_DATA): A's GUID prefix was fixed by A's certificate.
// What not: a participant without an identity (no DDS Security) is only what it claims, and a forged subject would
// need a CA-signed certificate whose subject collides with another in 47 bits of SHA-256.
#pragma once

#include <dds/dds.h>

#include <array>
#include <filesystem>
#include <map>
#include <memory>
#include <mutex>
#include <string>

#include "recon/status.hpp"
#include "wire/dds.hpp"

namespace facescan::wire {

// The USER_DATA a participant with the identity folder `dir` announces: a tag line, then its certificate (PEM).
StatusOr<std::string> identityUserData(const std::filesystem::path& dir);

// The subject whose hash the first 48 bits of an authenticated participant's GUID carry (DDS Security 1.1,
// 9.3.3), from the DER encoding of a certificate subject.
std::array<uint8_t, 6> adjustedGuidPrefix(const std::string& subject_der);

class PeerIdentities {
 public:
    // With the identity folder of this participant (its site's identity CA and revocation list).
    static StatusOr<std::unique_ptr<PeerIdentities>> create(const Participant& participant,
                                                            const std::filesystem::path& identity_dir);
    ~PeerIdentities();
    PeerIdentities(const PeerIdentities&) = delete;
    PeerIdentities& operator=(const PeerIdentities&) = delete;

    // The authenticated subject ("CN=client,OU=client,O=lab") of the participant whose writer `publication`
    // (a sample's publication_handle) matches `reader`; an error that says why when it cannot be established
    // (the writer is gone, the participant announces no certificate, or one that is not its own).
    StatusOr<std::string> subjectOf(dds_entity_t reader, dds_instance_handle_t publication);

 private:
    PeerIdentities() = default;
    StatusOr<std::string> verifiedSubject(const dds_guid_t& participant, const std::string& user_data) const;

    Entity participants_;  // a reader of DDS's built-in DCPSParticipant topic
    std::string ca_pem_, crl_pem_;
    std::mutex mutex_;
    std::map<std::array<uint8_t, 16>, std::string> known_;  // participant GUID -> its verified subject
};

}  // namespace facescan::wire
