#include "client/tls_front.hpp"

#include <arpa/inet.h>
#include <fcntl.h>
#include <netinet/in.h>
#include <netinet/tcp.h>
#include <openssl/err.h>
#include <openssl/pem.h>
#include <openssl/ssl.h>
#include <openssl/x509.h>
#include <poll.h>
#include <signal.h>
#include <sys/socket.h>
#include <unistd.h>

#include <atomic>
#include <cerrno>
#include <condition_variable>
#include <cstdio>
#include <cstring>
#include <ctime>
#include <filesystem>
#include <map>
#include <mutex>
#include <set>
#include <thread>

namespace facescan::client {
namespace {

std::string opensslError() {
    char text[256] = {};
    const unsigned long e = ERR_get_error();
    if (e == 0) return "no detail from OpenSSL";
    ERR_error_string_n(e, text, sizeof text);
    ERR_clear_error();
    return text;
}

std::string addressText(const sockaddr_storage& addr) {
    char text[INET6_ADDRSTRLEN] = {};
    if (addr.ss_family == AF_INET) {
        ::inet_ntop(AF_INET, &reinterpret_cast<const sockaddr_in&>(addr).sin_addr, text, sizeof text);
    } else if (addr.ss_family == AF_INET6) {
        ::inet_ntop(AF_INET6, &reinterpret_cast<const sockaddr_in6&>(addr).sin6_addr, text, sizeof text);
    }
    return text;
}

void setTimeout(int fd, double seconds) {
    timeval tv{};
    tv.tv_sec = static_cast<time_t>(seconds);
    tv.tv_usec = static_cast<suseconds_t>((seconds - static_cast<double>(tv.tv_sec)) * 1e6);
    ::setsockopt(fd, SOL_SOCKET, SO_RCVTIMEO, &tv, sizeof tv);
    ::setsockopt(fd, SOL_SOCKET, SO_SNDTIMEO, &tv, sizeof tv);
}

bool sendAll(int fd, const char* p, size_t n) {
    while (n > 0) {
        const ssize_t w = ::send(fd, p, n, MSG_NOSIGNAL);
        if (w < 0 && errno == EINTR) continue;
        if (w <= 0) return false;
        p += w;
        n -= static_cast<size_t>(w);
    }
    return true;
}

// PermissionDenied when `certificate` is on the revocation list in `crl_path` (saying since when); NotFound when
// the list cannot be read. The list is the site's, signed by the CA that issued the web certificate: a list that
// is not (another site's) is an error too, so a swapped file cannot hide a revocation.
Status checkRevocation(X509* certificate, const std::filesystem::path& crl_path) {
    FILE* file = std::fopen(crl_path.c_str(), "r");
    if (!file) return notFound("cannot read the revocation list " + crl_path.string() + ": " + std::strerror(errno));
    X509_CRL* crl = PEM_read_X509_CRL(file, nullptr, nullptr, nullptr);
    std::fclose(file);
    if (!crl) return invalidArgument(crl_path.string() + " is not a PEM revocation list (" + opensslError() + ")");
    Status status = Status::ok();
    if (X509_NAME_cmp(X509_CRL_get_issuer(crl), X509_get_issuer_name(certificate)) != 0) {
        status = invalidArgument(crl_path.string() +
                                 " is not the revocation list of the CA that issued the web certificate (another "
                                 "site's?): copy the site's crl.pem");
    } else if (X509_REVOKED* revoked = nullptr; X509_CRL_get0_by_cert(crl, &revoked, certificate) == 1) {
        char when[64] = "an unknown date";
        if (const ASN1_TIME* t = revoked ? X509_REVOKED_get0_revocationDate(revoked) : nullptr) {
            std::tm tm{};
            if (ASN1_TIME_to_tm(t, &tm) == 1) std::strftime(when, sizeof when, "%Y-%m-%d %H:%M UTC", &tm);
        }
        status = permissionDenied(std::string("the viewer's web certificate was revoked on ") + when + " (it is on " +
                                  crl_path.string() +
                                  "): this viewer may not serve; enrol a new viewer (site.sh add, web, login)");
    }
    X509_CRL_free(crl);
    return status;
}

}  // namespace

struct TlsFront::Impl {
    Options options;
    SSL_CTX* ctx = nullptr;
    int listen_fd = -1;
    int wake[2] = {-1, -1};  // written by stop(): ends the acceptor's poll
    uint16_t port = 0;
    std::thread acceptor;
    std::atomic<bool> stopping{false};
    mutable std::mutex mutex;
    std::condition_variable changed;
    std::map<uint16_t, std::string> relays;  // the relay's local port on 127.0.0.1 -> the browser's address
    std::set<int> sockets;                   // every open socket of a relay, shut down by stop()
    int active = 0;
    // Revocation (Options::crl): the list's last change seen, and whether it lists the web certificate.
    std::filesystem::file_time_type crl_seen{};
    bool revoked = false;

    // Looks at the revocation list again when it changed; true when the certificate is revoked (said once).
    bool isRevoked() {
        if (options.crl.empty()) return false;
        std::error_code ec;
        const auto changed_at = std::filesystem::last_write_time(options.crl, ec);
        std::lock_guard lock(mutex);
        if (revoked || ec || changed_at == crl_seen) return revoked;
        crl_seen = changed_at;
        const Status s = checkRevocation(SSL_CTX_get0_certificate(ctx), options.crl);
        if (s.code() == StatusCode::kPermissionDenied) {
            revoked = true;
            std::fprintf(stderr, "facescan view: %s; refusing every connection from now on\n", s.message().c_str());
            // The open connections end too: a revoked viewer shows nothing more.
            for (const int fd : sockets) ::shutdown(fd, SHUT_RDWR);
        } else if (!s.isOk()) {
            std::fprintf(stderr, "facescan view: WARNING: %s\n", s.message().c_str());
        }
        return revoked;
    }

    ~Impl() {
        if (listen_fd >= 0) ::close(listen_fd);
        for (const int fd : wake) {
            if (fd >= 0) ::close(fd);
        }
        if (ctx) SSL_CTX_free(ctx);
    }

    void acceptLoop() {
        while (!stopping) {
            pollfd fds[2] = {{listen_fd, POLLIN, 0}, {wake[0], POLLIN, 0}};
            if (::poll(fds, 2, -1) < 0 && errno != EINTR) return;
            if (stopping || fds[1].revents) return;
            if (!(fds[0].revents & POLLIN)) continue;
            sockaddr_storage from{};
            socklen_t len = sizeof from;
            const int fd = ::accept4(listen_fd, reinterpret_cast<sockaddr*>(&from), &len, SOCK_CLOEXEC);
            if (fd < 0) continue;
            if (isRevoked()) {
                ::close(fd);  // no handshake: a revoked certificate is never shown again
                continue;
            }
            std::unique_lock lock(mutex);
            changed.wait(lock, [&] { return stopping || active < options.max_connections; });
            if (stopping) {
                ::close(fd);
                return;
            }
            ++active;
            sockets.insert(fd);
            lock.unlock();
            std::thread([this, fd, address = addressText(from)] { relay(fd, address); }).detach();
        }
    }

    // One browser connection: the TLS handshake, then bytes both ways until either side closes.
    void relay(int client, const std::string& address) {
        int backend = -1;
        uint16_t local_port = 0;
        SSL* ssl = SSL_new(ctx);
        setTimeout(client, options.handshake_timeout_s);
        if (ssl && SSL_set_fd(ssl, client) == 1 && SSL_accept(ssl) == 1) {
            setTimeout(client, 0);  // none once the handshake is done: a WebSocket may be quiet for long
            backend = ::socket(AF_INET, SOCK_STREAM | SOCK_CLOEXEC, 0);
            sockaddr_in to{};
            to.sin_family = AF_INET;
            to.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
            to.sin_port = htons(options.backend_port);
            sockaddr_in local{};
            socklen_t len = sizeof local;
            if (backend >= 0 && ::connect(backend, reinterpret_cast<sockaddr*>(&to), sizeof to) == 0 &&
                ::getsockname(backend, reinterpret_cast<sockaddr*>(&local), &len) == 0) {
                local_port = ntohs(local.sin_port);
                const int one = 1;
                ::setsockopt(backend, IPPROTO_TCP, TCP_NODELAY, &one, sizeof one);
                {
                    std::lock_guard lock(mutex);
                    relays[local_port] = address;
                    sockets.insert(backend);
                }
                pump(ssl, client, backend);
            }
        }
        ERR_clear_error();
        std::lock_guard lock(mutex);
        if (local_port) relays.erase(local_port);
        if (ssl) {
            if (!stopping) SSL_shutdown(ssl);
            SSL_free(ssl);
        }
        for (const int fd : {client, backend}) {
            if (fd < 0) continue;
            sockets.erase(fd);
            ::close(fd);
        }
        --active;
        changed.notify_all();
    }

    void pump(SSL* ssl, int client, int backend) {
        char buf[16384];
        while (!stopping && !isRevoked()) {
            pollfd fds[2] = {{client, POLLIN, 0}, {backend, POLLIN, 0}};
            // Bytes OpenSSL already decrypted are not on the socket any more: take them without waiting.
            if (SSL_pending(ssl) > 0) {
                fds[0].revents = POLLIN;
            } else if (::poll(fds, 2, 1000) < 0) {
                if (errno == EINTR) continue;
                return;
            }
            if (fds[0].revents & (POLLIN | POLLHUP | POLLERR)) {
                const int n = SSL_read(ssl, buf, sizeof buf);
                if (n <= 0) {
                    const int e = SSL_get_error(ssl, n);
                    if (e == SSL_ERROR_WANT_READ || e == SSL_ERROR_WANT_WRITE) continue;
                    return;  // closed, reset or not TLS
                }
                if (!sendAll(backend, buf, static_cast<size_t>(n))) return;
            }
            if (fds[1].revents & (POLLIN | POLLHUP | POLLERR)) {
                const ssize_t n = ::recv(backend, buf, sizeof buf, 0);
                if (n < 0 && errno == EINTR) continue;
                if (n <= 0) return;
                if (SSL_write(ssl, buf, static_cast<int>(n)) <= 0) return;
            }
        }
    }
};

StatusOr<std::unique_ptr<TlsFront>> TlsFront::start(const Options& options) {
    std::unique_ptr<TlsFront> front(new TlsFront());
    front->impl_ = std::make_unique<Impl>();
    Impl& impl = *front->impl_;
    impl.options = options;
    ::signal(SIGPIPE, SIG_IGN);  // a browser that goes away mid-write is an error return, not the end of us
    impl.ctx = SSL_CTX_new(TLS_server_method());
    if (!impl.ctx) return internalError("OpenSSL: cannot make a TLS context: " + opensslError());
    SSL_CTX_set_min_proto_version(impl.ctx, TLS1_2_VERSION);
    const std::string pem = options.pem.string();
    if (SSL_CTX_use_certificate_chain_file(impl.ctx, pem.c_str()) != 1) {
        return invalidArgument(pem + " holds no usable certificate (" + opensslError() +
                               "): make it with facescan-site web SITE NAME --host THIS-HOST");
    }
    if (SSL_CTX_use_PrivateKey_file(impl.ctx, pem.c_str(), SSL_FILETYPE_PEM) != 1 ||
        SSL_CTX_check_private_key(impl.ctx) != 1) {
        return invalidArgument(pem + ": the private key is missing or not the certificate's (" + opensslError() +
                               "): make the file again with facescan-site web");
    }
    if (!options.crl.empty()) {
        RETURN_IF_ERROR(checkRevocation(SSL_CTX_get0_certificate(impl.ctx), options.crl));
        std::error_code ec;
        impl.crl_seen = std::filesystem::last_write_time(options.crl, ec);
    }

    const bool v6 = options.bind.find(':') != std::string::npos;
    sockaddr_storage addr{};
    socklen_t len = 0;
    if (v6) {
        auto& a = reinterpret_cast<sockaddr_in6&>(addr);
        a.sin6_family = AF_INET6;
        a.sin6_port = htons(options.port);
        if (::inet_pton(AF_INET6, options.bind.c_str(), &a.sin6_addr) != 1) {
            return invalidArgument("not an IP address: " + options.bind);
        }
        len = sizeof a;
    } else {
        auto& a = reinterpret_cast<sockaddr_in&>(addr);
        a.sin_family = AF_INET;
        a.sin_port = htons(options.port);
        if (::inet_pton(AF_INET, options.bind.c_str(), &a.sin_addr) != 1) {
            return invalidArgument("not an IP address: " + options.bind);
        }
        len = sizeof a;
    }
    const std::string where = (v6 ? "[" + options.bind + "]" : options.bind) + ":" + std::to_string(options.port);
    impl.listen_fd = ::socket(addr.ss_family, SOCK_STREAM | SOCK_CLOEXEC, 0);
    const int one = 1;
    if (impl.listen_fd < 0 || ::setsockopt(impl.listen_fd, SOL_SOCKET, SO_REUSEADDR, &one, sizeof one) != 0 ||
        ::bind(impl.listen_fd, reinterpret_cast<sockaddr*>(&addr), len) != 0 || ::listen(impl.listen_fd, 128) != 0) {
        return unavailable("cannot serve on " + where + ": " + std::strerror(errno) +
                           " (another program on that port? choose one with --port)");
    }
    sockaddr_storage bound{};
    socklen_t bound_len = sizeof bound;
    ::getsockname(impl.listen_fd, reinterpret_cast<sockaddr*>(&bound), &bound_len);
    impl.port = ntohs(bound.ss_family == AF_INET6 ? reinterpret_cast<sockaddr_in6&>(bound).sin6_port
                                                  : reinterpret_cast<sockaddr_in&>(bound).sin_port);
    if (::pipe2(impl.wake, O_CLOEXEC) != 0) return internalError(std::string("pipe: ") + std::strerror(errno));
    impl.acceptor = std::thread([&impl] { impl.acceptLoop(); });
    return front;
}

TlsFront::~TlsFront() { stop(); }

void TlsFront::stop() {
    if (!impl_ || impl_->stopping.exchange(true)) return;
    const char byte = 1;
    (void)!::write(impl_->wake[1], &byte, 1);
    if (impl_->acceptor.joinable()) impl_->acceptor.join();
    std::unique_lock lock(impl_->mutex);
    for (const int fd : impl_->sockets) ::shutdown(fd, SHUT_RDWR);  // wakes every relay's blocking call
    impl_->changed.notify_all();
    impl_->changed.wait(lock, [&] { return impl_->active == 0; });
}

uint16_t TlsFront::port() const { return impl_->port; }

std::optional<std::string> TlsFront::clientAddress(uint16_t relay_port) const {
    std::lock_guard lock(impl_->mutex);
    const auto it = impl_->relays.find(relay_port);
    if (it == impl_->relays.end()) return std::nullopt;
    return it->second;
}

}  // namespace facescan::client
