// TLS in front of the viewer's CivetWeb. Debian 12's CivetWeb (1.15+dfsg-4) was built to load OpenSSL at run time
// by the names of OpenSSL 1.1, and OpenSSL 3 no longer exports one of them (SSL_get_peer_certificate, now a macro):
// its HTTPS cannot start ("load_tls_dll: libssl.so: cannot find SSL_get_peer_certificate"). So the viewer
// terminates TLS itself with OpenSSL, linked the ordinary way, and relays each connection's bytes to CivetWeb on
// a loopback port; CivetWeb still parses every HTTP request and WebSocket frame.
//
// Only connections that came through the front count: CivetWeb's handlers ask clientAddress() for the relay's
// local port, which gives the browser's real address (for the login brake) and is empty for anybody who connects
// to the loopback port directly.
#pragma once

#include <cstdint>
#include <filesystem>
#include <memory>
#include <optional>
#include <string>

#include "recon/status.hpp"

namespace facescan::client {

class TlsFront {
 public:
    struct Options {
        std::string bind = "127.0.0.1";  // the address browsers connect to
        uint16_t port = 0;               // 0: any free port (port() says which)
        std::filesystem::path pem;       // the key and the certificate (facescan-site web: DIR/NAME/web.pem)
        // The site's revocation list (DIR/NAME/crl.pem, which site.sh revoke rewrites; empty: none). A web
        // certificate on it is not served: start() refuses, and a running front refuses every new connection and
        // ends the open ones from the moment the file lists it (it is looked at again when it changes).
        std::filesystem::path crl;
        uint16_t backend_port = 0;        // CivetWeb's plain port on 127.0.0.1
        int max_connections = 64;         // relayed at once; more wait in the listen queue
        double handshake_timeout_s = 10;  // a client that does not finish its TLS handshake is dropped
    };
    // Loads the key and certificate (the reason when they are bad, do not match or are revoked) and listens.
    static StatusOr<std::unique_ptr<TlsFront>> start(const Options& options);
    ~TlsFront();  // stop()
    TlsFront(const TlsFront&) = delete;
    TlsFront& operator=(const TlsFront&) = delete;

    void stop();
    uint16_t port() const;
    // The browser's address for a relay connection, by the relay's local port on 127.0.0.1; nullopt for a
    // connection that did not come through the front.
    std::optional<std::string> clientAddress(uint16_t relay_port) const;

    struct Impl;

 private:
    TlsFront() = default;
    std::unique_ptr<Impl> impl_;
};

}  // namespace facescan::client
