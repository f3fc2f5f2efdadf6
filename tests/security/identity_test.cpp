// The site script and the start-up checks of an identity (no DDS traffic): every test makes a fresh site with
// deploy/security/site.sh, and every check is shown to fail on the file it names.
#include <fnmatch.h>
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <functional>
#include <regex>
#include <set>

#include "child_process.hpp"
#include "site_fixture.hpp"
#include "wire/dds.hpp"
#include "wire/security.hpp"

namespace {

namespace fs = std::filesystem;
using facescan::StatusCode;
using facescan::testing::readText;
using facescan::testing::TempSite;

bool contains(const std::string& text, const std::string& part) { return text.find(part) != std::string::npos; }

void replaceInFile(const fs::path& path, const std::string& from, const std::string& to) {
    std::string text = readText(path);
    const size_t at = text.find(from);
    ASSERT_NE(at, std::string::npos) << from << " not in " << path;
    text.replace(at, from.size(), to);
    std::ofstream(path, std::ios::binary) << text;
}

TEST(SiteScript, InitMakesOneIdentityPerRoleThatChecksOut) {
    TempSite site("init");
    ASSERT_TRUE(site.ok()) << site.initOutput();
    for (const std::string role : {"agent", "server", "client", "viewer"}) {
        auto identity = facescan::wire::checkIdentity(site.identity(role));
        ASSERT_TRUE(identity.isOk()) << identity.status().toString();
        EXPECT_EQ(identity->name, role);
        EXPECT_EQ(identity->role, role);
        EXPECT_EQ(identity->site, "lab");
        // The CA keys never go into an identity folder (it is what gets copied to a machine).
        for (const auto& entry : fs::directory_iterator(site.identity(role))) {
            EXPECT_FALSE(contains(entry.path().filename().string(), "_ca.key")) << entry.path();
        }
        EXPECT_EQ(fs::status(site.identity(role) / "identity.key").permissions() & fs::perms::others_read,
                  fs::perms::none);
    }
    const auto list = TempSite::site("list " + site.dir().string());
    EXPECT_EQ(list.exit_code, 0) << list.out;
    for (const std::string role : {"agent", "server", "client", "viewer"}) {
        EXPECT_TRUE(std::regex_search(list.out, std::regex(role + " +" + role + " +[0-9-]+T[0-9:]+ +ok"))) << list.out;
    }
}

TEST(SiteScript, HelpShowsHowToEnrolACapturePcInThreeCommands) {
    const auto help = TempSite::site("--help");
    EXPECT_EQ(help.exit_code, 0);
    EXPECT_TRUE(contains(help.out, "in three commands")) << help.out;
    EXPECT_TRUE(std::regex_search(
        help.out,
        std::regex(R"(site\.sh add \S+ agent (\S+).*\n.*scp -r \S+/\1 .*\n.*facescan-agent .*--security \S+/\1)")))
        << help.out;
}

TEST(SiteScript, RefusesBadInputWithAReason) {
    TempSite site("usage");
    ASSERT_TRUE(site.ok()) << site.initOutput();
    const auto role = site.add("admin", "pc1");
    EXPECT_EQ(role.exit_code, 2);
    EXPECT_TRUE(contains(role.out, "unknown role 'admin'")) << role.out;
    const auto name = site.add("agent", "pc/1");
    EXPECT_EQ(name.exit_code, 2);
    EXPECT_TRUE(contains(name.out, "not a valid name")) << name.out;
    const auto twice = site.add("agent", "agent");
    EXPECT_EQ(twice.exit_code, 1);
    EXPECT_TRUE(contains(twice.out, "exists already")) << twice.out;
    const auto again = TempSite::site("init " + site.dir().string());
    EXPECT_EQ(again.exit_code, 1);
    EXPECT_TRUE(contains(again.out, "not empty")) << again.out;
    const auto nosite = TempSite::site("add " + site.root().string() + " agent pc1");
    EXPECT_EQ(nosite.exit_code, 1);
    EXPECT_TRUE(contains(nosite.out, "is not a facescan site")) << nosite.out;
    const auto unknown = site.revoke("nobody");
    EXPECT_EQ(unknown.exit_code, 1);
    EXPECT_TRUE(contains(unknown.out, "no identity 'nobody'")) << unknown.out;
}

// The topics of idl/include/wire/topics.hpp, read from the header itself so that a new topic without a grant
// fails here rather than at a site.
std::set<std::string> facescanTopics() {
    const std::string header = readText(fs::path(FACESCAN_SOURCE_DIR) / "idl/include/wire/topics.hpp");
    std::set<std::string> topics;
    const std::regex name(R"re("(facescan/[A-Za-z0-9_/]+)")re");
    for (auto it = std::sregex_iterator(header.begin(), header.end(), name); it != std::sregex_iterator(); ++it) {
        topics.insert((*it)[1].str());
    }
    return topics;
}

// The topic patterns of one <publish> or <subscribe> block of a permissions document.
std::vector<std::string> grantedTopics(const std::string& xml, const std::string& kind) {
    std::vector<std::string> topics;
    const std::regex block("<" + kind + ">([\\s\\S]*?)</" + kind + ">");
    std::smatch m;
    if (!std::regex_search(xml, m, block)) return topics;
    const std::string body = m[1].str();
    // Cyclone refuses every reader and writer of a block without partitions (NOT_ALLOWED_BY_SECURITY, -13).
    EXPECT_TRUE(contains(body, "<partitions><partition>*</partition></partitions>")) << body;
    const std::regex topic("<topic>([^<]+)</topic>");
    for (auto it = std::sregex_iterator(body.begin(), body.end(), topic); it != std::sregex_iterator(); ++it) {
        topics.push_back((*it)[1].str());
    }
    return topics;
}

bool grants(const std::vector<std::string>& patterns, const std::string& topic) {
    for (const std::string& p : patterns) {
        if (fnmatch(p.c_str(), topic.c_str(), 0) == 0) return true;
    }
    return false;
}

TEST(SiteScript, EveryTopicHasAPublisherAndASubscriberRoleAndTheViewerOnlyReads) {
    TempSite site("topics");
    ASSERT_TRUE(site.ok()) << site.initOutput();
    const std::set<std::string> topics = facescanTopics();
    ASSERT_GE(topics.size(), 6u);
    std::map<std::string, std::pair<std::vector<std::string>, std::vector<std::string>>> roles;
    for (const std::string role : {"agent", "server", "client", "viewer"}) {
        const std::string xml = readText(site.identity(role) / "permissions.xml");
        roles[role] = {grantedTopics(xml, "publish"), grantedTopics(xml, "subscribe")};
    }
    for (const std::string& topic : topics) {
        int publishers = 0, subscribers = 0;
        for (const auto& [role, granted] : roles) {
            publishers += grants(granted.first, topic);
            subscribers += grants(granted.second, topic);
        }
        EXPECT_GT(publishers, 0) << topic << " has no role that may publish it (deploy/security/site.sh)";
        EXPECT_GT(subscribers, 0) << topic << " has no role that may read it (deploy/security/site.sh)";
    }
    EXPECT_TRUE(roles["viewer"].first.empty()) << "the viewer publishes nothing";
    EXPECT_FALSE(grants(roles["viewer"].second, "facescan/RgbdFrame")) << "the viewer never sees frames";
    EXPECT_FALSE(grants(roles["agent"].first, "facescan/ScanCommand")) << "an agent sends no commands";
    EXPECT_TRUE(grants(roles["client"].first, "facescan/ScanCommand"));
    EXPECT_TRUE(grants(roles["server"].first, "facescan/cluster/Replica")) << "servers talk to each other";
    EXPECT_FALSE(grants(roles["client"].second, "facescan/cluster/Replica")) << "cluster topics are servers' only";
}

// One way to spoil an identity folder, the file the check must name and the words it must use.
struct BadIdentity {
    const char* what;
    std::function<void(const TempSite&, const fs::path& id)> spoil;
    const char* file;
    const char* says;
    StatusCode code = StatusCode::kPermissionDenied;
};

TEST(IdentityCheck, EachBadFileStopsWithOneLineThatNamesItAndSaysWhy) {
    TempSite site("bad");
    ASSERT_TRUE(site.ok()) << site.initOutput();
    TempSite other("bad_other", "othersite");
    ASSERT_TRUE(other.ok()) << other.initOutput();
    const std::vector<BadIdentity> cases = {
        {"missing key", [](const TempSite&, const fs::path& id) { fs::remove(id / "identity.key"); }, "identity.key",
         "missing", StatusCode::kNotFound},
        {"expired",
         [](const TempSite& s, const fs::path& id) {
             fs::remove_all(id);
             s.add("agent", id.filename().string(), "--from 2020-01-01 --until 2021-01-01");
         },
         "identity.pem", "expired on 2021-01-01 00:00 UTC"},
        {"not yet valid",
         [](const TempSite& s, const fs::path& id) {
             fs::remove_all(id);
             s.add("agent", id.filename().string(), "--from 2099-01-01 --days 30");
         },
         "identity.pem", "not valid before 2099-01-01 00:00 UTC"},
        {"tampered permissions",
         [](const TempSite&, const fs::path& id) {
             replaceInFile(id / "permissions.p7s", "<topic>facescan/RgbdFrame</topic>",
                           "<topic>facescan/ScanCommand</topic>");
         },
         "permissions.p7s", "changed after it was signed"},
        {"tampered governance",
         [](const TempSite&, const fs::path& id) {
             replaceInFile(id / "governance.p7s", "<data_protection_kind>ENCRYPT", "<data_protection_kind>NONE");
         },
         "governance.p7s", "changed after it was signed"},
        {"certificate of another site",
         [&other](const TempSite&, const fs::path& id) {
             fs::copy_file(other.identity("agent") / "identity.pem", id / "identity.pem",
                           fs::copy_options::overwrite_existing);
             fs::copy_file(other.identity("agent") / "identity.key", id / "identity.key",
                           fs::copy_options::overwrite_existing);
         },
         "identity.pem", "not signed by this site's identity CA"},
        {"permissions of another site",
         [&other](const TempSite&, const fs::path& id) {
             fs::copy_file(other.identity("agent") / "permissions.p7s", id / "permissions.p7s",
                           fs::copy_options::overwrite_existing);
         },
         "permissions.p7s", "not signed by this site's permissions CA"},
        {"permissions of another identity",
         [](const TempSite& s, const fs::path& id) {
             fs::copy_file(s.identity("client") / "permissions.p7s", id / "permissions.p7s",
                           fs::copy_options::overwrite_existing);
         },
         "permissions.p7s", "not this identity's certificate"},
        {"key of another identity",
         [](const TempSite& s, const fs::path& id) {
             fs::copy_file(s.identity("client") / "identity.key", id / "identity.key",
                           fs::copy_options::overwrite_existing);
         },
         "identity.key", "is not the private key of"},
        {"revoked", [](const TempSite& s, const fs::path& id) { s.revoke(id.filename().string()); }, "identity.pem",
         "revoked on"},
        {"not a certificate",
         [](const TempSite&, const fs::path& id) { std::ofstream(id / "identity_ca.pem") << "hello\n"; },
         "identity_ca.pem", "not a PEM certificate"},
        {"revocation list of another site",
         [&other](const TempSite&, const fs::path& id) {
             fs::copy_file(other.dir() / "crl.pem", id / "crl.pem", fs::copy_options::overwrite_existing);
         },
         "crl.pem", "not signed by this site's identity CA"},
    };
    int n = 0;
    for (const BadIdentity& c : cases) {
        SCOPED_TRACE(c.what);
        const std::string name = "pc" + std::to_string(++n);
        ASSERT_EQ(site.add("agent", name).exit_code, 0);
        const fs::path id = site.identity(name);
        ASSERT_TRUE(facescan::wire::checkIdentity(id).isOk()) << "the check passes before the file is spoilt";
        c.spoil(site, id);
        const auto checked = facescan::wire::checkIdentity(id);
        ASSERT_FALSE(checked.isOk());
        const std::string& message = checked.status().message();
        EXPECT_EQ(checked.status().code(), c.code) << message;
        EXPECT_TRUE(contains(message, (id / c.file).string() + ": ")) << message;
        EXPECT_TRUE(contains(message, c.says)) << message;
        EXPECT_FALSE(contains(message, "\n")) << message;
    }
}

TEST(SecurityConfig, NamesThePluginsByFullPathAndEveryFileOfTheIdentity) {
    TempSite site("xml");
    ASSERT_TRUE(site.ok()) << site.initOutput();
    const std::string profile = "<CycloneDDS><Domain Id=\"any\"><General/></Domain></CycloneDDS>";
    auto xml = facescan::wire::addSecurity(profile, site.identity("agent"));
    ASSERT_TRUE(xml.isOk()) << xml.status().toString();
    const fs::path plugins = facescan::wire::securityPluginDir();
    ASSERT_TRUE(plugins.is_absolute()) << plugins;
    for (const char* lib : {"libdds_security_auth.so", "libdds_security_ac.so", "libdds_security_crypto.so"}) {
        EXPECT_TRUE(fs::exists(plugins / lib)) << plugins / lib;
        EXPECT_TRUE(contains(*xml, "path=\"" + (plugins / lib).string() + "\"")) << *xml;
    }
    for (const char* file : {"identity_ca.pem", "identity.pem", "identity.key", "crl.pem", "permissions_ca.pem",
                             "governance.p7s", "permissions.p7s"}) {
        EXPECT_TRUE(contains(*xml, "file:" + (fs::absolute(site.identity("agent")) / file).string())) << file;
    }
    EXPECT_TRUE(contains(*xml, "</Security>\n</Domain></CycloneDDS>")) << *xml;

    const auto no_domain = facescan::wire::addSecurity("<CycloneDDS/>", site.identity("agent"));
    EXPECT_EQ(no_domain.status().code(), StatusCode::kInvalidArgument);
    const auto twice = facescan::wire::addSecurity(*xml, site.identity("agent"));
    EXPECT_EQ(twice.status().code(), StatusCode::kInvalidArgument);
    // Domain ids above 230 cannot be named by governance and permissions documents.
    EXPECT_FALSE(facescan::wire::DomainConfig(231, "loopback", site.identity("agent").string()).validate().isOk());
    EXPECT_TRUE(facescan::wire::DomainConfig(231, "loopback").validate().isOk());
}

}  // namespace
