// `facescan view` on a secured site (DDS Security): with the read-only viewer identity it
// follows a secured scan (sessions, pushed snapshots that decode) and, since that role may not send commands, its
// downloads are the session's latest snapshot: the final mesh once the scan is finished. The same viewer without
// an identity sees nothing of the secured domain (the check can fail).
#include <gtest/gtest.h>
#include <tiny_gltf.h>

#include <filesystem>
#include <fstream>
#include <regex>
#include <thread>

#include "child_process.hpp"
#include "client/web_assets.hpp"
#include "glb_reader.hpp"
#include "http_client.hpp"
#include "site_fixture.hpp"
#include "test_domain.hpp"
#include "wire/mesh_codec.hpp"
#include "wire/topics.hpp"

namespace {

using namespace facescan;
using namespace std::chrono_literals;
namespace fs = std::filesystem;
namespace ft = facescan::testing;

bool contains(const std::string& text, const std::string& part) { return text.find(part) != std::string::npos; }

std::vector<std::string> withDds(std::vector<std::string> args, uint32_t domain, const fs::path& identity) {
    args.insert(args.end(), {"--profile", "loopback", "--domain", std::to_string(domain)});
    if (!identity.empty()) args.insert(args.end(), {"--security", identity.string()});
    return args;
}

// The port `facescan view --port 0` printed in its log.
uint16_t viewerPort(const fs::path& log) {
    std::smatch match;
    const std::regex serving(R"(serving http://127\.0\.0\.1:(\d+)/)");
    std::string text;
    if (!ft::pollUntilTrue(
            [&] {
                text = ft::readText(log);
                return std::regex_search(text, match, serving);
            },
            20s)) {
        ADD_FAILURE() << "the viewer did not start:\n" << text;
        return 0;
    }
    return static_cast<uint16_t>(std::stoi(match[1].str()));
}

TEST(SecureView, TheViewerIdentityWatchesAScanAndDownloadsItsFinalSnapshot) {
    if (auto root = client::findWebRoot(); !root.isOk()) GTEST_SKIP() << root.status().message();
    ft::TempSite site("view");
    ASSERT_TRUE(site.ok()) << site.initOutput();
    const uint32_t domain = ft::privateDomain(23);
    const fs::path dir = site.root();
    const std::string session = "secure-view-" + std::to_string(::getpid());

    ft::ChildProcess viewer(withDds({FACESCAN_CLI, "view", "--port", "0"}, domain, site.identity("viewer")),
                            dir / "view.log");
    ft::ChildProcess outsider(withDds({FACESCAN_CLI, "view", "--port", "0"}, domain, {}), dir / "outsider.log");
    const uint16_t port = viewerPort(dir / "view.log");
    const uint16_t outsider_port = viewerPort(dir / "outsider.log");
    ASSERT_TRUE(port && outsider_port);
    ft::WsClient ws(port);
    ASSERT_TRUE(ws.connected()) << ws.error();
    ASSERT_TRUE(ws.send("follow " + session));

    ft::ChildProcess server(withDds({FACESCAN_SERVER_BIN, "--data-dir", (dir / "data").string(), "--snapshot-hz", "2"},
                                    domain, site.identity("server")),
                            dir / "server.log");
    ft::ChildProcess agent(
        withDds({FACESCAN_AGENT_BIN, "--session", session, "--source", "synthetic:frames=30,subject=builtin,seed=1",
                 "--rate", "max", "--wait-for-server", "60"},
                domain, site.identity("agent")),
        dir / "agent.log");
    auto logs = [&] {
        return "\nview:\n" + ft::readText(dir / "view.log") + "\nserver:\n" + ft::readText(dir / "server.log") +
               "\nagent:\n" + ft::readText(dir / "agent.log");
    };

    // The viewer role may not publish ScanCommand: the viewer says so at start and serves snapshots instead.
    EXPECT_TRUE(contains(ft::readText(dir / "view.log"), "cannot ask servers for meshes")) << logs();
    ASSERT_TRUE(ws.waitFor(
        [](const auto& m) { return std::any_of(m.begin(), m.end(), [](const auto& x) { return x.binary; }); }, 90s))
        << logs();
    EXPECT_EQ(agent.wait(90s), 0) << logs();
    ASSERT_TRUE(ft::pollUntilTrue(
        [&] { return contains(ft::httpRequest(port, "/api/sessions/" + session).body, "\"state\":\"FINISHED\""); },
        60s))
        << logs();

    // The download is the final snapshot: a GLB with colours, and the same bytes as snapshot.drc decode.
    std::this_thread::sleep_for(1s);  // the final snapshot follows the FINISHED status
    const auto drc = ft::httpRequest(port, "/api/sessions/" + session + "/mesh.drc");
    ASSERT_EQ(drc.status, 200) << drc.body << logs();
    EXPECT_EQ(drc.body, ft::httpRequest(port, "/api/sessions/" + session + "/snapshot.drc").body);
    auto mesh = wire::decodeMeshDraco(reinterpret_cast<const uint8_t*>(drc.body.data()), drc.body.size());
    ASSERT_TRUE(mesh.isOk()) << mesh.status().toString();
    EXPECT_GT(mesh->n_faces(), 1000u);
    const auto glb = ft::httpRequest(port, "/api/sessions/" + session + "/mesh.glb");
    ASSERT_EQ(glb.status, 200) << glb.body;
    tinygltf::Model model;
    std::string err;
    ASSERT_TRUE(ft::readGlb(glb.body, model, err)) << err;
    EXPECT_TRUE(model.meshes.at(0).primitives.at(0).attributes.count("COLOR_0"));

    // Without an identity, the same viewer on the same domain sees nothing of the secured scan.
    EXPECT_FALSE(contains(ft::httpRequest(outsider_port, "/api/sessions").body, session));
    EXPECT_EQ(ft::httpRequest(outsider_port, "/api/sessions/" + session).status, 404);

    // facescan delete (the client role): the viewer drops the scan from its memory and its pages.
    const auto erased = ft::runCommand(std::string(FACESCAN_CLI) + " delete " + session +
                                       " --profile loopback --domain " + std::to_string(domain) +
                                       " --timeout 20 --security " + site.identity("client").string() + " 2>&1");
    EXPECT_EQ(erased.exit_code, 0) << erased.out << logs();
    EXPECT_TRUE(ft::pollUntilTrue([&] { return ft::httpRequest(port, "/api/sessions/" + session).status == 404; }, 20s))
        << logs();
    EXPECT_EQ(ft::httpRequest(port, "/api/sessions/" + session + "/mesh.drc").status, 404);
    EXPECT_EQ(ft::httpRequest(port, "/api/sessions/" + session + "/snapshot.drc").status, 404);
    EXPECT_FALSE(contains(ft::httpRequest(port, "/api/sessions").body, session));
    EXPECT_TRUE(contains(ft::readText(dir / "view.log"), "scan " + session + " was erased on the domain")) << logs();
    EXPECT_TRUE(ws.waitFor(
        [&](const auto& m) {
            return !m.empty() && !m.back().binary && contains(m.back().data, "\"type\":\"sessions\"") &&
                   !contains(m.back().data, session);
        },
        20s))
        << "the page is told at once";
}

// facescan delete on a secured site: the client role may erase a scan (and the server's audit trail names the
// client's identity); the read-only viewer role may not.
TEST(SecureDelete, TheClientRoleErasesAScanAndTheViewerRoleMayNot) {
    ft::TempSite site("delete");
    ASSERT_TRUE(site.ok()) << site.initOutput();
    const uint32_t domain = ft::privateDomain(24);
    const fs::path data = site.root() / "data";
    for (const std::string id : {"secure-gone", "secure-kept"}) {
        fs::create_directories(data / id);
        std::ofstream(data / id / "mesh.ply") << "ply";
        std::ofstream(data / id / "summary.json") << "{}";
    }
    ft::ChildProcess server(
        withDds({FACESCAN_SERVER_BIN, "--data-dir", data.string()}, domain, site.identity("server")),
        site.root() / "server.log");
    const auto cli = [&](const std::string& args, const std::string& identity) {
        return ft::runCommand(std::string(FACESCAN_CLI) + " " + args + " --profile loopback --domain " +
                              std::to_string(domain) + " --timeout 20 --security " + site.identity(identity).string() +
                              " 2>&1");
    };
    const auto denied = cli("delete secure-kept", "viewer");
    EXPECT_EQ(denied.exit_code, 6) << denied.out;
    EXPECT_TRUE(fs::exists(data / "secure-kept" / "mesh.ply")) << ft::readText(site.root() / "server.log");

    const auto erased = cli("delete secure-gone", "client");
    EXPECT_EQ(erased.exit_code, 0) << erased.out << ft::readText(site.root() / "server.log");
    EXPECT_TRUE(contains(erased.out, "removed 2 file(s):")) << erased.out;
    EXPECT_FALSE(fs::exists(data / "secure-gone"));
    EXPECT_TRUE(fs::exists(data / "secure-kept" / "mesh.ply"));
    const auto audit = ft::runCommand(std::string(FACESCAN_CLI) + " audit " + data.string() + " --session secure-gone");
    EXPECT_EQ(audit.exit_code, 0) << audit.out;
    EXPECT_TRUE(contains(audit.out, "delete")) << audit.out;
    EXPECT_TRUE(contains(audit.out, "dds CN=client,OU=client,O=lab (client id client@"))
        << "the subject the client authenticated with is on record: " << audit.out;

    // Enrolled identity A (client-a) sends a request that claims to come from B (the client id `client` uses):
    // the record names A, the subject A authenticated with; B only as the claim beside it. `user_data`, when
    // given, replaces what A's participant announces (B's certificate: a forgery the GUID binding catches).
    ASSERT_EQ(site.add("client", "client-a").exit_code, 0);
    const auto forge = [&](const std::string& session, const std::string* user_data) {
        fs::create_directories(data / session);
        std::ofstream(data / session / "mesh.ply") << "ply";
        auto participant = wire::Participant::create({domain, "loopback", site.identity("client-a").string()});
        EXPECT_TRUE(participant.isOk()) << participant.status().toString();
        if (!participant.isOk()) return std::string();
        if (user_data) {
            wire::Qos qos;
            dds_qset_userdata(qos.get(), user_data->data(), user_data->size());
            EXPECT_EQ(dds_set_qos(participant->handle(), qos.get()), DDS_RETCODE_OK);
        }
        auto topic = wire::Topic<facescan_wire_EraseRequest>::create(*participant);
        EXPECT_TRUE(topic.isOk()) << topic.status().toString();
        if (!topic.isOk()) return std::string();
        auto writer = wire::Writer<facescan_wire_EraseRequest>::create(*topic);
        EXPECT_TRUE(writer.isOk() && writer->waitForReaders(1, std::chrono::seconds(20)))
            << ft::readText(site.root() / "server.log");
        const std::string request = session + "-request", claimed = "client@boss-pc:1:1";
        facescan_wire_EraseRequest m{};
        m.session_id = wire::stringView(session);
        m.request_id = wire::stringView(request);
        m.client_id = wire::stringView(claimed);
        EXPECT_TRUE(writer->write(m).isOk());
        for (int i = 0; i < 200 && fs::exists(data / session); ++i) {
            std::this_thread::sleep_for(std::chrono::milliseconds(100));
        }
        EXPECT_FALSE(fs::exists(data / session)) << ft::readText(site.root() / "server.log");
        const auto record =
            ft::runCommand(std::string(FACESCAN_CLI) + " audit " + data.string() + " --session " + session);
        EXPECT_EQ(record.exit_code, 0) << record.out;
        return record.out;
    };
    const std::string forged = forge("secure-forged", nullptr);
    EXPECT_TRUE(contains(forged, "dds CN=client-a,OU=client,O=lab (client id client@boss-pc:1:1)"))
        << "the sender is the identity it authenticated with, not the one it claims: " << forged;
    // B's certificate in A's USER_DATA: never recorded as B (A's own, if the server read it before the change).
    const std::string b_certificate = ft::readText(site.identity("client") / "identity.pem");
    ASSERT_FALSE(b_certificate.empty());
    const std::string b_user_data = "facescan-identity-certificate\n" + b_certificate;
    const std::string stolen = forge("secure-stolen", &b_user_data);
    std::printf("an announced certificate that is not the sender's own:\n%s", stolen.c_str());
    EXPECT_FALSE(contains(stolen, "dds CN=client,")) << stolen;
    EXPECT_TRUE(contains(stolen, "which is not the identity it authenticated with") ||
                contains(stolen, "dds CN=client-a,OU=client,O=lab"))
        << stolen;
}

}  // namespace
