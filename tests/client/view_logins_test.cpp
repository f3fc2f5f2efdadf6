// The viewer's logins (client/view_logins.hpp): hashes made by the same openssl command site.sh runs are checked
// by OpenSSL's PBKDF2 here; wrong passwords brake further tries per address and per user; sessions end when idle,
// when too old, at logout, and when their user leaves the logins file. Time is driven by the test.
#include "client/view_logins.hpp"

#include <gtest/gtest.h>
#include <unistd.h>

#include <chrono>
#include <filesystem>
#include <fstream>

#include "run_command.hpp"

namespace facescan::client {
namespace {

// A logins line for `user` made as facescan-site login makes it: openssl enc -pbkdf2 (the minimum iterations we
// accept, to keep the test quick).
std::string loginLine(const std::string& user, const std::string& password, const std::string& salt_hex) {
    const auto run = testing::runCommand("printf '%s\\n' '" + password +
                                         "' | openssl enc -aes-256-cbc -pbkdf2 -md sha256 -iter 100000 -S " + salt_hex +
                                         " -pass stdin -P | sed -n 's/^key=//p'");
    EXPECT_EQ(run.exit_code, 0) << run.out;
    std::string key = run.out;
    while (!key.empty() && (key.back() == '\n' || key.back() == ' ')) key.pop_back();
    EXPECT_EQ(key.size(), 64u) << run.out;
    return user + ":pbkdf2-sha256:100000:" + salt_hex + ":" + key;
}

std::vector<LoginEntry> entries(const std::string& text) {
    auto parsed = parseLogins(text, "logins");
    EXPECT_TRUE(parsed.isOk()) << parsed.status().toString();
    return parsed.isOk() ? *parsed : std::vector<LoginEntry>{};
}

TEST(ViewLogins, TheHashOfOpensslEncPbkdf2IsCheckedAndAWrongPasswordFails) {
    const auto list = entries("# viewer logins\n" + loginLine("alice", "correct horse battery", "0011223344556677") +
                              "\n" + loginLine("bob", "another password", "8899aabbccddeeff") + "\n");
    ASSERT_EQ(list.size(), 2u);
    EXPECT_TRUE(passwordMatches(list[0], "correct horse battery"));
    EXPECT_FALSE(passwordMatches(list[0], "correct horse batterz"));
    EXPECT_FALSE(passwordMatches(list[0], "another password")) << "bob's password is not alice's";
    EXPECT_FALSE(passwordMatches(list[0], ""));
    EXPECT_TRUE(passwordMatches(list[1], "another password"));
}

TEST(ViewLogins, AMalformedLineIsRefusedWithItsNumber) {
    const std::string good = loginLine("alice", "correct horse battery", "0011223344556677");
    const auto expectBad = [](const std::string& text, const std::string& needle) {
        auto parsed = parseLogins(text, "f");
        ASSERT_FALSE(parsed.isOk()) << text;
        EXPECT_NE(parsed.status().message().find(needle), std::string::npos) << parsed.status().message();
    };
    expectBad("alice:plain:secret\n", "f line 1: expected USER:pbkdf2-sha256");
    expectBad("\n# c\n" + good.substr(0, good.size() - 2) + "\n", "f line 3: KEY must be 32 bytes");
    expectBad(good + "\n" + good + "\n", "listed twice");
    expectBad("al ice:pbkdf2-sha256:100000:0011223344556677:" + std::string(64, 'a') + "\n", "not a valid user");
    expectBad("alice:pbkdf2-sha256:1000:0011223344556677:" + std::string(64, 'a') + "\n", "ITERATIONS must be");
    expectBad("alice:pbkdf2-sha256:100000:zz11223344556677:" + std::string(64, 'a') + "\n", "SALT must be");
    EXPECT_TRUE(parseLogins("# nothing yet\n", "f").isOk());
}

TEST(ViewLogins, WrongPasswordsBrakeTheAddressAndTheUserAndARightOneReleasesThem) {
    LoginParams params;
    params.free_failures = 3;
    params.first_lockout_s = 30;
    params.max_lockout_s = 100;
    LoginBook book(params);
    book.setEntries(entries(loginLine("alice", "correct horse battery", "0011223344556677")));
    double t = 1000;
    for (int i = 0; i < 2; ++i)
        EXPECT_EQ(book.login("alice", "guess", "10.0.0.9", t).outcome, LoginBook::Outcome::kWrong);
    // The third wrong one starts the brake: 30 s, during which even the right password is not taken.
    EXPECT_EQ(book.login("alice", "guess", "10.0.0.9", t).outcome, LoginBook::Outcome::kWrong);
    auto locked = book.login("alice", "correct horse battery", "10.0.0.9", t + 1);
    EXPECT_EQ(locked.outcome, LoginBook::Outcome::kLockedOut);
    EXPECT_NEAR(locked.retry_after_s, 29.0, 1e-6);
    // The user is braked from another address too (a guesser that changes address), and the address for
    // another user (one that changes user).
    EXPECT_EQ(book.login("alice", "correct horse battery", "10.0.0.7", t + 2).outcome, LoginBook::Outcome::kLockedOut);
    EXPECT_EQ(book.login("bob", "x", "10.0.0.9", t + 2).outcome, LoginBook::Outcome::kLockedOut);
    // After it, one more wrong password doubles the wait (60 s), then 100 s at most.
    t += 31;
    EXPECT_EQ(book.login("alice", "guess", "10.0.0.9", t).outcome, LoginBook::Outcome::kWrong);
    EXPECT_NEAR(book.login("alice", "guess", "10.0.0.9", t).retry_after_s, 60.0, 1e-6);
    t += 61;
    EXPECT_EQ(book.login("alice", "guess", "10.0.0.9", t).outcome, LoginBook::Outcome::kWrong);
    EXPECT_NEAR(book.login("alice", "guess", "10.0.0.9", t).retry_after_s, 100.0, 1e-6) << "capped";
    t += 101;
    const auto ok = book.login("alice", "correct horse battery", "10.0.0.9", t);
    ASSERT_EQ(ok.outcome, LoginBook::Outcome::kOk);
    // Released: the next wrong password is a free one again.
    EXPECT_EQ(book.login("alice", "guess", "10.0.0.9", t).outcome, LoginBook::Outcome::kWrong);
    EXPECT_EQ(book.login("alice", "correct horse battery", "10.0.0.9", t).outcome, LoginBook::Outcome::kOk);
    // An unknown user is just a wrong login (and counts).
    EXPECT_EQ(book.login("mallory", "correct horse battery", "10.0.0.5", t).outcome, LoginBook::Outcome::kWrong);
}

TEST(ViewLogins, SessionsEndWhenIdleWhenTooOldAtLogoutAndWhenTheirUserIsRemoved) {
    LoginParams params;
    params.session_idle_s = 60;
    params.session_max_s = 300;
    LoginBook book(params);
    const std::string alice = loginLine("alice", "correct horse battery", "0011223344556677");
    const std::string bob = loginLine("bob", "another password", "8899aabbccddeeff");
    book.setEntries(entries(alice + "\n" + bob + "\n"));
    double t = 0;
    const auto a = book.login("alice", "correct horse battery", "127.0.0.1", t);
    ASSERT_EQ(a.outcome, LoginBook::Outcome::kOk);
    EXPECT_EQ(a.token.size(), 64u);
    EXPECT_EQ(a.token.find_first_not_of("0123456789abcdef"), std::string::npos) << a.token;
    EXPECT_FALSE(book.check("", t));
    EXPECT_FALSE(book.check(a.token.substr(1) + "0", t));
    // Used every 50 s, it lives until its maximum age.
    for (t = 50; t <= 300; t += 50) EXPECT_EQ(book.check(a.token, t).value_or("none"), "alice") << t;
    EXPECT_FALSE(book.check(a.token, 301)) << "older than session_max_s";
    // Idle for longer than session_idle_s.
    t = 1000;
    const auto idle = book.login("alice", "correct horse battery", "127.0.0.1", t);
    EXPECT_TRUE(book.check(idle.token, t + 59));
    EXPECT_FALSE(book.check(idle.token, t + 59 + 61));
    // Logout, and two logins get different tokens.
    const auto b1 = book.login("bob", "another password", "127.0.0.1", t);
    const auto b2 = book.login("bob", "another password", "127.0.0.1", t);
    EXPECT_NE(b1.token, b2.token);
    book.logout(b1.token);
    EXPECT_FALSE(book.check(b1.token, t));
    EXPECT_TRUE(book.check(b2.token, t));
    // Bob leaves the logins file: his sessions end.
    const auto dir = std::filesystem::temp_directory_path() / ("facescan-logins-" + std::to_string(getpid()));
    std::filesystem::create_directories(dir);
    std::ofstream(dir / "logins") << alice << "\n" << bob << "\n";
    ASSERT_TRUE(book.load(dir / "logins").isOk());
    EXPECT_TRUE(book.check(b2.token, t));
    const auto loaded_at = std::filesystem::last_write_time(dir / "logins");
    std::ofstream(dir / "logins", std::ios::trunc) << alice << "\n";
    // A later modification time (a file system's clock may not have ticked since the load).
    std::filesystem::last_write_time(dir / "logins", loaded_at + std::chrono::seconds(10));
    ASSERT_TRUE(book.reload().isOk());
    EXPECT_EQ(book.users(), 1u);
    EXPECT_FALSE(book.check(b2.token, t));
    // An empty or missing file is an error that says what to run.
    std::ofstream(dir / "empty") << "# none\n";
    const Status empty = book.load(dir / "empty");
    EXPECT_NE(empty.message().find("facescan-site login SITE NAME USER"), std::string::npos) << empty.message();
    EXPECT_EQ(book.load(dir / "missing").code(), StatusCode::kNotFound);
    std::filesystem::remove_all(dir);
}

}  // namespace
}  // namespace facescan::client
