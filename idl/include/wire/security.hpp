// OMG DDS Security for facescan: Cyclone DDS's built-in plugins (authentication, access control, AES-GCM
// cryptography) do all the work; a site (CAs, governance, per-role permissions) is made by
// deploy/security/site.sh. This file only turns an identity folder of a site into the Cyclone <Security>
// configuration, after checking its files with OpenSSL so that a bad one stops the program with one line that
// names the file and what is wrong (Cyclone itself only says that the participant could not be created).
#pragma once

#include <cstdint>
#include <filesystem>
#include <string>

#include "recon/status.hpp"

namespace facescan::wire {

// The files of an identity folder DIR/NAME, as site.sh writes them.
struct IdentityFiles {
    static constexpr const char* kIdentityCa = "identity_ca.pem";        // the site's identity CA
    static constexpr const char* kCertificate = "identity.pem";          // this identity, signed by it
    static constexpr const char* kPrivateKey = "identity.key";           // its private key (unencrypted, 0600)
    static constexpr const char* kRevocationList = "crl.pem";            // the identity CA's revocation list
    static constexpr const char* kPermissionsCa = "permissions_ca.pem";  // signs governance and permissions
    static constexpr const char* kGovernance = "governance.p7s";         // S/MIME: the domain's protection
    static constexpr const char* kPermissions = "permissions.p7s";       // S/MIME: what this identity may do
};

// Who an identity is (from its certificate's subject: CN=name, OU=role, O=site) and until when it is valid.
struct SecurityIdentity {
    std::filesystem::path dir;
    std::string name;
    std::string role;
    std::string site;
    std::string valid_until;       // "2027-11-23 03:08 UTC": the earlier of the certificate's and the permissions' end
    std::string describe() const;  // "identity capture-3 (role agent, site lab), valid until 2027-11-23 03:08 UTC"
};

// Checks every file of an identity folder with OpenSSL, as the plugins will, and says which file is wrong and
// how: missing or unreadable; not PEM; a CA, certificate, permissions document or revocation list expired or not
// yet valid; the certificate not signed by the site's identity CA (another site's) or revoked; the private key
// not the certificate's; governance or permissions not signed by the site's permissions CA, or changed after
// signing; permissions for another subject. NotFound for a missing file, PermissionDenied for the rest.
StatusOr<SecurityIdentity> checkIdentity(const std::filesystem::path& dir);

// Where Debian's libddsc0debian installs the three plugins (not on the loader's path, so the configuration
// names each by its full path). FACESCAN_DDS_SECURITY_PLUGIN_DIR in the environment overrides it.
std::filesystem::path securityPluginDir();

// The Cyclone <Security> element for an identity folder (absolute file: URIs, plugins by full path). No checks.
std::string securityXml(const std::filesystem::path& dir, const std::filesystem::path& plugin_dir);

// Checks the identity (checkIdentity) and the plugins, and returns `profile_xml` with the <Security> element
// added to its <Domain>: what Participant::create gives Cyclone when DomainConfig::security is set.
StatusOr<std::string> addSecurity(const std::string& profile_xml, const std::filesystem::path& dir);

}  // namespace facescan::wire
