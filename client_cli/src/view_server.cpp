// The viewer's HTTP and WebSocket side on CivetWeb (client/view_server.hpp). CivetWeb parses HTTP and WebSocket
// frames; this file routes requests, answers from memory (assets, snapshots, JSON) and runs one sender thread per
// browser over the ViewHub.
#include "client/view_server.hpp"

#include <arpa/inet.h>
#include <civetweb.h>
#include <unistd.h>

#include <cstring>
#include <map>
#include <mutex>
#include <optional>
#include <thread>

#include "client/mesh_file.hpp"
#include "client/status_json.hpp"
#include "client/textured_mesh_file.hpp"
#include "client/tls_front.hpp"
#include "client/view_logins.hpp"
#include "view_auth.hpp"
#include "wire/audit_log.hpp"
#include "wire/mesh_codec.hpp"
#include "wire/messages.hpp"

namespace facescan::client {

namespace {

std::string jsonError(const std::string& message) { return "{\"error\":" + jsonString(message) + "}"; }

// One response with a body (none for HEAD). CivetWeb writes the status line and headers.
// API answers are live data: no-store unless told (assets bring their own caching headers).
void respond(mg_connection* conn, int status, const char* mime, std::string_view body,
             const std::vector<std::pair<std::string, std::string>>& headers = {}, bool no_store = true) {
    mg_response_header_start(conn, status);
    mg_response_header_add(conn, "Content-Type", mime, -1);
    if (no_store) mg_response_header_add(conn, "Cache-Control", "no-store", -1);
    mg_response_header_add(conn, "Content-Length", std::to_string(body.size()).c_str(), -1);
    for (const auto& [name, value] : headers) mg_response_header_add(conn, name.c_str(), value.c_str(), -1);
    mg_response_header_send(conn);
    const mg_request_info* ri = mg_get_request_info(conn);
    if (std::strcmp(ri->request_method, "HEAD") != 0 && !body.empty()) mg_write(conn, body.data(), body.size());
}

int respondError(mg_connection* conn, int status, const std::string& message) {
    respond(conn, status, "application/json", jsonError(message));
    return status;
}

}  // namespace

Status ViewServerConfig::validate() const {
    in_addr v4{};
    in6_addr v6{};
    if (::inet_pton(AF_INET, bind.c_str(), &v4) != 1 && ::inet_pton(AF_INET6, bind.c_str(), &v6) != 1) {
        return invalidArgument(
            "--bind needs an IP address of this machine (127.0.0.1, 0.0.0.0 for the LAN, ::1), got '" + bind + "'");
    }
    if (threads < 4 || threads > 1024) return invalidArgument("ViewServerConfig: threads must be 4..1024");
    if (!isLoopbackAddress(bind) && !insecure_http && tls_dir.empty()) {
        return invalidArgument(
            "--bind " + bind +
            " would serve every scan (a face: personal data) in plain HTTP, without a login, to anyone who "
            "reaches this port. Serve it over TLS with a login: on the site's machine `facescan-site web SITE NAME "
            "--host THIS-HOST` and `facescan-site login SITE NAME USER`, then `facescan view --bind " +
            bind +
            " --tls SITE/NAME`. Or keep it on 127.0.0.1 and reach it through SSH (ssh -L 8080:127.0.0.1:8080 "
            "THIS-HOST, then http://127.0.0.1:8080/ there), or give --insecure-http on a network where every "
            "machine may see the scans (it warns at every start)");
    }
    return Status::ok();
}

bool isLoopbackAddress(const std::string& ip) {
    in_addr v4{};
    if (::inet_pton(AF_INET, ip.c_str(), &v4) == 1) return (ntohl(v4.s_addr) >> 24) == 127;
    in6_addr v6{};
    if (::inet_pton(AF_INET6, ip.c_str(), &v6) != 1) return false;
    if (IN6_IS_ADDR_LOOPBACK(&v6)) return true;
    return IN6_IS_ADDR_V4MAPPED(&v6) && v6.s6_addr[12] == 127;
}

// One browser's WebSocket: its cursor in the hub and the thread that sends it what is new.
struct Browser {
    mg_connection* conn = nullptr;
    std::string who;  // the audit trail's identity: "login USER" or "http ADDRESS"
    ViewHub::Cursor cursor;
    std::thread sender;
};

struct ViewServer::Impl {
    ViewServerConfig config;
    std::vector<LoadedAsset> assets;
    ViewHub* hub = nullptr;
    MeshFetcher fetch_mesh;
    mg_context* ctx = nullptr;
    mutable std::mutex browsers_mutex;
    std::map<const mg_connection*, std::unique_ptr<Browser>> browsers;
    std::unique_ptr<LoginBook> logins;      // with TLS: who may see anything; null: plain HTTP, no login
    std::unique_ptr<TlsFront> front;        // with TLS: the browsers' port; CivetWeb listens on loopback behind it
    std::unique_ptr<wire::AuditLog> audit;  // config.audit_file: downloads, snapshots, follows and logins
    std::string recorder;                   // "viewer HOST"

    // Who a request comes from, for the audit trail: the viewer login, or the address of a browser without one.
    std::string who(const mg_connection* conn) const {
        if (logins) {
            if (auto user = detail::sessionUser(conn, *logins)) return "login " + *user;
            return "login (none)";
        }
        return std::string("http ") + mg_get_request_info(conn)->remote_addr;
    }
    void record(const std::string& action, const std::string& session, const std::string& identity,
                const std::string& outcome) const {
        if (!audit) return;
        wire::AuditRecord r;
        r.action = action;
        r.session = session;
        r.identity = identity;
        r.outcome = outcome;
        r.recorder = recorder;
        if (const Status s = audit->append(std::move(r)); !s.isOk()) {
            std::fprintf(stderr, "facescan view: %s\n", s.message().c_str());
        }
    }

    // With TLS, the browser's address for this connection; nullopt when it did not come through the TLS front
    // (somebody on this machine at CivetWeb's loopback port).
    std::optional<std::string> clientAddress(const mg_connection* conn) const {
        const mg_request_info* ri = mg_get_request_info(conn);
        return front ? front->clientAddress(static_cast<uint16_t>(ri->remote_port)) : std::nullopt;
    }

    int handleRequest(mg_connection* conn);
    int handleApi(mg_connection* conn, std::string_view rest);
    int sendAsset(mg_connection* conn, const LoadedAsset& asset);
    int sendMesh(mg_connection* conn, const std::string& session, const std::string& extension);
    int sendTextured(mg_connection* conn, const std::string& session);
    int respondFetchError(mg_connection* conn, const Status& status);

    // Writes one WebSocket message; false once the browser is gone.
    static bool send(mg_connection* conn, int opcode, std::string_view bytes) {
        mg_lock_connection(conn);
        const int rc = mg_websocket_write(conn, opcode, bytes.data(), bytes.size());
        mg_unlock_connection(conn);
        return rc > 0;
    }

    void senderLoop(Browser* browser) {
        while (true) {
            const ViewHub::Update update = hub->next(browser->cursor, std::chrono::seconds(1));
            if (update.closed) return;
            if (update.sessions_json && !send(browser->conn, MG_WEBSOCKET_OPCODE_TEXT, *update.sessions_json)) return;
            if (update.snapshot && !send(browser->conn, MG_WEBSOCKET_OPCODE_BINARY, update.snapshot->message)) return;
        }
    }
};

int ViewServer::Impl::handleRequest(mg_connection* conn) {
    const mg_request_info* ri = mg_get_request_info(conn);
    const std::string_view method = ri->request_method;
    const std::string_view uri = ri->local_uri ? ri->local_uri : "";
    if (logins) {  // nothing but the login page without a session
        const auto address = clientAddress(conn);
        if (!address) return respondError(conn, 403, "connect with https:// to the viewer's port");
        if (uri == "/login") {
            return detail::handleLogin(conn, *logins, config.login.session_max_s, *address,
                                       [this](const std::string& user, const std::string& outcome) {
                                           record("login", "", "login " + user, outcome);
                                       });
        }
        if (uri == "/logout" && method == "POST") return detail::handleLogout(conn, *logins);
        if (!detail::sessionUser(conn, *logins)) return detail::refuseWithoutLogin(conn, std::string(uri));
    }
    if (method != "GET" && method != "HEAD") {
        respond(conn, 405, "application/json", jsonError("only GET and HEAD are served, not " + std::string(method)),
                {{"Allow", "GET, HEAD"}});
        return 405;
    }
    if (uri == "/api/sessions" || uri.starts_with("/api/sessions/")) {
        const int status = handleApi(conn, uri.substr(13));
        // A scan's data leaving the viewer: its snapshot or its mesh, by whom, and whether it went.
        const std::string_view rest = uri.substr(std::min<size_t>(uri.size(), 14));
        const size_t slash = rest.find('/');
        if (slash != std::string_view::npos) {
            const std::string_view what = rest.substr(slash + 1);
            const char* action = what == "snapshot.drc"      ? "snapshot"
                                 : what.starts_with("mesh.") ? "download"
                                 : what == "textured"        ? "textured model"
                                                             : nullptr;
            if (action) {
                record(action + (what.starts_with("mesh.") ? " " + std::string(what.substr(5)) : std::string()),
                       std::string(rest.substr(0, slash)), who(conn),
                       status == 200 ? "ok" : "error: HTTP " + std::to_string(status));
            }
        }
        return status;
    }
    for (const LoadedAsset& asset : assets) {
        if (uri == asset.url) return sendAsset(conn, asset);
    }
    return respondError(conn, 404, "no such page: " + std::string(uri));
}

// From memory: gzipped when the browser accepts it, 304 when it has this version (no-cache: it always asks, so a
// new viewer's page is never stale).
int ViewServer::Impl::sendAsset(mg_connection* conn, const LoadedAsset& asset) {
    const char* if_none_match = mg_get_header(conn, "If-None-Match");
    if (if_none_match && asset.etag == if_none_match) {
        mg_response_header_start(conn, 304);
        mg_response_header_add(conn, "ETag", asset.etag.c_str(), -1);
        mg_response_header_add(conn, "Cache-Control", "no-cache", -1);
        mg_response_header_send(conn);
        return 304;
    }
    const char* accept = mg_get_header(conn, "Accept-Encoding");
    const bool gzip = accept && std::string_view(accept).find("gzip") != std::string_view::npos;
    std::vector<std::pair<std::string, std::string>> headers = {
        {"ETag", asset.etag}, {"Cache-Control", "no-cache"}, {"Vary", "Accept-Encoding"}};
    if (gzip) headers.emplace_back("Content-Encoding", "gzip");
    respond(conn, 200, asset.mime.c_str(), gzip ? asset.gzip : asset.identity, headers, /*no_store=*/false);
    return 200;
}

int ViewServer::Impl::handleApi(mg_connection* conn, std::string_view rest) {
    if (rest.empty() || rest == "/") {
        respond(conn, 200, "application/json", *hub->sessionsJson());
        return 200;
    }
    rest.remove_prefix(1);  // the '/'
    const size_t slash = rest.find('/');
    const std::string session(rest.substr(0, slash));
    const std::string what = slash == std::string_view::npos ? std::string() : std::string(rest.substr(slash + 1));
    if (Status s = wire::validateSessionId(session); !s.isOk()) {
        return respondError(conn, 400, "bad session id '" + session + "': " + s.message());
    }
    if (what.empty()) {
        const auto status = hub->session(session);
        if (!status) return respondError(conn, 404, "unknown session '" + session + "'");
        respond(conn, 200, "application/json", statusJson(*status, /*with_alive=*/true));
        return 200;
    }
    if (what == "snapshot.drc") {
        const auto snapshot = hub->snapshot(session);
        if (!snapshot) {
            return respondError(conn, 404,
                                hub->session(session) ? "session '" + session + "' has no snapshot yet"
                                                      : "unknown session '" + session + "'");
        }
        respond(conn, 200, "application/octet-stream", snapshot->draco(),
                {{"X-Facescan-Seq", std::to_string(snapshot->seq)},
                 {"X-Facescan-Created-Ms", millisecondsText(snapshot->created_ns)}});
        return 200;
    }
    if (what.starts_with("mesh.")) return sendMesh(conn, session, what.substr(5));
    if (what == "textured") return sendTextured(conn, session);
    return respondError(conn, 404,
                        "no such resource '" + what + "' (snapshot.drc, mesh.ply|obj|stl|off|drc|glb, textured)");
}

int ViewServer::Impl::sendMesh(mg_connection* conn, const std::string& session, const std::string& extension) {
    auto format = meshFormatFor("mesh." + extension);
    if (!format.isOk()) return respondError(conn, 400, format.status().message());
    // Only a GLB holds the texture in one file (an OBJ or a PLY would need its picture beside it).
    auto fetched = fetch_mesh(session, *format == MeshFormat::kGlb);
    if (!fetched.isOk()) return respondFetchError(conn, fetched.status());
    const std::vector<uint8_t>* draco = &fetched->draco;
    if (!fetched->texture_png.empty()) {
        auto textured = decodeTexturedMesh(fetched->draco, fetched->texture_png);
        if (!textured.isOk()) {
            return respondError(conn, 502,
                                "the server's textured model cannot be decoded: " + textured.status().message());
        }
        auto glb = texturedGlbBytes(*textured);
        if (!glb.isOk()) return respondError(conn, 502, glb.status().message());
        respond(conn, 200, meshMimeType(*format), *glb,
                {{"Content-Disposition", "attachment; filename=\"" + session + ".glb\""}});
        return 200;
    }
    auto mesh = wire::decodeIndexedMesh(draco->data(), draco->size());
    if (!mesh.isOk()) return respondError(conn, 502, "the server's mesh cannot be decoded: " + mesh.status().message());
    auto bytes = encodeMeshFile(*mesh, *format, draco);
    if (!bytes.isOk()) return respondError(conn, 502, bytes.status().message());
    respond(conn, 200, meshMimeType(*format), *bytes,
            {{"Content-Disposition", "attachment; filename=\"" + session + "." + meshFormatName(*format) + "\""}});
    return 200;
}

int ViewServer::Impl::respondFetchError(mg_connection* conn, const Status& status) {
    const StatusCode code = status.code();
    const int http = code == StatusCode::kNotFound                                               ? 404
                     : code == StatusCode::kDeadlineExceeded || code == StatusCode::kUnavailable ? 503
                                                                                                 : 502;
    return respondError(conn, http, status.message());
}

// The page's textured model: passed on as the server sent it (the page's decoders check it), like the snapshots.
int ViewServer::Impl::sendTextured(mg_connection* conn, const std::string& session) {
    auto fetched = fetch_mesh(session, true);
    if (!fetched.isOk()) return respondFetchError(conn, fetched.status());
    if (fetched->texture_png.empty()) {
        return respondError(conn, 404,
                            "session '" + session + "' has no texture (not finished yet, or scanned without colour)");
    }
    const std::string header = "{\"texture_bytes\": " + std::to_string(fetched->texture_png.size()) + "}";
    std::string body;
    body.reserve(4 + header.size() + fetched->texture_png.size() + fetched->draco.size());
    const uint32_t length = static_cast<uint32_t>(header.size());
    for (int i = 0; i < 4; ++i) body.push_back(static_cast<char>((length >> (8 * i)) & 0xffu));
    body += header;
    body.append(reinterpret_cast<const char*>(fetched->texture_png.data()), fetched->texture_png.size());
    body.append(reinterpret_cast<const char*>(fetched->draco.data()), fetched->draco.size());
    respond(conn, 200, "application/octet-stream", body);
    return 200;
}

namespace {

int onRequest(mg_connection* conn, void* data) { return static_cast<ViewServer::Impl*>(data)->handleRequest(conn); }

// Refuses a WebSocket opened by another site's page (cross-site WebSocket hijacking): browsers always send
// Origin, and ours is the page this server served, so its host is the Host the browser asked for.
bool sameOrigin(const char* origin, const char* host, bool tls) {
    if (!origin) return true;  // not a browser (tests, tools): nothing to hijack
    if (!host) return false;
    std::string_view o(origin), h(host);
    const std::string_view scheme = tls ? "https://" : "http://";
    if (!o.starts_with(scheme)) return false;
    o.remove_prefix(scheme.size());
    return o == h;
}

// With TLS, a WebSocket needs the session cookie as much as a page does (the browser sends it with the upgrade).
int onWsConnect(const mg_connection* conn, void* data) {
    auto* impl = static_cast<ViewServer::Impl*>(data);
    if (!sameOrigin(mg_get_header(conn, "Origin"), mg_get_header(conn, "Host"), impl->logins != nullptr)) return 1;
    if (impl->logins && (!impl->clientAddress(conn) || !detail::sessionUser(conn, *impl->logins))) return 1;
    return 0;
}

void onWsReady(mg_connection* conn, void* data) {
    auto* impl = static_cast<ViewServer::Impl*>(data);
    auto browser = std::make_unique<Browser>();
    browser->conn = conn;
    browser->who = impl->who(conn);
    Browser* raw = browser.get();
    std::lock_guard lock(impl->browsers_mutex);
    impl->browsers[conn] = std::move(browser);
    raw->sender = std::thread([impl, raw] { impl->senderLoop(raw); });
}

int onWsData(mg_connection* conn, int flags, char* data, size_t size, void* cb) {
    auto* impl = static_cast<ViewServer::Impl*>(cb);
    const int opcode = flags & 0xf;
    if (opcode == MG_WEBSOCKET_OPCODE_CONNECTION_CLOSE) return 0;
    if (opcode != MG_WEBSOCKET_OPCODE_TEXT) return 1;  // pings are answered by CivetWeb; nothing else is expected
    const std::string text(data, size);
    Browser* browser = nullptr;
    {
        std::lock_guard lock(impl->browsers_mutex);
        const auto it = impl->browsers.find(conn);
        if (it != impl->browsers.end()) browser = it->second.get();
    }
    if (!browser) return 0;
    std::string error;
    if (text.starts_with("follow ")) {
        const std::string session = text.substr(7);
        if (Status s = wire::validateSessionId(session); s.isOk()) {
            impl->hub->follow(browser->cursor, session);
            impl->record("follow", session, browser->who, "ok");
            return 1;
        } else {
            error = "bad session id: " + s.message();
        }
    } else {
        error = "unknown message (expected 'follow SESSION')";
    }
    ViewServer::Impl::send(conn, MG_WEBSOCKET_OPCODE_TEXT,
                           "{\"type\":\"error\",\"message\":" + jsonString(error) + "}");
    return 1;
}

void onWsClose(const mg_connection* conn, void* data) {
    auto* impl = static_cast<ViewServer::Impl*>(data);
    std::unique_ptr<Browser> browser;
    {
        std::lock_guard lock(impl->browsers_mutex);
        const auto it = impl->browsers.find(conn);
        if (it == impl->browsers.end()) return;
        browser = std::move(it->second);
        impl->browsers.erase(it);
    }
    // CivetWeb frees the connection after this returns: the sender must be done with it.
    impl->hub->close(browser->cursor);
    if (browser->sender.joinable()) browser->sender.join();
}

int onLog(const mg_connection*, const char* message) {
    std::fprintf(stderr, "facescan view: %s\n", message);
    return 1;
}

}  // namespace

StatusOr<std::unique_ptr<ViewServer>> ViewServer::start(const ViewServerConfig& config, ViewHub& hub,
                                                        MeshFetcher fetch_mesh) {
    RETURN_IF_ERROR(config.validate());
    ASSIGN_OR_RETURN(std::vector<LoadedAsset> assets, loadWebAssets(config.web_root));
    std::unique_ptr<LoginBook> logins;
    const std::filesystem::path certificate = config.tls_dir / "web.pem";
    if (!config.tls_dir.empty()) {
        std::error_code ec;
        if (!std::filesystem::is_regular_file(certificate, ec)) {
            return notFound("no TLS certificate for the viewer in " + certificate.string() +
                            ": make one on the site's machine with `facescan-site web SITE NAME --host THIS-HOST` "
                            "and copy SITE/NAME here");
        }
        logins = std::make_unique<LoginBook>(config.login);
        RETURN_IF_ERROR(logins->load(config.tls_dir / "logins"));
    }
    static std::once_flag init_once;
    std::call_once(init_once, [] { mg_init_library(0); });

    std::unique_ptr<ViewServer> server(new ViewServer());
    server->impl_ = std::make_unique<Impl>();
    Impl& impl = *server->impl_;
    impl.config = config;
    impl.assets = std::move(assets);
    impl.hub = &hub;
    impl.fetch_mesh = std::move(fetch_mesh);
    impl.logins = std::move(logins);
    if (!config.audit_file.empty()) {
        ASSIGN_OR_RETURN(impl.audit, wire::AuditLog::open(config.audit_file));
        char host[256] = {};
        impl.recorder = std::string("viewer ") + (::gethostname(host, sizeof host - 1) == 0 ? host : "?");
    }

    // With TLS, CivetWeb serves plain HTTP on a loopback port of its own behind the TLS front (client/tls_front.hpp:
    // Debian's CivetWeb cannot load OpenSSL 3 for its own HTTPS).
    const bool v6 = config.bind.find(':') != std::string::npos;
    const std::string listen = impl.logins
                                   ? std::string("127.0.0.1:0")
                                   : (v6 ? "[" + config.bind + "]" : config.bind) + ":" + std::to_string(config.port);
    const std::string threads = std::to_string(config.threads);
    const char* options[] = {"listening_ports", listen.c_str(), "num_threads", threads.c_str(),
                             // No folder is served as such: only the routes above (no directory listing).
                             "enable_directory_listing", "no", nullptr};
    mg_callbacks callbacks{};
    callbacks.log_message = onLog;
    mg_init_data init{};
    init.callbacks = &callbacks;
    init.user_data = &impl;
    init.configuration_options = options;
    char error_text[256] = {};
    unsigned error_code = 0;
    mg_error_data error{};
    error.code = &error_code;
    error.text = error_text;
    error.text_buffer_size = sizeof(error_text);
    impl.ctx = mg_start2(&init, &error);
    if (!impl.ctx) {
        return unavailable("cannot serve on " + listen + ": " + (error_text[0] ? error_text : "CivetWeb failed") +
                           " (another program on that port? choose one with --port)");
    }
    mg_set_request_handler(impl.ctx, "/", onRequest, &impl);
    mg_set_websocket_handler(impl.ctx, "/ws", onWsConnect, onWsReady, onWsData, onWsClose, &impl);

    mg_server_port ports[4] = {};
    const int n = mg_get_server_ports(impl.ctx, 4, ports);
    server->port_ = n > 0 ? static_cast<uint16_t>(ports[0].port) : config.port;
    if (impl.logins) {
        TlsFront::Options front;
        front.bind = config.bind;
        front.port = config.port;
        front.pem = certificate;
        // site.sh revoke rewrites the identity folder's revocation list (and puts the web certificate on it).
        if (std::error_code ec; std::filesystem::exists(config.tls_dir / "crl.pem", ec)) {
            front.crl = config.tls_dir / "crl.pem";
        }
        front.backend_port = server->port_;
        front.max_connections = config.threads;
        auto started = TlsFront::start(front);
        if (!started.isOk()) {
            server->stop();
            return started.status();
        }
        impl.front = std::move(started).value();
        server->port_ = impl.front->port();
    }
    return server;
}

ViewServer::~ViewServer() { stop(); }

void ViewServer::stop() {
    if (!impl_ || !impl_->ctx) return;
    if (impl_->front) impl_->front->stop();  // the browsers' connections first: nothing new reaches CivetWeb
    {
        std::lock_guard lock(impl_->browsers_mutex);
        for (auto& [conn, browser] : impl_->browsers) {
            impl_->hub->close(browser->cursor);
            // A close frame ends the browser's side at once; CivetWeb's read loop would otherwise notice the stop
            // only at its next poll (up to 2 s).
            Impl::send(browser->conn, MG_WEBSOCKET_OPCODE_CONNECTION_CLOSE, "");
        }
    }
    // Calls onWsClose for every browser left (which joins its sender). CivetWeb's threads notice the stop at their
    // next poll: about 2 s.
    mg_stop(impl_->ctx);
    impl_->ctx = nullptr;
}

std::string ViewServer::url() const {
    std::string host = impl_->config.bind;
    if (host == "0.0.0.0" || host == "::") {
        char name[256] = {};
        host = ::gethostname(name, sizeof(name) - 1) == 0 && name[0] ? name : "localhost";
    } else if (host.find(':') != std::string::npos) {
        host = "[" + host + "]";
    }
    return (impl_->logins ? "https://" : "http://") + host + ":" + std::to_string(port_) + "/";
}

int ViewServer::browsers() const {
    std::lock_guard lock(impl_->browsers_mutex);
    return static_cast<int>(impl_->browsers.size());
}

}  // namespace facescan::client
