// Who may use `facescan view --tls`: the viewer logins of the site (facescan-site login SITE NAME USER writes them
// to SITE/NAME/logins), the sessions of the browsers that logged in, and the brake on guessing passwords.
//
// A logins file has one line per user, "USER:pbkdf2-sha256:ITERATIONS:SALT:KEY" (SALT and KEY in hex; '#' starts
// a comment): KEY is what `openssl enc -pbkdf2 -md sha256 -iter ITERATIONS -S SALT -pass stdin -P` prints as key=
// for the password, the first 32 of the 48 bytes PBKDF2-HMAC-SHA256 derives (RFC 8018, section 5.2). The check runs
// OpenSSL's PKCS5_PBKDF2_HMAC and compares in constant time; no password is ever stored.
//
// Pure: no sockets and no clock of its own (every call takes the time in seconds), so the timeouts and the
// rate limit are tested without waiting.
#pragma once

#include <cstdint>
#include <filesystem>
#include <map>
#include <mutex>
#include <optional>
#include <string>
#include <vector>

#include "recon/status.hpp"

namespace facescan::client {

struct LoginParams {
    double session_idle_s = 15 * 60;      // a session unused this long ends (the browser logs in again)
    double session_max_s = 12 * 60 * 60;  // and none lasts longer than this, used or not
    int free_failures = 5;                // wrong passwords allowed before the brake (per address and per user)
    double first_lockout_s = 30;          // then each further failure locks out twice as long as the last ...
    double max_lockout_s = 15 * 60;       // ... up to this
    size_t max_sessions = 1000;           // the oldest session goes when a new one would exceed this

    Status validate() const;
};

struct LoginEntry {
    std::string user;
    uint32_t iterations = 0;
    std::vector<uint8_t> salt;
    std::vector<uint8_t> key;  // 32 bytes
};

// Parses a logins file's text. InvalidArgument naming the line for a malformed one; an empty list is an error
// for the caller to judge (see LoginBook::load).
StatusOr<std::vector<LoginEntry>> parseLogins(const std::string& text, const std::string& origin);

// Whether `password` matches `entry` (PBKDF2-HMAC-SHA256 through OpenSSL, constant-time comparison).
bool passwordMatches(const LoginEntry& entry, const std::string& password);

class LoginBook {
 public:
    explicit LoginBook(LoginParams params = {}) : params_(params) {}

    // Reads the logins file; again later whenever the file has changed (reload()), so a login added or removed
    // with facescan-site takes effect without a restart. NotFound or InvalidArgument with what to run.
    Status load(const std::filesystem::path& file);
    // Re-reads the file when its modification time changed; keeps the old list (and says why) when it is broken.
    Status reload();
    // Uses `entries` instead of a file (tests).
    void setEntries(std::vector<LoginEntry> entries);
    size_t users() const;

    enum class Outcome { kOk, kWrong, kLockedOut };
    struct Attempt {
        Outcome outcome = Outcome::kWrong;
        std::string token;         // kOk: the new session's token (64 hex digits, from OpenSSL's RAND_bytes)
        double retry_after_s = 0;  // kLockedOut: when the next try is taken
    };
    // One login from `address` at `now_s`. While the address or the user is locked out, the password is not even
    // checked. A wrong user and a wrong password look the same to the caller.
    Attempt login(const std::string& user, const std::string& password, const std::string& address, double now_s);

    // The user of a live session (and it counts as used now), or nullopt: unknown, idle too long or too old.
    std::optional<std::string> check(const std::string& token, double now_s);
    void logout(const std::string& token);
    size_t sessions() const;

 private:
    struct Session {
        std::string user;
        double created_s = 0;
        double last_s = 0;
    };
    struct Brake {
        int failures = 0;
        double locked_until_s = 0;
    };
    void fail(const std::string& key, double now_s);
    double lockedUntil(const std::string& key) const;

    LoginParams params_;
    mutable std::mutex mutex_;
    std::filesystem::path file_;
    std::filesystem::file_time_type file_time_{};
    std::vector<LoginEntry> entries_;
    std::map<std::string, Session> sessions_;
    std::map<std::string, Brake> brakes_;  // "address:..." and "user:..."
};

}  // namespace facescan::client
