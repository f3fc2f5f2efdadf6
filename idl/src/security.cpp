// Checks of an identity folder with OpenSSL (the same library and the same checks as Cyclone's plugins), and
// the <Security> element of the Cyclone configuration. No cryptography of our own: OpenSSL verifies.
#include "wire/security.hpp"

#include <openssl/bio.h>
#include <openssl/err.h>
#include <openssl/pem.h>
#include <openssl/pkcs7.h>
#include <openssl/x509.h>
#include <openssl/x509_vfy.h>

#include <algorithm>
#include <ctime>
#include <iomanip>
#include <memory>
#include <optional>
#include <regex>
#include <set>
#include <sstream>

#include "openssl_ptr.hpp"

namespace facescan::wire {
namespace fs = std::filesystem;
namespace {

using openssl::BioPtr;
using openssl::CrlPtr;
using openssl::KeyPtr;
using openssl::Pkcs7Ptr;
using openssl::StoreCtxPtr;
using openssl::StorePtr;
using openssl::X509Ptr;

// Every message names the file and says what is wrong with it, on one line.
Status fileError(const fs::path& path, const std::string& what) {
    return permissionDenied("DDS Security: " + path.string() + ": " + what);
}

StatusOr<BioPtr> openFile(const fs::path& path) {
    std::error_code ec;
    if (!fs::exists(path, ec)) {
        return notFound("DDS Security: " + path.string() +
                        ": missing (an identity folder made by deploy/security/site.sh holds it)");
    }
    if (!fs::is_regular_file(path, ec)) return fileError(path, "is not a file");
    BioPtr bio(BIO_new_file(path.c_str(), "r"));
    if (!bio) return fileError(path, "cannot be read (permissions of the file?)");
    return bio;
}

// Never ask for a pass phrase on the terminal: identity keys are stored unencrypted, readable by their user only.
int noPassword(char*, int, int, void*) { return 0; }

StatusOr<X509Ptr> readCertificate(const fs::path& path) {
    ASSIGN_OR_RETURN(BioPtr bio, openFile(path));
    X509Ptr cert(PEM_read_bio_X509(bio.get(), nullptr, noPassword, nullptr));
    if (!cert) return fileError(path, "is not a PEM certificate");
    return cert;
}

StatusOr<CrlPtr> readCrl(const fs::path& path) {
    ASSIGN_OR_RETURN(BioPtr bio, openFile(path));
    CrlPtr crl(PEM_read_bio_X509_CRL(bio.get(), nullptr, noPassword, nullptr));
    if (!crl) return fileError(path, "is not a PEM certificate revocation list");
    return crl;
}

StatusOr<KeyPtr> readPrivateKey(const fs::path& path) {
    ASSIGN_OR_RETURN(BioPtr bio, openFile(path));
    KeyPtr key(PEM_read_bio_PrivateKey(bio.get(), nullptr, noPassword, nullptr));
    if (!key) return fileError(path, "is not an unencrypted PEM private key");
    return key;
}

std::string timeText(std::tm tm) {
    char text[32];
    std::strftime(text, sizeof(text), "%Y-%m-%d %H:%M UTC", &tm);
    return text;
}
std::string timeText(const ASN1_TIME* t) {
    std::tm tm{};
    if (!t || ASN1_TIME_to_tm(t, &tm) != 1) return "(unreadable date)";
    return timeText(tm);
}

// "is not valid before ..." / "expired on ..." for a certificate or a revocation list's dates.
Status checkDates(const fs::path& path, const std::string& what, const ASN1_TIME* not_before,
                  const ASN1_TIME* not_after) {
    if (not_before && X509_cmp_current_time(not_before) > 0) {
        return fileError(path, what + " is not valid before " + timeText(not_before) + " (check this machine's clock)");
    }
    if (not_after && X509_cmp_current_time(not_after) < 0) {
        return fileError(path, what + " expired on " + timeText(not_after));
    }
    return Status::ok();
}

std::string nameText(const X509_NAME* name) {
    BioPtr bio(BIO_new(BIO_s_mem()));
    X509_NAME_print_ex(bio.get(), name, 0, XN_FLAG_RFC2253);
    char* data = nullptr;
    const long size = BIO_get_mem_data(bio.get(), &data);
    return size > 0 ? std::string(data, static_cast<size_t>(size)) : std::string();
}

std::string nameField(const X509_NAME* name, int nid) {
    const int index = X509_NAME_get_index_by_NID(name, nid, -1);
    if (index < 0) return {};
    unsigned char* utf8 = nullptr;
    const int size = ASN1_STRING_to_UTF8(&utf8, X509_NAME_ENTRY_get_data(X509_NAME_get_entry(name, index)));
    if (size < 0) return {};
    std::string text(reinterpret_cast<char*>(utf8), static_cast<size_t>(size));
    OPENSSL_free(utf8);
    return text;
}

// "CN=a, OU=b,O=c" -> {"CN=a", "OU=b", "O=c"}: subjects compare as sets of attributes, as Cyclone's plugin does.
std::set<std::string> subjectParts(const std::string& subject) {
    std::set<std::string> parts;
    std::stringstream in(subject);
    for (std::string part; std::getline(in, part, ',');) {
        part.erase(0, part.find_first_not_of(" \t\r\n"));
        part.erase(part.find_last_not_of(" \t\r\n") + 1);
        if (const size_t eq = part.find('='); eq != std::string::npos) {
            std::string key = part.substr(0, eq), value = part.substr(eq + 1);
            key.erase(key.find_last_not_of(' ') + 1);
            value.erase(0, value.find_first_not_of(' '));
            part = key + "=" + value;
        }
        if (!part.empty()) parts.insert(part);
    }
    return parts;
}

// Verifies the identity certificate against the site's identity CA and its revocation list.
Status verifyCertificate(const fs::path& cert_path, X509* cert, const fs::path& ca_path, X509* ca, X509_CRL* crl) {
    StorePtr store(X509_STORE_new());
    StoreCtxPtr ctx(X509_STORE_CTX_new());
    if (!store || !ctx || X509_STORE_add_cert(store.get(), ca) != 1 || X509_STORE_add_crl(store.get(), crl) != 1) {
        return internalError("DDS Security: OpenSSL cannot make a certificate store");
    }
    X509_STORE_set_flags(store.get(), X509_V_FLAG_CRL_CHECK);
    if (X509_STORE_CTX_init(ctx.get(), store.get(), cert, nullptr) != 1) {
        return internalError("DDS Security: OpenSSL cannot make a certificate store");
    }
    if (X509_verify_cert(ctx.get()) == 1) return Status::ok();
    const int error = X509_STORE_CTX_get_error(ctx.get());
    switch (error) {
        case X509_V_ERR_UNABLE_TO_GET_ISSUER_CERT_LOCALLY:
        case X509_V_ERR_UNABLE_TO_GET_ISSUER_CERT:
        case X509_V_ERR_UNABLE_TO_VERIFY_LEAF_SIGNATURE:
        case X509_V_ERR_CERT_SIGNATURE_FAILURE:
            return fileError(cert_path, "is not signed by this site's identity CA (" + ca_path.string() +
                                            "): it was issued by '" + nameText(X509_get_issuer_name(cert)) +
                                            "', an identity of another site?");
        case X509_V_ERR_CERT_REVOKED: {
            X509_REVOKED* revoked = nullptr;
            std::string when;
            if (X509_CRL_get0_by_cert(crl, &revoked, cert) == 1 && revoked) {
                when = " on " + timeText(X509_REVOKED_get0_revocationDate(revoked));
            }
            return fileError(cert_path, "this identity was revoked" + when + " (it is on the site's revocation list)");
        }
        default:
            return fileError(cert_path, std::string("does not verify against ") + ca_path.string() + ": " +
                                            X509_verify_cert_error_string(error));
    }
}

// Verifies an S/MIME document (clear-signed, as `openssl smime -sign -text` writes it) against the site's
// permissions CA exactly as Cyclone's access control plugin does, and returns its signed content.
StatusOr<std::string> verifySigned(const fs::path& path, X509* ca, const fs::path& ca_path) {
    ASSIGN_OR_RETURN(BioPtr bio, openFile(path));
    BIO* content = nullptr;
    Pkcs7Ptr p7(SMIME_read_PKCS7(bio.get(), &content));
    BioPtr content_owner(content);
    if (!p7) return fileError(path, "is not an S/MIME signed document (damaged?)");
    BioPtr out(BIO_new(BIO_s_mem()));
    STACK_OF(X509)* signers = sk_X509_new_null();
    sk_X509_push(signers, ca);
    ERR_clear_error();
    const int verified =
        PKCS7_verify(p7.get(), signers, nullptr, content, out.get(), PKCS7_TEXT | PKCS7_NOVERIFY | PKCS7_NOINTERN);
    sk_X509_free(signers);
    if (verified != 1) {
        const unsigned long error = ERR_peek_last_error();
        const int reason = ERR_GET_REASON(error);
        ERR_clear_error();
        if (reason == PKCS7_R_SIGNER_CERTIFICATE_NOT_FOUND) {
            return fileError(path, "is not signed by this site's permissions CA (" + ca_path.string() +
                                       "): a document of another site?");
        }
        if (reason == PKCS7_R_DIGEST_FAILURE || reason == PKCS7_R_SIGNATURE_FAILURE) {
            return fileError(path,
                             "was changed after it was signed (its signature does not match its content): take it "
                             "again from the site");
        }
        const char* why = ERR_reason_error_string(error);
        return fileError(path, std::string("its signature does not verify: ") + (why ? why : "unknown reason"));
    }
    char* data = nullptr;
    const long size = BIO_get_mem_data(out.get(), &data);
    return size > 0 ? std::string(data, static_cast<size_t>(size)) : std::string();
}

std::optional<std::string> xmlElement(const std::string& xml, const std::string& name) {
    const std::regex element("<" + name + ">\\s*([^<]*?)\\s*</" + name + ">");
    std::smatch m;
    if (!std::regex_search(xml, m, element)) return std::nullopt;
    return m[1].str();
}

// An XML Schema dateTime of a permissions <validity> ("2027-11-23T03:08:57", UTC).
std::optional<std::tm> xmlTime(const std::string& text) {
    std::tm tm{};
    std::istringstream in(text);
    in >> std::get_time(&tm, "%Y-%m-%dT%H:%M:%S");
    if (in.fail()) return std::nullopt;
    return tm;
}

// The signed permissions: for this certificate's subject, within their validity, allowing something.
Status checkPermissions(const fs::path& path, const std::string& xml, X509* cert, std::string& valid_until) {
    const auto subject = xmlElement(xml, "subject_name");
    const auto not_before_text = xmlElement(xml, "not_before");
    const auto not_after_text = xmlElement(xml, "not_after");
    if (!subject || !not_before_text || !not_after_text) {
        return fileError(path, "has no <subject_name> or <validity>: not a facescan permissions document");
    }
    const std::string cert_subject = nameText(X509_get_subject_name(cert));
    if (subjectParts(*subject) != subjectParts(cert_subject)) {
        return fileError(path, "grants '" + *subject + "', not this identity's certificate ('" + cert_subject + "')");
    }
    const auto not_before = xmlTime(*not_before_text);
    const auto not_after = xmlTime(*not_after_text);
    if (!not_before || !not_after) return fileError(path, "has an unreadable <validity>");
    std::tm before = *not_before, after = *not_after;
    const std::time_t now = std::time(nullptr);
    if (timegm(&before) > now) {
        return fileError(path, "is not valid before " + timeText(*not_before) + " (check this machine's clock)");
    }
    if (timegm(&after) <= now) {
        const bool revoked = xml.find("<allow_rule>") == std::string::npos;
        return fileError(path, (revoked ? "this identity was revoked on " : "expired on ") + timeText(*not_after));
    }
    if (xml.find("<allow_rule>") == std::string::npos) return fileError(path, "allows nothing (revoked?)");
    valid_until = timeText(*not_after);
    return Status::ok();
}

std::string xmlEscape(const std::string& text) {
    std::string out;
    for (const char c : text) {
        switch (c) {
            case '&': out += "&amp;"; break;
            case '<': out += "&lt;"; break;
            case '>': out += "&gt;"; break;
            case '"': out += "&quot;"; break;
            default: out += c;
        }
    }
    return out;
}

constexpr const char* kPlugins[3][2] = {{"Authentication", "libdds_security_auth.so"},
                                        {"AccessControl", "libdds_security_ac.so"},
                                        {"Cryptographic", "libdds_security_crypto.so"}};

}  // namespace

std::string SecurityIdentity::describe() const {
    return "identity " + name + " (role " + role + ", site " + site + "), valid until " + valid_until;
}

StatusOr<SecurityIdentity> checkIdentity(const fs::path& dir) {
    std::error_code ec;
    if (!fs::is_directory(dir, ec)) {
        return notFound("DDS Security: " + dir.string() +
                        ": no such identity folder (make one with deploy/security/site.sh add SITE ROLE NAME)");
    }
    using F = IdentityFiles;
    const fs::path ca_path = dir / F::kIdentityCa, cert_path = dir / F::kCertificate, key_path = dir / F::kPrivateKey;
    const fs::path crl_path = dir / F::kRevocationList, pca_path = dir / F::kPermissionsCa;
    const fs::path gov_path = dir / F::kGovernance, perm_path = dir / F::kPermissions;

    ASSIGN_OR_RETURN(const X509Ptr ca, readCertificate(ca_path));
    RETURN_IF_ERROR(
        checkDates(ca_path, "the site's identity CA", X509_get0_notBefore(ca.get()), X509_get0_notAfter(ca.get())));
    ASSIGN_OR_RETURN(const CrlPtr crl, readCrl(crl_path));
    if (X509_CRL_verify(crl.get(), X509_get0_pubkey(ca.get())) != 1) {
        return fileError(crl_path, "is not signed by this site's identity CA (" + ca_path.string() + ")");
    }
    RETURN_IF_ERROR(checkDates(crl_path, "the revocation list", X509_CRL_get0_lastUpdate(crl.get()),
                               X509_CRL_get0_nextUpdate(crl.get())));

    ASSIGN_OR_RETURN(const X509Ptr cert, readCertificate(cert_path));
    RETURN_IF_ERROR(
        checkDates(cert_path, "the certificate", X509_get0_notBefore(cert.get()), X509_get0_notAfter(cert.get())));
    RETURN_IF_ERROR(verifyCertificate(cert_path, cert.get(), ca_path, ca.get(), crl.get()));
    ASSIGN_OR_RETURN(const KeyPtr key, readPrivateKey(key_path));
    if (X509_check_private_key(cert.get(), key.get()) != 1) {
        ERR_clear_error();
        return fileError(key_path, "is not the private key of " + cert_path.string() + " (the two do not match)");
    }

    ASSIGN_OR_RETURN(const X509Ptr pca, readCertificate(pca_path));
    RETURN_IF_ERROR(checkDates(pca_path, "the site's permissions CA", X509_get0_notBefore(pca.get()),
                               X509_get0_notAfter(pca.get())));
    ASSIGN_OR_RETURN(const std::string governance, verifySigned(gov_path, pca.get(), pca_path));
    if (governance.find("<domain_access_rules>") == std::string::npos) {
        return fileError(gov_path, "has no <domain_access_rules>: not a governance document");
    }
    ASSIGN_OR_RETURN(const std::string permissions, verifySigned(perm_path, pca.get(), pca_path));
    SecurityIdentity identity;
    RETURN_IF_ERROR(checkPermissions(perm_path, permissions, cert.get(), identity.valid_until));

    const X509_NAME* subject = X509_get_subject_name(cert.get());
    identity.dir = dir;
    identity.name = nameField(subject, NID_commonName);
    identity.role = nameField(subject, NID_organizationalUnitName);
    identity.site = nameField(subject, NID_organizationName);
    // The earlier end wins: the certificate and the permissions are issued together by site.sh.
    identity.valid_until = std::min(identity.valid_until, timeText(X509_get0_notAfter(cert.get())));
    return identity;
}

fs::path securityPluginDir() {
    if (const char* env = std::getenv("FACESCAN_DDS_SECURITY_PLUGIN_DIR"); env && *env) return env;
    return FACESCAN_DDS_SECURITY_PLUGIN_DIR;
}

std::string securityXml(const fs::path& dir, const fs::path& plugin_dir) {
    const fs::path abs = fs::absolute(dir).lexically_normal();
    auto file = [&](const char* name) { return "file:" + xmlEscape((abs / name).string()); };
    auto library = [&](int i, const char* init, const char* finalize) {
        return "<Library path=\"" + xmlEscape((plugin_dir / kPlugins[i][1]).string()) + "\" initFunction=\"" + init +
               "\" finalizeFunction=\"" + finalize + "\"/>";
    };
    using F = IdentityFiles;
    return "<Security>\n"
           "  <Authentication>\n    " +
           library(0, "init_authentication", "finalize_authentication") + "\n    <IdentityCA>" + file(F::kIdentityCa) +
           "</IdentityCA>\n    <IdentityCertificate>" + file(F::kCertificate) +
           "</IdentityCertificate>\n    <PrivateKey>" + file(F::kPrivateKey) + "</PrivateKey>\n    <CRL>" +
           file(F::kRevocationList) +
           "</CRL>\n  </Authentication>\n"
           "  <AccessControl>\n    " +
           library(1, "init_access_control", "finalize_access_control") + "\n    <PermissionsCA>" +
           file(F::kPermissionsCa) + "</PermissionsCA>\n    <Governance>" + file(F::kGovernance) +
           "</Governance>\n    <Permissions>" + file(F::kPermissions) +
           "</Permissions>\n  </AccessControl>\n"
           "  <Cryptographic>\n    " +
           library(2, "init_crypto", "finalize_crypto") +
           "\n  </Cryptographic>\n"
           "</Security>\n";
}

StatusOr<std::string> addSecurity(const std::string& profile_xml, const fs::path& dir) {
    RETURN_IF_ERROR(checkIdentity(dir).status());
    const fs::path plugin_dir = securityPluginDir();
    for (const auto& plugin : kPlugins) {
        std::error_code ec;
        if (!fs::exists(plugin_dir / plugin[1], ec)) {
            return notFound("DDS Security: the " + std::string(plugin[0]) + " plugin " +
                            (plugin_dir / plugin[1]).string() +
                            " is missing: install Debian's libddsc0debian (or set FACESCAN_DDS_SECURITY_PLUGIN_DIR)");
        }
    }
    const size_t end = profile_xml.rfind("</Domain>");
    if (end == std::string::npos) {
        return invalidArgument("DDS Security: the DDS profile has no <Domain> element to add <Security> to");
    }
    if (profile_xml.find("<Security>") != std::string::npos) {
        return invalidArgument(
            "DDS Security: the DDS profile has its own <Security> element; use it without --security");
    }
    return profile_xml.substr(0, end) + securityXml(dir, plugin_dir) + profile_xml.substr(end);
}

}  // namespace facescan::wire
