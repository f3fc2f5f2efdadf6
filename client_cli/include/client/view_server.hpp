// The web side of `facescan view` (CivetWeb, Debian's libcivetweb-dev): the page and its three.js files, a small
// JSON API, the final mesh as a download, and one WebSocket per browser that pushes the sessions list and the
// followed session's snapshots from the ViewHub.
//
//   GET /                                      the page (client_cli/web/index.html)
//   GET /viewer.js /style.css /vendor/...      our script and style; three.js and Draco's wasm decoder from npm
//                                              (client/web_assets.hpp: from memory, gzipped when accepted, ETags)
//   GET /api/sessions                          {"type":"sessions","sessions":[status, ...]}
//   GET /api/sessions/ID                       one session's status; 404 when unknown
//   GET /api/sessions/ID/snapshot.drc          the latest MeshSnapshot's Draco bytes, as received; 404 when none
//   GET /api/sessions/ID/mesh.EXT              the full-resolution mesh from its server (ScanCommand GET_MESH) as
//                                              EXT = ply obj stl off drc glb, an attachment named ID.EXT; a finished
//                                              model with a texture: the GLB holds it (the others: vertex colours)
//   GET /api/sessions/ID/textured              the finished model with its texture, for the page: [u32 header
//                                              length, little-endian][JSON header {"texture_bytes": N}][the
//                                              texture's N PNG bytes][Draco with texture coordinates]; 404 when it
//                                              has none (not finished, or scanned without colour)
//   WS  /ws                                    server -> browser: the sessions message (text) and snapshots
//                                              (binary, client/view_hub.hpp); browser -> server: "follow ID"
// Errors are JSON {"error": "..."}: 400 for a malformed request (bad session id, unknown format, bad method), 404
// for an unknown session or page, 503 when no server answers. No DDS here: meshes come through a MeshFetcher.
// With TLS (ViewServerConfig::tls_dir) the same over HTTPS and WSS, behind a login:
//   GET /login, POST /login                    the login page and form (view_auth.hpp); a session cookie on success
//   POST /logout                               ends the session
// and without a session every other request gets nothing of the scans: / redirects to /login, the rest is 401,
// and the WebSocket upgrade is refused.
#pragma once

#include <cstdint>
#include <filesystem>
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include "client/view_hub.hpp"
#include "client/view_logins.hpp"
#include "client/web_assets.hpp"
#include "recon/status.hpp"

namespace facescan::client {

struct ViewServerConfig {
    std::string bind = "127.0.0.1";  // an IP address: 127.0.0.1 (this machine only), 0.0.0.0 (the LAN), ::1, ...
    uint16_t port = 8080;            // 0: any free port (see ViewServer::port())
    std::filesystem::path web_root;  // the asset folder (findWebRoot())
    int threads = 64;                // CivetWeb workers; each open WebSocket holds one
    // Plain HTTP without a login on an address other machines reach: every scan's face to anyone on the network.
    // Refused by validate() unless set (--insecure-http); the viewer then warns at every start.
    bool insecure_http = false;
    // HTTPS and WSS with a login (--tls DIR/NAME): DIR/NAME/web.pem, the key and the certificate the site's CA signed
    // (facescan-site web), and DIR/NAME/logins (facescan-site login). Every page but /login, every API call and the
    // WebSocket then need a session. Empty: plain HTTP without a login.
    std::filesystem::path tls_dir;
    LoginParams login;  // session timeouts and the brake on wrong passwords
    // The audit trail (wire/audit_log.hpp): snapshots and meshes fetched, sessions followed, logins, each with the
    // viewer login (or the address of a browser without one). Empty: none.
    std::filesystem::path audit_file;

    // InvalidArgument for a bind that is not an IP address, a thread count out of range, or a non-loopback bind
    // without tls_dir or insecure_http (the message says how to set TLS and a login up).
    Status validate() const;
};

// True for an address only this machine reaches: 127.0.0.0/8, ::1 and ::ffff:127.x.x.x.
bool isLoopbackAddress(const std::string& ip);

// The full-resolution mesh of a session as Draco bytes (ScanClient::request(GET_MESH) in the real viewer) and, when
// asked for and the finished model has one, its texture (PNG; the Draco bytes then have texture coordinates).
struct FetchedMesh {
    std::vector<uint8_t> draco;
    std::vector<uint8_t> texture_png;  // empty: none
};
// NotFound: unknown session; DeadlineExceeded or Unavailable: no server answered.
using MeshFetcher = std::function<StatusOr<FetchedMesh>(const std::string& session_id, bool want_texture)>;

class ViewServer {
 public:
    // Listens at once. Unavailable with CivetWeb's reason when the address cannot be bound (e.g. in use).
    static StatusOr<std::unique_ptr<ViewServer>> start(const ViewServerConfig& config, ViewHub& hub,
                                                       MeshFetcher fetch_mesh);
    ~ViewServer();  // stop()
    ViewServer(const ViewServer&) = delete;
    ViewServer& operator=(const ViewServer&) = delete;

    // Closes every WebSocket (a close frame, so browsers see the end at once) and stops listening.
    void stop();
    uint16_t port() const { return port_; }
    // http://ADDRESS:PORT/, https:// with TLS (for 0.0.0.0: this host's name, which the LAN can reach).
    std::string url() const;
    int browsers() const;  // open WebSockets

    struct Impl;

 private:
    ViewServer() = default;
    std::unique_ptr<Impl> impl_;
    uint16_t port_ = 0;
};

}  // namespace facescan::client
