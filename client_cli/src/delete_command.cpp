// `facescan delete SESSION [--force]`: asks every server on the domain to erase one scan (EraseRequest), waits for
// each live server's EraseReport and prints what each removed. A scan still being scanned is refused unless
// --force, which finishes it first. Servers pass the request on, so one that is down now erases its copy when it
// comes back (recon_server/service/erasure_service.hpp).
#include <unistd.h>

#include <chrono>
#include <cstdio>
#include <map>
#include <set>
#include <thread>

#include "command_util.hpp"
#include "wire/topics.hpp"

namespace facescan::client::detail {

int runDelete(const CliOptions& options) {
    using namespace std::chrono_literals;
    int code = kExitOk;
    auto client = connectOrFail(options, code);
    if (!client) return code;
    const auto settle = std::chrono::milliseconds(std::min<int64_t>(1000, options.timeout.count()));
    auto servers = client->servers(settle, options.timeout);
    if (!servers.isOk()) return fail(exitCodeForRequest(servers.status()), servers.status().message());
    auto sessions = client->sessions(std::chrono::milliseconds(600));
    if (!sessions.isOk()) return fail(exitCodeForRequest(sessions.status()), sessions.status().message());
    for (const SessionStatus& s : *sessions) {
        if (s.session_id != options.session || s.state == facescan_wire_STATE_FINISHED ||
            s.state == facescan_wire_STATE_REFUSED) {
            continue;
        }
        if (!options.force) {
            return fail(kExitServerError, "session " + options.session + " is still being scanned on " + s.server_id +
                                              ": finish it first (facescan finish " + options.session +
                                              "), or give --force to finish it now and delete it");
        }
        auto finished = client->request(options.session, facescan_wire_CMD_FINISH);
        if (!finished.isOk()) return fail(exitCodeForRequest(finished.status()), finished.status().message());
        std::printf("finished %s on %s (--force)\n", options.session.c_str(), finished->server_id.c_str());
    }

    auto participant = wire::Participant::create(options.domain);
    if (!participant.isOk()) return fail(kExitNoServer, participant.status().message());
    auto request_topic = wire::Topic<facescan_wire_EraseRequest>::create(*participant);
    auto report_topic = wire::Topic<facescan_wire_EraseReport>::create(*participant);
    if (!request_topic.isOk() || !report_topic.isOk()) {
        return fail(kExitNotAllowed, (request_topic.isOk() ? report_topic.status() : request_topic.status()).message());
    }
    auto writer = wire::Writer<facescan_wire_EraseRequest>::create(*request_topic);
    auto reader = wire::Reader<facescan_wire_EraseReport>::create(*report_topic);
    if (!writer.isOk() || !reader.isOk()) {
        return fail(kExitNotAllowed,
                    (writer.isOk() ? reader.status() : writer.status()).message() +
                        " (this identity may not delete scans: a client identity enrolled after erasure existed can)");
    }
    std::set<std::string> waiting;
    for (const ServerInfo& s : *servers) waiting.insert(s.server_id);
    // Every live server's reader first, so none misses the request's first delivery.
    (void)writer->waitForReaders(static_cast<int>(waiting.size()), std::chrono::milliseconds(2000));
    const std::string request_id = client->clientId() + ":delete:" + std::to_string(::getpid());
    facescan_wire_EraseRequest m{};
    m.session_id = wire::stringView(options.session);
    m.request_id = wire::stringView(request_id);
    m.client_id = wire::stringView(client->clientId());
    if (Status s = writer->write(m); !s.isOk()) return fail(kExitNoServer, s.message());

    int refused = 0, answered = 0;
    const auto deadline = std::chrono::steady_clock::now() + options.timeout;
    while (!waiting.empty() && std::chrono::steady_clock::now() < deadline) {
        auto n = reader->take([&](const facescan_wire_EraseReport& r, const dds_sample_info_t& info) {
            if (!info.valid_data || wire::fromDds(r.request_id) != request_id) return;
            const std::string server = wire::fromDds(r.server_id);
            if (!waiting.erase(server)) return;
            ++answered;
            if (!r.ok) {
                ++refused;
                std::printf("%s: NOT erased: %s\n", server.c_str(), wire::fromDds(r.error).c_str());
                return;
            }
            if (r.removed._length == 0) {
                std::printf("%s: nothing of %s was there (now recorded as erased)\n", server.c_str(),
                            options.session.c_str());
                return;
            }
            std::printf("%s: removed %u file(s):\n", server.c_str(), r.removed._length);
            for (uint32_t i = 0; i < r.removed._length; ++i) std::printf("  %s\n", r.removed._buffer[i]);
        });
        if (!n.isOk()) return fail(kExitNoServer, n.status().message());
        if (*n == 0) std::this_thread::sleep_for(50ms);
    }
    for (const std::string& server : waiting) std::printf("%s: no answer\n", server.c_str());
    if (answered == 0) return fail(kExitNoServer, "no server answered the erasure of " + options.session);
    std::printf("%s: erased on %d of %zu server(s)%s; servers down now erase it when they come back\n",
                options.session.c_str(), answered - refused, servers->size(),
                refused ? " (see above why not everywhere)" : "");
    return refused ? kExitServerError : kExitOk;
}

}  // namespace facescan::client::detail
