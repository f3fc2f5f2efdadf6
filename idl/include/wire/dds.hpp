// A thin RAII layer over the Cyclone DDS C API (Debian ships no cyclonedds-cxx). It owns entity handles and
// turns return codes into Status; everything else (discovery, reliability, history, durability, liveliness,
// fragmentation) is DDS's own work, configured through QoS (wire/qos.hpp) and the XML profiles in deploy/profiles.
#pragma once

#include <dds/dds.h>

#include <algorithm>
#include <chrono>
#include <cstdint>
#include <filesystem>
#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "recon/status.hpp"

namespace facescan::wire {

// A Cyclone return code (negative) as a Status that names the failed operation.
Status ddsStatus(dds_return_t code, const std::string& what);

// Which DDS domain, which network profile and which DDS Security identity. Profiles: "loopback" (this machine
// only; tests and demo), "lan" (discovery on the local network), or a path to a Cyclone XML file. Every program
// sets these from the same command-line options (wire/dds_options.hpp).
struct DomainConfig {
    // {domain, "loopback"} in tests, {0, "lan"} as programs' defaults: security stays off unless given.
    DomainConfig(uint32_t domain = 0, std::string profile_name = "lan", std::string security_dir = {})
        : domain_id(domain), profile(std::move(profile_name)), security(std::move(security_dir)) {}

    uint32_t domain_id = 0;       // DDS domain; separate domains never see each other
    std::string profile = "lan";  // loopback | lan | FILE.xml
    // An identity folder DIR/NAME of a site made by deploy/security/site.sh: enables OMG DDS Security
    // (authentication, access control, encryption) with it (wire/security.hpp). Empty: no DDS Security.
    std::string security;
    // How long a writer deleted with unacknowledged samples keeps resending them before it goes (Cyclone's
    // WriterLingerDuration, for the whole process, on top of the profile). Unset: Cyclone's default, 1 s. The
    // agent sets it short: when it stops, a stuck server's unacknowledged frames are saved on disk instead.
    std::optional<std::chrono::milliseconds> writer_linger;
    Status validate() const;
    // "domain 7 (profile lan, DDS Security identity DIR/NAME)": for messages.
    std::string describe() const;
};

// The file of a profile: FILE.xml as given; loopback and lan from $FACESCAN_PROFILE_DIR when set, else
// share/facescan/profiles of the installed or build tree (data_files.hpp). loadProfileXml reads it.
StatusOr<std::filesystem::path> findProfileFile(const std::string& profile);
StatusOr<std::string> loadProfileXml(const std::string& profile);

// Reads net.core.rmem_max and compares it with the SocketReceiveBufferSize min of the profile. When the kernel
// limit is lower, Cyclone cannot create the participant; the Status says exactly which sysctl to run.
Status checkSocketBuffers(const std::string& profile_xml);
// The profile's Discovery/LeaseDuration in seconds: how long a silent peer counts as alive. Cyclone's default
// (10 s) when the profile sets none or sets one that cannot be read.
double profileLeaseS(const std::string& profile_xml);

// An owned DDS entity handle; deleting it deletes its children (DDS semantics).
class Entity {
 public:
    Entity() = default;
    explicit Entity(dds_entity_t handle) : handle_(handle) {}
    ~Entity() { reset(); }
    Entity(Entity&& other) noexcept : handle_(std::exchange(other.handle_, 0)) {}
    Entity& operator=(Entity&& other) noexcept {
        if (this != &other) {
            reset();
            handle_ = std::exchange(other.handle_, 0);
        }
        return *this;
    }
    Entity(const Entity&) = delete;
    Entity& operator=(const Entity&) = delete;

    dds_entity_t handle() const { return handle_; }
    bool valid() const { return handle_ > 0; }
    void reset();

 private:
    dds_entity_t handle_ = 0;
};

class Qos {
 public:
    Qos() : qos_(dds_create_qos()) {}
    ~Qos() { dds_delete_qos(qos_); }
    Qos(const Qos& other) : qos_(dds_create_qos()) { dds_copy_qos(qos_, other.qos_); }
    Qos& operator=(const Qos& other) {
        if (this != &other) dds_copy_qos(qos_, other.qos_);
        return *this;
    }
    dds_qos_t* get() const { return qos_; }

 private:
    dds_qos_t* qos_;
};

// One domain participant. Several Participants of one process may share a domain; the domain (with its XML
// configuration) lives as long as any of them.
class Participant {
 public:
    static StatusOr<Participant> create(const DomainConfig& config);
    dds_entity_t handle() const { return entity_.handle(); }
    uint32_t domainId() const { return domain_id_; }
    // Other participants discovered on the domain so far (DDS's built-in DCPSParticipant topic), whoever they are;
    // -1 when it cannot be read. Participants of DDS Security are discovered even by one without it (but never
    // talk to it): "someone is here, nobody answers" is how an unsecured program learns it is on a secured domain.
    int otherParticipants() const;

 private:
    std::shared_ptr<Entity> domain_;
    Entity entity_;
    uint32_t domain_id_ = 0;
};

// A publisher (or subscriber) of one DDS partition under `participant`; an empty Entity for an empty partition
// (the writer or reader then lives in the default partition).
StatusOr<Entity> partitionParent(dds_entity_t participant, const std::string& partition, bool publisher);

// What a generated C type needs to become a topic: its descriptor, its topic name and its QoS profile.
// Specialised for every facescan topic in wire/topics.hpp.
template <typename T>
struct TopicTraits;

template <typename T>
class Topic {
 public:
    static StatusOr<Topic> create(const Participant& participant) {
        Topic topic;
        const Qos qos = TopicTraits<T>::qos();
        const dds_entity_t h = dds_create_topic(participant.handle(), TopicTraits<T>::descriptor(),
                                                TopicTraits<T>::name(), qos.get(), nullptr);
        if (h < 0) return ddsStatus(h, std::string("create topic ") + TopicTraits<T>::name());
        topic.entity_ = Entity(h);
        topic.participant_ = participant.handle();
        return topic;
    }
    dds_entity_t handle() const { return entity_.handle(); }
    dds_entity_t participant() const { return participant_; }

 private:
    Entity entity_;
    dds_entity_t participant_ = 0;
};

template <typename T>
class Writer {
 public:
    // `qos` overrides the topic's default writer QoS (e.g. keep-all for recordings that must not lose frames).
    // A non-empty `partition` puts the writer in its own publisher of that DDS partition: only readers of the
    // same partition match (wire::sessionPartition routes a session's frames to its owner alone).
    static StatusOr<Writer> create(const Topic<T>& topic, const Qos* qos = nullptr, const std::string& partition = {}) {
        Writer writer;
        ASSIGN_OR_RETURN(writer.publisher_, partitionParent(topic.participant(), partition, /*publisher=*/true));
        const dds_entity_t parent = writer.publisher_.valid() ? writer.publisher_.handle() : topic.participant();
        const Qos defaults = TopicTraits<T>::qos();
        const dds_entity_t h = dds_create_writer(parent, topic.handle(), qos ? qos->get() : defaults.get(), nullptr);
        if (h < 0) return ddsStatus(h, std::string("create writer for ") + TopicTraits<T>::name());
        writer.entity_ = Entity(h);
        return writer;
    }
    // Blocks at most the QoS max_blocking_time when a reliable keep-all history is full (back-pressure).
    Status write(const T& sample) {
        const dds_return_t rc = dds_write(entity_.handle(), &sample);
        return rc < 0 ? ddsStatus(rc, std::string("write ") + TopicTraits<T>::name()) : Status::ok();
    }
    // The same with the source timestamp given: a sample written again keeps the first one's, which readers may
    // use as an order that every one of them agrees on (a late joiner only ever sees the last sample).
    Status writeAt(const T& sample, dds_time_t source_timestamp) {
        const dds_return_t rc = dds_write_ts(entity_.handle(), &sample, source_timestamp);
        return rc < 0 ? ddsStatus(rc, std::string("write ") + TopicTraits<T>::name()) : Status::ok();
    }
    // Tells readers this instance (session) is gone for good.
    Status dispose(const T& key_sample) {
        const dds_return_t rc = dds_writedispose(entity_.handle(), &key_sample);
        return rc < 0 ? ddsStatus(rc, "writedispose") : Status::ok();
    }
    // Forgets the instance (session): its last sample leaves the writer's history, so late-joining readers no
    // longer get it; readers see it disposed when the writer auto-disposes (the default QoS).
    Status unregister(const T& key_sample) {
        const dds_return_t rc = dds_unregister_instance(entity_.handle(), &key_sample);
        return rc < 0 ? ddsStatus(rc, "unregister instance") : Status::ok();
    }
    // Number of matched readers (discovery).
    int matchedReaders() const {
        dds_publication_matched_status_t st{};
        return dds_get_publication_matched_status(entity_.handle(), &st) < 0 ? 0 : static_cast<int>(st.current_count);
    }
    // Waits until at least `count` readers are matched; false on timeout.
    bool waitForReaders(int count, std::chrono::milliseconds timeout) const;
    // Waits until every sample written so far is acknowledged by all reliable readers.
    Status waitForAcks(std::chrono::milliseconds timeout) {
        const dds_return_t rc = dds_wait_for_acks(entity_.handle(), DDS_MSECS(timeout.count()));
        return rc < 0 ? ddsStatus(rc, "wait for acknowledgements") : Status::ok();
    }
    dds_entity_t handle() const { return entity_.handle(); }

 private:
    Entity publisher_;  // declared first: destroyed after the writer
    Entity entity_;
};

template <typename T>
class Reader {
 public:
    // A non-empty `partition`: the reader gets its own subscriber of that DDS partition (see Writer::create).
    static StatusOr<Reader> create(const Topic<T>& topic, const Qos* qos = nullptr, const std::string& partition = {}) {
        Reader reader;
        ASSIGN_OR_RETURN(reader.subscriber_, partitionParent(topic.participant(), partition, /*publisher=*/false));
        const dds_entity_t parent = reader.subscriber_.valid() ? reader.subscriber_.handle() : topic.participant();
        const Qos defaults = TopicTraits<T>::qos();
        const dds_entity_t h = dds_create_reader(parent, topic.handle(), qos ? qos->get() : defaults.get(), nullptr);
        if (h < 0) return ddsStatus(h, std::string("create reader for ") + TopicTraits<T>::name());
        reader.entity_ = Entity(h);
        const dds_entity_t ws = dds_create_waitset(topic.participant());
        if (ws < 0) return ddsStatus(ws, "create waitset");
        reader.waitset_ = Entity(ws);
        const dds_entity_t cond = dds_create_readcondition(h, DDS_ANY_STATE);
        if (cond < 0) return ddsStatus(cond, "create read condition");
        const dds_return_t rc = dds_waitset_attach(ws, cond, h);
        if (rc < 0) return ddsStatus(rc, "attach read condition");
        return reader;
    }

    // Takes up to `max_samples` samples (loaned, zero-copy) and calls fn(const T&, const dds_sample_info_t&)
    // for each; invalid samples (instance state changes, e.g. a writer that died) are passed too, with
    // info.valid_data false. Returns the number of samples seen, or an error.
    template <typename Fn>
    StatusOr<int> take(Fn&& fn, int max_samples = 16) {
        constexpr int kBatch = 16;
        void* samples[kBatch];
        dds_sample_info_t infos[kBatch];
        int seen = 0;
        while (seen < max_samples) {
            samples[0] = nullptr;
            const int want = std::min(kBatch, max_samples - seen);
            const dds_return_t n =
                dds_take(entity_.handle(), samples, infos, static_cast<size_t>(want), static_cast<uint32_t>(want));
            if (n < 0) return ddsStatus(n, std::string("take ") + TopicTraits<T>::name());
            for (int i = 0; i < n; ++i) fn(*static_cast<const T*>(samples[i]), infos[i]);
            if (n > 0) dds_return_loan(entity_.handle(), samples, n);
            seen += n;
            if (n < want) break;
        }
        return seen;
    }

    // Like take, but leaves the samples in the reader (e.g. to look at durable state without consuming it).
    template <typename Fn>
    StatusOr<int> read(Fn&& fn, int max_samples = 16) {
        constexpr int kBatch = 16;
        void* samples[kBatch];
        dds_sample_info_t infos[kBatch];
        samples[0] = nullptr;
        const int want = std::min(kBatch, max_samples);
        const dds_return_t n =
            dds_read(entity_.handle(), samples, infos, static_cast<size_t>(want), static_cast<uint32_t>(want));
        if (n < 0) return ddsStatus(n, std::string("read ") + TopicTraits<T>::name());
        for (int i = 0; i < n; ++i) fn(*static_cast<const T*>(samples[i]), infos[i]);
        if (n > 0) dds_return_loan(entity_.handle(), samples, n);
        return static_cast<int>(n);
    }

    // Blocks until data (or an instance state change) is available, or the timeout passes; false on timeout.
    bool waitForData(std::chrono::milliseconds timeout) {
        const dds_return_t rc = dds_waitset_wait(waitset_.handle(), nullptr, 0, DDS_MSECS(timeout.count()));
        return rc > 0;
    }
    int matchedWriters() const {
        dds_subscription_matched_status_t st{};
        return dds_get_subscription_matched_status(entity_.handle(), &st) < 0 ? 0 : static_cast<int>(st.current_count);
    }
    bool waitForWriters(int count, std::chrono::milliseconds timeout) const;
    // The instance handles of the writers matched now (their participants are still discovered), whatever
    // their liveliness: a writer here whose instance reads not alive belongs to a process that is there but
    // has stopped asserting it.
    std::vector<dds_instance_handle_t> matchedPublications() const {
        std::vector<dds_instance_handle_t> handles(static_cast<size_t>(std::max(matchedWriters(), 0)) + 8);
        const dds_return_t n = dds_get_matched_publications(entity_.handle(), handles.data(), handles.size());
        handles.resize(n < 0 ? 0 : std::min(static_cast<size_t>(n), handles.size()));
        return handles;
    }
    dds_entity_t handle() const { return entity_.handle(); }

 private:
    Entity subscriber_;  // declared first: destroyed after the reader
    Entity entity_;
    Entity waitset_;
};

// Waits for data on several readers at once: a DDS waitset holding each attached reader's read condition (the
// conditions belong to their readers and go with them).
class WaitSet {
 public:
    static StatusOr<WaitSet> create(const Participant& participant) {
        WaitSet waitset;
        const dds_entity_t ws = dds_create_waitset(participant.handle());
        if (ws < 0) return ddsStatus(ws, "create waitset");
        waitset.waitset_ = Entity(ws);
        return waitset;
    }
    template <typename T>
    Status attach(const Reader<T>& reader) {
        const dds_entity_t cond = dds_create_readcondition(reader.handle(), DDS_ANY_STATE);
        if (cond < 0) return ddsStatus(cond, "create read condition");
        const dds_return_t rc = dds_waitset_attach(waitset_.handle(), cond, reader.handle());
        return rc < 0 ? ddsStatus(rc, "attach read condition") : Status::ok();
    }
    // Blocks until any attached reader has data (or an instance state change), or the timeout passes.
    bool wait(std::chrono::milliseconds timeout) {
        return dds_waitset_wait(waitset_.handle(), nullptr, 0, DDS_MSECS(timeout.count())) > 0;
    }

 private:
    Entity waitset_;
};

// Polls `done` every few milliseconds until it returns true or the timeout passes (discovery waits).
bool pollUntil(const std::function<bool()>& done, std::chrono::milliseconds timeout);

template <typename T>
bool Writer<T>::waitForReaders(int count, std::chrono::milliseconds timeout) const {
    return pollUntil([&] { return matchedReaders() >= count; }, timeout);
}
template <typename T>
bool Reader<T>::waitForWriters(int count, std::chrono::milliseconds timeout) const {
    return pollUntil([&] { return matchedWriters() >= count; }, timeout);
}

// A created entity moved to the heap (members that are made after their owner's constructor).
template <typename T>
StatusOr<std::unique_ptr<T>> boxed(StatusOr<T> v) {
    if (!v.isOk()) return v.status();
    return std::make_unique<T>(std::move(v).value());
}

// Borrowing views for writing string fields (no copy; DDS never frees them).
inline char* stringView(const std::string& s) { return const_cast<char*>(s.c_str()); }
// A received string field (may be null in a malformed sample).
inline std::string fromDds(const char* s) { return s ? std::string(s) : std::string(); }

}  // namespace facescan::wire
