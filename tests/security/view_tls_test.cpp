// `facescan view --tls` (client/view_server.hpp, client/tls_front.hpp): HTTPS and WSS with the certificate and the
// logins that the real deploy/security/site.sh makes, checked by clients that trust only the site's CA (curl,
// openssl s_client). Without a session nothing of the scans is served; with one, the scan; wrong passwords are
// braked; a certificate from another site, an expired one or one for another host is rejected (each check shown
// to fail). The viewer runs in this process with a real ViewHub and real Draco bytes; no DDS is needed.
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <regex>

#include "child_process.hpp"
#include "client/view_hub.hpp"
#include "client/view_server.hpp"
#include "client/web_assets.hpp"
#include "site_fixture.hpp"
#include "wire/audit_log.hpp"
#include "wire/mesh_codec.hpp"

namespace {

using namespace facescan;
using namespace facescan::client;
namespace fs = std::filesystem;
namespace ft = facescan::testing;

bool contains(const std::string& text, const std::string& part) { return text.find(part) != std::string::npos; }

constexpr const char* kPassword = "correct horse battery";

// site.sh login DIR NAME USER with the password on its standard input, as a script would give it.
ft::CommandRun addLogin(const fs::path& site, const std::string& name, const std::string& user,
                        const std::string& password) {
    return ft::runCommand("printf '%s\\n' '" + password + "' | " + ft::siteScript() + " login " + site.string() + " " +
                          name + " " + user + " 2>&1");
}

// A small real mesh, Draco-encoded, as a server's snapshot.
std::vector<uint8_t> patchDraco() {
    recon::Mesh mesh;
    std::vector<recon::Mesh::VertexHandle> v;
    for (int r = 0; r < 8; ++r) {
        for (int c = 0; c < 8; ++c) v.push_back(mesh.add_vertex({0.01f * c, 0.01f * r, 0.7f}));
    }
    for (int r = 0; r + 1 < 8; ++r) {
        for (int c = 0; c + 1 < 8; ++c) {
            mesh.add_face(v[r * 8 + c], v[(r + 1) * 8 + c], v[r * 8 + c + 1]);
            mesh.add_face(v[r * 8 + c + 1], v[(r + 1) * 8 + c], v[(r + 1) * 8 + c + 1]);
        }
    }
    std::vector<uint8_t> bytes;
    EXPECT_TRUE(wire::encodeMeshDraco(mesh, {}, bytes).isOk());
    return bytes;
}

struct Viewer {
    ViewHub hub;
    std::unique_ptr<ViewServer> server;
    Status status;
};

// A viewer on 127.0.0.1 with the identity folder `tls_dir`, showing session "scan-7".
std::unique_ptr<Viewer> startViewer(const fs::path& tls_dir, LoginParams login = {}, const fs::path& audit = {}) {
    auto viewer = std::make_unique<Viewer>();
    SessionStatus s;
    s.session_id = "scan-7";
    s.server_id = "server-a";
    s.state = facescan_wire_STATE_SCANNING;
    viewer->hub.updateStatuses({{"scan-7", s}});
    MeshSnapshotData snap;
    snap.session_id = "scan-7";
    snap.seq = 1;
    snap.draco = patchDraco();
    viewer->hub.putSnapshot(frameSnapshot(snap));
    ViewServerConfig config;
    config.port = 0;
    config.web_root = *findWebRoot();
    config.tls_dir = tls_dir;
    config.login = login;
    config.audit_file = audit;
    auto started =
        ViewServer::start(config, viewer->hub, [](const std::string& session, bool) -> StatusOr<FetchedMesh> {
            if (session == "scan-7") return FetchedMesh{patchDraco(), {}};
            return notFound("unknown session '" + session + "'");
        });
    if (started.isOk()) {
        viewer->server = std::move(started).value();
    } else {
        viewer->status = started.status();
    }
    return viewer;
}

// curl that trusts only `ca`; prints the status code last ("%{http_code}"), -D - the headers first.
ft::CommandRun curl(const fs::path& ca, const std::string& host, uint16_t port, const std::string& path,
                    const std::string& extra = "") {
    return ft::runCommand("curl -sS -D - --max-time 20 --cacert " + ca.string() + " --resolve " + host + ":" +
                          std::to_string(port) + ":127.0.0.1 " + extra + " -w '\\n%{http_code}' https://" + host + ":" +
                          std::to_string(port) + path + " 2>&1");
}

int httpCode(const ft::CommandRun& run) {
    const size_t nl = run.out.find_last_of('\n');
    try {
        return std::stoi(run.out.substr(nl == std::string::npos ? 0 : nl + 1));
    } catch (...) {
        return -1;
    }
}

// The WebSocket upgrade over TLS (openssl s_client, trusting only `ca`): what the viewer answered in 2 s.
std::string wsUpgrade(const fs::path& ca, uint16_t port, const std::string& cookie) {
    const std::string request = "GET /ws HTTP/1.1\\r\\nHost: 127.0.0.1:" + std::to_string(port) +
                                "\\r\\nConnection: Upgrade\\r\\nUpgrade: websocket\\r\\nSec-WebSocket-Version: 13\\r\\n"
                                "Sec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\\r\\n" +
                                (cookie.empty() ? std::string() : "Cookie: " + cookie + "\\r\\n") + "\\r\\n";
    return ft::runCommand(
               "(printf '" + request + "'; sleep 2) | timeout 10 openssl s_client -quiet -connect 127.0.0.1:" +
               std::to_string(port) + " -CAfile " + ca.string() + " -verify_return_error 2>/dev/null | head -c 4000")
        .out;
}

class TlsView : public ::testing::Test {
 protected:
    void SetUp() override {
        if (!findWebRoot().isOk()) GTEST_SKIP() << "the viewer's npm packages are missing (deploy/install-deps.sh)";
        if (ft::runCommand("command -v curl").exit_code != 0) GTEST_SKIP() << "curl is missing";
        site_ = std::make_unique<ft::TempSite>("tlsview");
        ASSERT_TRUE(site_->ok()) << site_->initOutput();
        const auto web = site_->site("web " + site_->dir().string() + " viewer --host 127.0.0.1 --host localhost");
        ASSERT_EQ(web.exit_code, 0) << web.out;
        const auto login = addLogin(site_->dir().string(), "viewer", "alice", kPassword);
        ASSERT_EQ(login.exit_code, 0) << login.out;
    }
    fs::path ca() const { return site_->dir() / "identity_ca.pem"; }
    std::unique_ptr<ft::TempSite> site_;
};

TEST_F(TlsView, WithoutALoginEveryPageAndCallIsRefusedAndTheWebSocketToo) {
    auto viewer = startViewer(site_->identity("viewer"));
    ASSERT_TRUE(viewer->server) << viewer->status.toString();
    const uint16_t port = viewer->server->port();
    EXPECT_EQ(viewer->server->url(), "https://127.0.0.1:" + std::to_string(port) + "/");
    for (const std::string path : {"/", "/index.html"}) {
        const auto run = curl(ca(), "127.0.0.1", port, path);
        EXPECT_EQ(httpCode(run), 303) << path << run.out;
        EXPECT_TRUE(contains(run.out, "Location: /login")) << run.out;
    }
    for (const std::string path :
         {"/viewer.js", "/style.css", "/api/sessions", "/api/sessions/scan-7", "/api/sessions/scan-7/snapshot.drc",
          "/api/sessions/scan-7/mesh.ply", "/api/sessions/scan-7/mesh.glb", "/logout"}) {
        const auto run = curl(ca(), "127.0.0.1", port, path);
        EXPECT_EQ(httpCode(run), 401) << path << run.out;
        EXPECT_FALSE(contains(run.out, "scan-7")) << path << run.out;
    }
    const auto forged = curl(ca(), "127.0.0.1", port, "/api/sessions",
                             "-H 'Cookie: __Host-facescan_session=" + std::string(64, 'a') + "'");
    EXPECT_EQ(httpCode(forged), 401) << forged.out;
    EXPECT_EQ(wsUpgrade(ca(), port, ""), "") << "no upgrade without a session";
    // The login page itself is served, and plain HTTP on the TLS port gets nothing.
    const auto page = curl(ca(), "127.0.0.1", port, "/login");
    EXPECT_EQ(httpCode(page), 200) << page.out;
    EXPECT_TRUE(contains(page.out, "<form method=\"post\" action=\"/login\">")) << page.out;
    const auto plain = ft::runCommand("curl -sS --max-time 10 http://127.0.0.1:" + std::to_string(port) + "/ 2>&1");
    EXPECT_NE(plain.exit_code, 0) << plain.out;
    EXPECT_FALSE(contains(plain.out, "scan-7")) << plain.out;
}

TEST_F(TlsView, ALoginSeesTheScanUntilLogoutAndWrongPasswordsAreBraked) {
    LoginParams login;
    login.free_failures = 3;
    const fs::path audit = site_->root() / "view-audit.log";
    auto viewer = startViewer(site_->identity("viewer"), login, audit);
    ASSERT_TRUE(viewer->server) << viewer->status.toString();
    const uint16_t port = viewer->server->port();
    const auto wrong = curl(ca(), "localhost", port, "/login", "-d 'user=alice&password=nope'");
    EXPECT_EQ(httpCode(wrong), 401) << wrong.out;
    EXPECT_TRUE(contains(wrong.out, "wrong user or password")) << wrong.out;
    EXPECT_FALSE(contains(wrong.out, "Set-Cookie")) << wrong.out;

    const auto ok = curl(ca(), "localhost", port, "/login",
                         "--data-urlencode 'user=alice' --data-urlencode 'password=" + std::string(kPassword) + "'");
    EXPECT_EQ(httpCode(ok), 303) << ok.out;
    std::smatch m;
    ASSERT_TRUE(
        std::regex_search(ok.out, m, std::regex(R"(Set-Cookie: (__Host-facescan_session=[0-9a-f]{64});([^\r\n]*))")))
        << ok.out;
    const std::string cookie = m[1].str(), attributes = m[2].str();
    for (const char* a : {"Secure", "HttpOnly", "SameSite=Strict", "Path=/", "Max-Age="}) {
        EXPECT_TRUE(contains(attributes, a)) << a << " missing: " << attributes;
    }
    const std::string with = "-H 'Cookie: " + cookie + "'";
    const auto sessions = curl(ca(), "localhost", port, "/api/sessions", with);
    EXPECT_EQ(httpCode(sessions), 200) << sessions.out;
    EXPECT_TRUE(contains(sessions.out, "\"session\":\"scan-7\"")) << sessions.out;
    EXPECT_EQ(httpCode(curl(ca(), "localhost", port, "/", with)), 200);
    EXPECT_EQ(httpCode(curl(ca(), "localhost", port, "/viewer.js", with)), 200);
    EXPECT_EQ(httpCode(curl(ca(), "localhost", port, "/api/sessions/scan-7/snapshot.drc", with + " -o /dev/null")),
              200);
    const auto mesh = curl(ca(), "localhost", port, "/api/sessions/scan-7/mesh.ply", with + " -o /dev/null");
    EXPECT_EQ(httpCode(mesh), 200) << mesh.out;
    EXPECT_TRUE(contains(mesh.out, "attachment; filename=\"scan-7.ply\"")) << mesh.out;
    const std::string ws = wsUpgrade(ca(), port, cookie);
    EXPECT_TRUE(contains(ws, "HTTP/1.1 101 Switching Protocols")) << ws;
    EXPECT_TRUE(contains(ws, "scan-7")) << "the sessions message, over WSS";

    // Logout ends the session: the same cookie gets nothing.
    EXPECT_EQ(httpCode(curl(ca(), "localhost", port, "/logout", with + " -X POST")), 303);
    EXPECT_EQ(httpCode(curl(ca(), "localhost", port, "/api/sessions", with)), 401);

    // The brake: after free_failures wrong passwords in a row (the login above released the first one), even the
    // right one waits.
    for (int i = 0; i < 3; ++i) {
        EXPECT_EQ(httpCode(curl(ca(), "localhost", port, "/login", "-d 'user=alice&password=nope'")), 401);
    }
    const auto braked =
        curl(ca(), "localhost", port, "/login",
             "--data-urlencode 'user=alice' --data-urlencode 'password=" + std::string(kPassword) + "'");
    EXPECT_EQ(httpCode(braked), 429) << braked.out;
    // 30 s less what has passed since the brake came on (a busy machine may take seconds between requests).
    EXPECT_TRUE(std::regex_search(braked.out, std::regex("Retry-After: ([1-9]|[12][0-9]|30)\r"))) << braked.out;
    EXPECT_FALSE(contains(braked.out, "Set-Cookie")) << braked.out;

    // The audit trail names the login for every fetch, and every login attempt with its outcome.
    auto records = wire::readAuditLog(audit);
    ASSERT_TRUE(records.isOk()) << records.status().toString();
    std::vector<std::string> lines;
    for (const wire::AuditRecord& r : *records) {
        lines.push_back(r.action + " | " + r.session + " | " + r.identity + " | " + r.outcome);
        EXPECT_TRUE(r.recorder.starts_with("viewer ")) << r.recorder;
    }
    const std::vector<std::string> expected = {
        "login |  | login alice | error: wrong user or password (from 127.0.0.1)",
        "login |  | login alice | ok (from 127.0.0.1)",
        "snapshot | scan-7 | login alice | ok",
        "download ply | scan-7 | login alice | ok",
        "login |  | login alice | error: wrong user or password (from 127.0.0.1)",
        "login |  | login alice | error: wrong user or password (from 127.0.0.1)",
        "login |  | login alice | error: wrong user or password (from 127.0.0.1)",
        "login |  | login alice | error: locked out after wrong passwords (from 127.0.0.1)"};
    EXPECT_EQ(lines, expected);
}

TEST_F(TlsView, ACertificateOfAnotherSiteExpiredOrForAnotherHostIsRejectedByAClientThatTrustsTheSite) {
    // The viewer's own certificate passes: the checks below fail for their reason, not for any.
    {
        auto viewer = startViewer(site_->identity("viewer"));
        ASSERT_TRUE(viewer->server) << viewer->status.toString();
        const auto run = curl(ca(), "localhost", viewer->server->port(), "/login");
        EXPECT_EQ(run.exit_code, 0) << run.out;
        EXPECT_EQ(httpCode(run), 200) << run.out;
        // Another name than the certificate's hosts.
        const auto other_host = curl(ca(), "viewer.example", viewer->server->port(), "/login");
        EXPECT_EQ(other_host.exit_code, 60) << other_host.out;
        EXPECT_TRUE(contains(other_host.out, "no alternative certificate subject name matches")) << other_host.out;
    }
    // A certificate signed by another site's CA (valid there).
    ft::TempSite other("tlsview-other", "elsewhere");
    ASSERT_TRUE(other.ok()) << other.initOutput();
    ASSERT_EQ(other.site("web " + other.dir().string() + " viewer --host localhost").exit_code, 0);
    ASSERT_EQ(addLogin(other.dir().string(), "viewer", "alice", kPassword).exit_code, 0);
    {
        auto viewer = startViewer(other.identity("viewer"));
        ASSERT_TRUE(viewer->server) << viewer->status.toString();
        const auto run = curl(ca(), "localhost", viewer->server->port(), "/login");
        EXPECT_EQ(run.exit_code, 60) << run.out;
        EXPECT_TRUE(contains(run.out, "unable to get local issuer certificate")) << run.out;
        const auto own = curl(other.dir() / "identity_ca.pem", "localhost", viewer->server->port(), "/login");
        EXPECT_EQ(own.exit_code, 0) << "it is valid for its own site: " << own.out;
    }
    // An expired certificate of this site.
    ASSERT_EQ(site_->add("viewer", "old-viewer").exit_code, 0);
    const auto expired = site_->site("web " + site_->dir().string() +
                                     " old-viewer --host localhost --from 2020-01-01 --until 2020-02-01");
    ASSERT_EQ(expired.exit_code, 0) << expired.out;
    ASSERT_EQ(addLogin(site_->dir().string(), "old-viewer", "alice", kPassword).exit_code, 0);
    {
        auto viewer = startViewer(site_->identity("old-viewer"));
        ASSERT_TRUE(viewer->server) << viewer->status.toString();
        const auto run = curl(ca(), "localhost", viewer->server->port(), "/login");
        EXPECT_EQ(run.exit_code, 60) << run.out;
        EXPECT_TRUE(contains(run.out, "certificate has expired")) << run.out;
    }
}

// site.sh revoke of a viewer: its web certificate goes on the site's revocation list with its identity, and the
// running viewer (whose folder site.sh refreshed) refuses every new connection, so no login works either; it
// will not start again with that certificate. Before the revocation the same requests are served.
TEST_F(TlsView, ARevokedViewerRefusesEveryConnectionAndWillNotStartAgain) {
    auto viewer = startViewer(site_->identity("viewer"));
    ASSERT_TRUE(viewer->server) << viewer->status.toString();
    const uint16_t port = viewer->server->port();
    const auto login = [&] {
        return curl(ca(), "127.0.0.1", port, "/login",
                    "--data-urlencode 'user=alice' --data-urlencode 'password=" + std::string(kPassword) + "'");
    };
    EXPECT_EQ(httpCode(curl(ca(), "127.0.0.1", port, "/login")), 200);
    const auto before = login();
    EXPECT_EQ(httpCode(before), 303) << "the login works before the revocation\n" << before.out;

    const auto revoked = site_->revoke("viewer");
    ASSERT_EQ(revoked.exit_code, 0) << revoked.out;
    EXPECT_TRUE(contains(revoked.out, "and its web certificate")) << revoked.out;
    const auto page = curl(ca(), "127.0.0.1", port, "/login");
    EXPECT_NE(page.exit_code, 0) << page.out;
    EXPECT_NE(httpCode(page), 200) << page.out;
    const auto after = login();
    EXPECT_NE(httpCode(after), 303) << after.out;
    EXPECT_FALSE(contains(after.out, "Set-Cookie")) << after.out;

    viewer.reset();
    auto again = startViewer(site_->identity("viewer"));
    EXPECT_FALSE(again->server);
    EXPECT_EQ(again->status.code(), StatusCode::kPermissionDenied) << again->status.toString();
    EXPECT_TRUE(contains(again->status.message(), "web certificate was revoked on")) << again->status.toString();
}

TEST_F(TlsView, WithoutItsCertificateOrLoginsTheViewerSaysWhatToRunAndSiteShChecksItsInput) {
    ASSERT_EQ(site_->add("viewer", "bare").exit_code, 0);
    auto no_cert = startViewer(site_->identity("bare"));
    EXPECT_FALSE(no_cert->server);
    EXPECT_TRUE(contains(no_cert->status.message(), "facescan-site web SITE NAME --host")) << no_cert->status.message();
    ASSERT_EQ(site_->site("web " + site_->dir().string() + " bare --host localhost").exit_code, 0);
    auto no_logins = startViewer(site_->identity("bare"));
    EXPECT_FALSE(no_logins->server);
    EXPECT_TRUE(contains(no_logins->status.message(), "facescan-site login SITE NAME USER"))
        << no_logins->status.message();

    const std::string dir = site_->dir().string();
    const auto short_password = addLogin(dir, "bare", "bob", "short");
    EXPECT_NE(short_password.exit_code, 0);
    EXPECT_TRUE(contains(short_password.out, "at least 10 characters")) << short_password.out;
    const auto no_host = site_->site("web " + dir + " bare");
    EXPECT_EQ(no_host.exit_code, 2) << no_host.out;
    EXPECT_TRUE(contains(no_host.out, "at least one --host")) << no_host.out;
    ASSERT_EQ(addLogin(dir, "bare", "bob", "a long enough one").exit_code, 0);
    ASSERT_EQ(addLogin(dir, "bare", "carol", "another long one").exit_code, 0);
    const fs::path logins = site_->identity("bare") / "logins";
    EXPECT_EQ(fs::status(logins).permissions() & fs::perms::all, fs::perms::owner_read | fs::perms::owner_write);
    EXPECT_EQ(fs::status(site_->identity("bare") / "web.pem").permissions() & fs::perms::all,
              fs::perms::owner_read | fs::perms::owner_write);
    const std::string text = ft::readText(logins);
    EXPECT_FALSE(contains(text, "long enough")) << "never the password itself";
    EXPECT_TRUE(std::regex_search(text, std::regex("^bob:pbkdf2-sha256:600000:[0-9a-f]{16}:[0-9A-F]{64}\n"))) << text;
    ASSERT_EQ(site_->site("login " + dir + " bare bob --remove").exit_code, 0);
    EXPECT_FALSE(contains(ft::readText(logins), "bob:"));
    EXPECT_TRUE(contains(ft::readText(logins), "carol:"));
}

}  // namespace
