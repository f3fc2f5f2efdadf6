// The command line of `facescan`: every command's arguments and every usage error.
#include "client/cli_args.hpp"

#include <gtest/gtest.h>

namespace facescan::client {
namespace {

StatusOr<CliOptions> parse(std::vector<std::string> args) { return parseArgs(args); }

void expectUsageError(std::vector<std::string> args, const std::string& needle) {
    auto parsed = parse(args);
    ASSERT_FALSE(parsed.isOk()) << "accepted: " << ::testing::PrintToString(args);
    EXPECT_EQ(parsed.status().code(), StatusCode::kInvalidArgument);
    EXPECT_NE(parsed.status().message().find(needle), std::string::npos) << parsed.status().message();
}

TEST(CliArgs, MeshWithGlobalOptionsAnywhere) {
    auto parsed = parse({"--profile", "loopback", "mesh", "scan-1", "-o", "out/face.ply", "--finish", "--domain=42",
                         "--timeout", "2.5"});
    ASSERT_TRUE(parsed.isOk()) << parsed.status().toString();
    EXPECT_EQ(parsed->command, Command::kMesh);
    EXPECT_EQ(parsed->session, "scan-1");
    EXPECT_EQ(parsed->output, "out/face.ply");
    EXPECT_TRUE(parsed->finish);
    EXPECT_EQ(parsed->domain.profile, "loopback");
    EXPECT_EQ(parsed->domain.domain_id, 42u);
    EXPECT_EQ(parsed->timeout.count(), 2500);
    EXPECT_FALSE(parsed->vertex_colours);  // the texture, when the server has one
}

TEST(CliArgs, MeshVertexColoursTakesNoValueAndOnlyForMesh) {
    auto parsed = parse({"mesh", "s", "-o", "f.obj", "--vertex-colours"});
    ASSERT_TRUE(parsed.isOk()) << parsed.status().toString();
    EXPECT_TRUE(parsed->vertex_colours);
    EXPECT_FALSE(parse({"mesh", "s", "-o", "f.obj", "--vertex-colours=yes"}).isOk());
    EXPECT_FALSE(parse({"preview", "s", "-o", "f.png", "--vertex-colours"}).isOk());
}

TEST(CliArgs, MeshFinishingOptionsAndTheirBadValues) {
    auto plain = parse({"mesh", "s", "-o", "f.ply"});
    ASSERT_TRUE(plain.isOk());
    EXPECT_FALSE(plain->finish_here);  // the server's model is written as it came
    auto parsed = parse({"mesh", "s", "-o", "f.glb", "--max-triangles", "avatar", "--keep", "all", "--close", "holes",
                         "--crop=-0.2,-0.2,0.2,0.2,0.2,1.2"});
    ASSERT_TRUE(parsed.isOk()) << parsed.status().toString();
    EXPECT_TRUE(parsed->finish_here);
    EXPECT_EQ(parsed->finish_params.max_triangles, 50000);
    EXPECT_EQ(parsed->finish_params.keep, recon::KeepParts::kAll);
    EXPECT_EQ(parsed->finish_params.close, recon::ClosingMode::kHoles);
    ASSERT_TRUE(parsed->finish_params.crop_m.has_value());
    EXPECT_FLOAT_EQ(parsed->finish_params.crop_m->max().z(), 1.2f);
    EXPECT_EQ(parse({"mesh", "s", "-o", "f.ply", "--max-triangles", "20000"})->finish_params.max_triangles, 20000);
    expectUsageError({"mesh", "s", "-o", "f.ply", "--max-triangles", "499"}, "at least 500");
    expectUsageError({"mesh", "s", "-o", "f.ply", "--max-triangles", "tiny"}, "web (20000)");
    EXPECT_EQ(parse({"mesh", "s", "-o", "f.ply", "--close", "watertight"})->finish_params.close,
              recon::ClosingMode::kWatertight);
    expectUsageError({"mesh", "s", "-o", "f.ply", "--close", "sealed"}, "none, holes or watertight");
    expectUsageError({"mesh", "s", "-o", "f.ply", "--keep", "torso"}, "head");
    expectUsageError({"mesh", "s", "-o", "f.ply", "--crop", "1,2,3"}, "six numbers");
    expectUsageError({"preview", "s", "-o", "f.png", "--max-triangles", "web"}, "unknown option --max-triangles");
}

TEST(CliArgs, SecurityTakesAnIdentityFolderForEveryCommand) {
    for (const std::string command : {"sessions", "watch", "view"}) {
        auto parsed = parse({command, "--security", "/etc/facescan/site/viewer"});
        ASSERT_TRUE(parsed.isOk()) << parsed.status().toString();
        EXPECT_EQ(parsed->domain.security, "/etc/facescan/site/viewer");
    }
    EXPECT_TRUE(parse({"sessions"})->domain.security.empty()) << "DDS Security is off unless asked for";
    expectUsageError({"sessions", "--security"}, "--security needs a value");
    expectUsageError({"sessions", "--security="}, "--security takes an identity folder");
    expectUsageError({"sessions", "--security", "x", "--domain", "231"}, "DDS Security covers domain ids 0..230");
}

TEST(CliArgs, DefaultsAreLanDomainZeroTenSeconds) {
    auto parsed = parse({"sessions"});
    ASSERT_TRUE(parsed.isOk());
    EXPECT_EQ(parsed->domain.profile, "lan");
    EXPECT_EQ(parsed->domain.domain_id, 0u);
    EXPECT_EQ(parsed->timeout.count(), 10'000);
    EXPECT_FALSE(parsed->json);
}

TEST(CliArgs, WatchSessionIsOptionalAndSaveTakesAFormat) {
    auto newest = parse({"watch"});
    ASSERT_TRUE(newest.isOk());
    EXPECT_EQ(newest->command, Command::kWatch);
    EXPECT_TRUE(newest->session.empty());
    auto saving = parse({"watch", "s", "--save", "snaps", "--save-format", "drc"});
    ASSERT_TRUE(saving.isOk()) << saving.status().toString();
    EXPECT_EQ(saving->save_dir, "snaps");
    EXPECT_EQ(saving->save_format, "drc");
    expectUsageError({"watch", "s", "--save", "d", "--save-format", "xyz"}, "--save-format");
    expectUsageError({"watch", "s", "--save-format", "ply"}, "needs --save");
}

TEST(CliArgs, EveryMeshExtensionIsAcceptedCaseInsensitively) {
    for (const char* file : {"a.ply", "a.obj", "a.stl", "a.off", "a.drc", "a.glb", "A.PLY", "dir/b.Obj"}) {
        EXPECT_TRUE(parse({"mesh", "s", "-o", file}).isOk()) << file;
    }
    expectUsageError({"mesh", "s", "-o", "a.xyz"}, "unknown mesh format");
    expectUsageError({"mesh", "s", "-o", "noext"}, "unknown mesh format");
}

TEST(CliArgs, HelpWinsAndNamesTheCommand) {
    auto help = parse({"mesh", "--help"});
    ASSERT_TRUE(help.isOk());
    EXPECT_TRUE(help->help);
    EXPECT_EQ(help->help_topic, "mesh");
    EXPECT_NE(usageText(help->help_topic).find("--finish"), std::string::npos);
    auto overview = parse({"-h"});
    ASSERT_TRUE(overview.isOk());
    EXPECT_TRUE(overview->help);
    EXPECT_TRUE(overview->help_topic.empty());
    EXPECT_NE(usageText("").find("trajectory SESSION"), std::string::npos);
    auto help_cmd = parse({"help", "watch"});
    ASSERT_TRUE(help_cmd.isOk());
    EXPECT_EQ(help_cmd->help_topic, "watch");
}

TEST(CliArgs, TrajectoryOutputIsOptional) {
    auto parsed = parse({"trajectory", "s"});
    ASSERT_TRUE(parsed.isOk());
    EXPECT_TRUE(parsed->output.empty());
}

TEST(CliArgs, ViewListsOnLocalhostPort8080UnlessTold) {
    auto plain = parse({"view"});
    ASSERT_TRUE(plain.isOk()) << plain.status().toString();
    EXPECT_EQ(plain->command, Command::kView);
    EXPECT_EQ(plain->view_port, 8080);
    EXPECT_EQ(plain->view_bind, "127.0.0.1");
    EXPECT_FALSE(plain->view_open);
    EXPECT_FALSE(plain->view_insecure_http);
    // Plain HTTP to the network only when the user says so (see CliErrors for the message).
    expectUsageError({"view", "--bind", "0.0.0.0"}, "would serve every scan");
    expectUsageError({"view", "--bind", "10.0.0.5"}, "--insecure-http");
    expectUsageError({"view", "--bind", "::"}, "ssh -L");
    expectUsageError({"view", "--bind", "0.0.0.0"}, "facescan-site web SITE NAME --host THIS-HOST");
    expectUsageError({"view", "--bind", "0.0.0.0", "--tls", "site/viewer", "--insecure-http"}, "contradict");
    expectUsageError({"view", "--tls"}, "--tls needs a value");
    auto tls = parse({"view", "--bind", "0.0.0.0", "--tls", "site/viewer"});
    ASSERT_TRUE(tls.isOk()) << tls.status().toString();
    EXPECT_EQ(tls->view_tls, "site/viewer");
    EXPECT_FALSE(tls->view_insecure_http);
    EXPECT_TRUE(parse({"view", "--bind", "127.0.0.2"}).isOk()) << "all of 127/8 is this machine";
    EXPECT_TRUE(parse({"view", "--bind", "::1"}).isOk());
    EXPECT_TRUE(parse({"view", "--bind", "::ffff:127.0.0.1"}).isOk());
    auto lan = parse({"view", "--port", "0", "--bind", "0.0.0.0", "--open", "--insecure-http", "--domain", "7"});
    ASSERT_TRUE(lan.isOk()) << lan.status().toString();
    EXPECT_EQ(lan->view_port, 0);
    EXPECT_EQ(lan->view_bind, "0.0.0.0");
    EXPECT_TRUE(lan->view_open);
    EXPECT_TRUE(lan->view_insecure_http);
    EXPECT_EQ(lan->domain.domain_id, 7u);
    expectUsageError({"view", "--port", "65536"}, "--port must be a TCP port");
    expectUsageError({"view", "--port", "http"}, "--port must be a TCP port");
    expectUsageError({"view", "--bind", "my-laptop"}, "--bind needs an IP address");
    expectUsageError({"view", "scan-1"}, "unexpected argument 'scan-1'");
    expectUsageError({"status", "s", "--port", "80"}, "unknown option --port");
}

TEST(CliArgs, UsageErrorsSayWhatIsWrong) {
    expectUsageError({}, "no command");
    expectUsageError({"scan"}, "unknown command 'scan'");
    expectUsageError({"mesh", "s"}, "needs -o");
    expectUsageError({"mesh", "-o", "a.ply"}, "needs a SESSION");
    expectUsageError({"status"}, "needs a SESSION");
    expectUsageError({"status", "a", "b"}, "unexpected argument 'b'");
    expectUsageError({"sessions", "extra"}, "unexpected argument");
    expectUsageError({"preview", "s", "-o", "p.jpg"}, ".png");
    expectUsageError({"status", "s", "--finish"}, "unknown option --finish");
    expectUsageError({"status", "s", "--domain"}, "--domain needs a value");
    expectUsageError({"status", "s", "--domain", "x"}, "--domain must be a number");
    expectUsageError({"status", "s", "--domain", "300"}, "0..232");
    expectUsageError({"status", "s", "--timeout", "0"}, "--timeout");
    expectUsageError({"status", "s", "--timeout", "-1"}, "--timeout");
    expectUsageError({"status", "s", "--finish=yes"}, "takes no value");
    expectUsageError({"status", "../etc"}, "session id");
    expectUsageError({"status", "s", "--profile", ""}, "profile");
    expectUsageError({"mesh", "s", "-o", "a.ply", "-o", "b.ply"}, "given twice");
}

}  // namespace
}  // namespace facescan::client
