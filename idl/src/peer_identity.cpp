// The authenticated identity of a remote writer (wire/peer_identity.hpp): its participant's certificate from
// USER_DATA, verified with OpenSSL against the site's CA and revocation list and bound to the participant's GUID
// the way Cyclone's authentication plugin binds it (the adjusted GUID of DDS Security 1.1, 9.3.3).
#include "wire/peer_identity.hpp"

#include <openssl/bio.h>
#include <openssl/pem.h>
#include <openssl/sha.h>
#include <openssl/x509.h>
#include <openssl/x509_vfy.h>

#include <cstring>
#include <fstream>
#include <sstream>

#include "openssl_ptr.hpp"
#include "wire/security.hpp"

namespace facescan::wire {
namespace fs = std::filesystem;
namespace {

constexpr const char* kUserDataTag = "facescan-identity-certificate\n";
constexpr size_t kMaxKnown = 4096;  // participants whose subject is cached

using openssl::BioPtr;
using openssl::CrlPtr;
using openssl::StoreCtxPtr;
using openssl::StorePtr;
using openssl::X509Ptr;

StatusOr<std::string> readWhole(const fs::path& path) {
    std::ifstream in(path, std::ios::binary);
    if (!in) return notFound("DDS Security: cannot read " + path.string());
    std::ostringstream text;
    text << in.rdbuf();
    return text.str();
}

BioPtr memoryBio(const std::string& text) {
    return BioPtr(BIO_new_mem_buf(text.data(), static_cast<int>(text.size())));
}

std::string subjectText(const X509_NAME* name) {
    BioPtr bio(BIO_new(BIO_s_mem()));
    X509_NAME_print_ex(bio.get(), name, 0, XN_FLAG_RFC2253);
    char* data = nullptr;
    const long size = BIO_get_mem_data(bio.get(), &data);
    return size > 0 ? std::string(data, static_cast<size_t>(size)) : std::string();
}

std::array<uint8_t, 16> guidBytes(const dds_guid_t& guid) {
    std::array<uint8_t, 16> bytes{};
    std::memcpy(bytes.data(), guid.v, bytes.size());
    return bytes;
}

}  // namespace

StatusOr<std::string> identityUserData(const fs::path& dir) {
    ASSIGN_OR_RETURN(std::string pem, readWhole(dir / IdentityFiles::kCertificate));
    return std::string(kUserDataTag) + pem;
}

std::array<uint8_t, 6> adjustedGuidPrefix(const std::string& subject_der) {
    // 9.3.3: bit 47 set, then the first 47 bits of SHA-256(subject), shifted right by one.
    uint8_t hash[SHA256_DIGEST_LENGTH];
    SHA256(reinterpret_cast<const unsigned char*>(subject_der.data()), subject_der.size(), hash);
    std::array<uint8_t, 6> prefix{};
    uint8_t high_bit = 0x80;
    for (size_t i = 0; i < prefix.size(); ++i) {
        prefix[i] = static_cast<uint8_t>(high_bit | (hash[i] >> 1));
        high_bit = static_cast<uint8_t>(hash[i] << 7);
    }
    return prefix;
}

StatusOr<std::unique_ptr<PeerIdentities>> PeerIdentities::create(const Participant& participant,
                                                                 const fs::path& identity_dir) {
    std::unique_ptr<PeerIdentities> p(new PeerIdentities());
    ASSIGN_OR_RETURN(p->ca_pem_, readWhole(identity_dir / IdentityFiles::kIdentityCa));
    ASSIGN_OR_RETURN(p->crl_pem_, readWhole(identity_dir / IdentityFiles::kRevocationList));
    const dds_entity_t reader =
        dds_create_reader(participant.handle(), DDS_BUILTIN_TOPIC_DCPSPARTICIPANT, nullptr, nullptr);
    if (reader < 0) return ddsStatus(reader, "create a reader of the discovered participants");
    p->participants_ = Entity(reader);
    return p;
}

PeerIdentities::~PeerIdentities() = default;

StatusOr<std::string> PeerIdentities::subjectOf(dds_entity_t reader, dds_instance_handle_t publication) {
    dds_builtintopic_endpoint_t* endpoint = dds_get_matched_publication_data(reader, publication);
    if (!endpoint) return notFound("its writer is no longer matched (the sender has left)");
    const dds_guid_t participant = endpoint->participant_key;
    const dds_instance_handle_t participant_handle = endpoint->participant_instance_handle;
    dds_builtintopic_free_endpoint(endpoint);
    const auto key = guidBytes(participant);
    {
        std::lock_guard lock(mutex_);
        if (const auto it = known_.find(key); it != known_.end()) return it->second;
    }
    // Its participant's discovery data: the instance of the built-in topic, or (another handle space) a search.
    std::string user_data;
    bool found = false;
    auto take = [&](const dds_builtintopic_participant_t& sample) {
        if (std::memcmp(sample.key.v, participant.v, sizeof(participant.v)) != 0) return;
        void* value = nullptr;
        size_t size = 0;
        if (sample.qos && dds_qget_userdata(sample.qos, &value, &size) && value) {
            user_data.assign(static_cast<const char*>(value), size);
        }
        dds_free(value);
        found = true;
    };
    {
        void* samples[1] = {nullptr};
        dds_sample_info_t infos[1];
        const dds_return_t n = dds_read_instance(participants_.handle(), samples, infos, 1, 1, participant_handle);
        if (n > 0) {
            if (infos[0].valid_data) take(*static_cast<const dds_builtintopic_participant_t*>(samples[0]));
            dds_return_loan(participants_.handle(), samples, n);
        }
    }
    if (!found) {
        constexpr size_t kMax = 256;
        void* samples[kMax] = {nullptr};
        dds_sample_info_t infos[kMax];
        const dds_return_t n = dds_read(participants_.handle(), samples, infos, kMax, kMax);
        for (dds_return_t i = 0; i < n; ++i) {
            if (infos[i].valid_data) take(*static_cast<const dds_builtintopic_participant_t*>(samples[i]));
        }
        if (n > 0) dds_return_loan(participants_.handle(), samples, n);
    }
    if (!found) return notFound("its participant is no longer discovered");
    ASSIGN_OR_RETURN(std::string subject, verifiedSubject(participant, user_data));
    std::lock_guard lock(mutex_);
    // Every client run is a new participant: the cache is bounded, a forgotten one is verified again.
    if (known_.size() >= kMaxKnown) known_.clear();
    known_[key] = subject;
    return subject;
}

StatusOr<std::string> PeerIdentities::verifiedSubject(const dds_guid_t& participant,
                                                      const std::string& user_data) const {
    if (user_data.rfind(kUserDataTag, 0) != 0) {
        return permissionDenied("its participant announces no identity certificate (an older facescan?)");
    }
    const std::string pem = user_data.substr(std::strlen(kUserDataTag));
    BioPtr bio = memoryBio(pem);
    X509Ptr cert(PEM_read_bio_X509(bio.get(), nullptr, nullptr, nullptr));
    if (!cert) return permissionDenied("the certificate its participant announces is not PEM");
    BioPtr ca_bio = memoryBio(ca_pem_), crl_bio = memoryBio(crl_pem_);
    X509Ptr ca(PEM_read_bio_X509(ca_bio.get(), nullptr, nullptr, nullptr));
    CrlPtr crl(PEM_read_bio_X509_CRL(crl_bio.get(), nullptr, nullptr, nullptr));
    StorePtr store(X509_STORE_new());
    StoreCtxPtr ctx(X509_STORE_CTX_new());
    if (!ca || !crl || !store || !ctx || X509_STORE_add_cert(store.get(), ca.get()) != 1 ||
        X509_STORE_add_crl(store.get(), crl.get()) != 1) {
        return internalError("DDS Security: cannot load this identity's CA and revocation list with OpenSSL");
    }
    X509_STORE_set_flags(store.get(), X509_V_FLAG_CRL_CHECK);
    if (X509_STORE_CTX_init(ctx.get(), store.get(), cert.get(), nullptr) != 1 || X509_verify_cert(ctx.get()) != 1) {
        return permissionDenied("the certificate its participant announces does not verify against the site's CA: " +
                                std::string(X509_verify_cert_error_string(X509_STORE_CTX_get_error(ctx.get()))));
    }
    const X509_NAME* name = X509_get_subject_name(cert.get());
    unsigned char* der = nullptr;
    const int der_size = i2d_X509_NAME(name, &der);
    if (der_size <= 0) return internalError("DDS Security: cannot encode a certificate subject");
    const std::string subject_der(reinterpret_cast<const char*>(der), static_cast<size_t>(der_size));
    OPENSSL_free(der);
    const auto prefix = adjustedGuidPrefix(subject_der);
    if (std::memcmp(prefix.data(), participant.v, prefix.size()) != 0) {
        return permissionDenied("its participant announces the certificate of '" + subjectText(name) +
                                "', which is not the identity it authenticated with");
    }
    return subjectText(name);
}

}  // namespace facescan::wire
