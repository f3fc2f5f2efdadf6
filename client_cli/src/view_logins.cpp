#include "client/view_logins.hpp"

#include <openssl/crypto.h>
#include <openssl/evp.h>
#include <openssl/rand.h>

#include <algorithm>
#include <cctype>
#include <cmath>
#include <fstream>
#include <sstream>

namespace facescan::client {
namespace {

constexpr size_t kKeyBytes = 32;      // the key= of `openssl enc -aes-256-cbc -pbkdf2`
constexpr size_t kDerivedBytes = 48;  // enc derives key and IV together; the IV's 16 bytes are not stored
constexpr uint32_t kMinIterations = 100'000;
constexpr uint32_t kMaxIterations = 10'000'000;

std::optional<std::vector<uint8_t>> fromHex(const std::string& hex) {
    if (hex.empty() || hex.size() % 2 != 0) return std::nullopt;
    std::vector<uint8_t> out(hex.size() / 2);
    for (size_t i = 0; i < out.size(); ++i) {
        int v = 0;
        for (int k = 0; k < 2; ++k) {
            const char c = hex[2 * i + k];
            const int d = c >= '0' && c <= '9'   ? c - '0'
                          : c >= 'a' && c <= 'f' ? c - 'a' + 10
                          : c >= 'A' && c <= 'F' ? c - 'A' + 10
                                                 : -1;
            if (d < 0) return std::nullopt;
            v = v * 16 + d;
        }
        out[i] = static_cast<uint8_t>(v);
    }
    return out;
}

std::vector<std::string> split(const std::string& line, char sep) {
    std::vector<std::string> parts;
    std::string part;
    std::istringstream in(line);
    while (std::getline(in, part, sep)) parts.push_back(part);
    if (!line.empty() && line.back() == sep) parts.emplace_back();
    return parts;
}

bool validUser(const std::string& user) {
    if (user.empty() || user.size() > 64) return false;
    return std::all_of(user.begin(), user.end(),
                       [](unsigned char c) { return std::isalnum(c) || c == '.' || c == '_' || c == '-' || c == '@'; });
}

}  // namespace

Status LoginParams::validate() const {
    if (!(session_idle_s > 0) || !(session_max_s >= session_idle_s)) {
        return invalidArgument("LoginParams: session_idle_s must be > 0 and session_max_s >= session_idle_s");
    }
    if (free_failures < 1 || !(first_lockout_s > 0) || !(max_lockout_s >= first_lockout_s) || max_sessions < 1) {
        return invalidArgument(
            "LoginParams: free_failures >= 1, 0 < first_lockout_s <= max_lockout_s, max_sessions >= 1");
    }
    return Status::ok();
}

StatusOr<std::vector<LoginEntry>> parseLogins(const std::string& text, const std::string& origin) {
    std::vector<LoginEntry> entries;
    std::istringstream in(text);
    std::string line;
    int number = 0;
    while (std::getline(in, line)) {
        ++number;
        if (!line.empty() && line.back() == '\r') line.pop_back();
        if (line.empty() || line[0] == '#') continue;
        const std::string where = origin + " line " + std::to_string(number);
        const std::vector<std::string> f = split(line, ':');
        if (f.size() != 5 || f[1] != "pbkdf2-sha256") {
            return invalidArgument(where +
                                   ": expected USER:pbkdf2-sha256:ITERATIONS:SALT:KEY (made by facescan-site login)");
        }
        LoginEntry e;
        e.user = f[0];
        if (!validUser(e.user)) return invalidArgument(where + ": '" + e.user + "' is not a valid user name");
        char* end = nullptr;
        const unsigned long iterations = std::strtoul(f[2].c_str(), &end, 10);
        if (f[2].empty() || *end != '\0' || iterations < kMinIterations || iterations > kMaxIterations) {
            return invalidArgument(where + ": ITERATIONS must be " + std::to_string(kMinIterations) + ".." +
                                   std::to_string(kMaxIterations));
        }
        e.iterations = static_cast<uint32_t>(iterations);
        auto salt = fromHex(f[3]);
        auto key = fromHex(f[4]);
        if (!salt || salt->size() < 8) return invalidArgument(where + ": SALT must be at least 8 bytes in hex");
        if (!key || key->size() != kKeyBytes) return invalidArgument(where + ": KEY must be 32 bytes in hex");
        e.salt = std::move(*salt);
        e.key = std::move(*key);
        for (const LoginEntry& other : entries) {
            if (other.user == e.user) return invalidArgument(where + ": user '" + e.user + "' is listed twice");
        }
        entries.push_back(std::move(e));
    }
    return entries;
}

bool passwordMatches(const LoginEntry& entry, const std::string& password) {
    uint8_t derived[kDerivedBytes];
    if (entry.key.size() != kKeyBytes ||
        PKCS5_PBKDF2_HMAC(password.data(), static_cast<int>(password.size()), entry.salt.data(),
                          static_cast<int>(entry.salt.size()), static_cast<int>(entry.iterations), EVP_sha256(),
                          static_cast<int>(sizeof derived), derived) != 1) {
        return false;
    }
    return CRYPTO_memcmp(derived, entry.key.data(), kKeyBytes) == 0;
}

Status LoginBook::load(const std::filesystem::path& file) {
    RETURN_IF_ERROR(params_.validate());
    std::error_code ec;
    const auto time = std::filesystem::last_write_time(file, ec);
    if (ec) {
        return notFound("no viewer logins in " + file.string() +
                        ": add one with `facescan-site login SITE NAME USER` (deploy/security/site.sh)");
    }
    std::ifstream in(file);
    const std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    if (!in && !in.eof()) return unavailable("cannot read " + file.string());
    ASSIGN_OR_RETURN(std::vector<LoginEntry> entries, parseLogins(text, file.string()));
    if (entries.empty()) {
        return invalidArgument(file.string() +
                               " lists no login: add one with `facescan-site login SITE NAME USER` "
                               "(deploy/security/site.sh)");
    }
    std::lock_guard lock(mutex_);
    file_ = file;
    file_time_ = time;
    entries_ = std::move(entries);
    return Status::ok();
}

Status LoginBook::reload() {
    std::filesystem::path file;
    {
        std::lock_guard lock(mutex_);
        if (file_.empty()) return Status::ok();
        std::error_code ec;
        if (std::filesystem::last_write_time(file_, ec) == file_time_ && !ec) return Status::ok();
        file = file_;
    }
    return load(file);
}

void LoginBook::setEntries(std::vector<LoginEntry> entries) {
    std::lock_guard lock(mutex_);
    entries_ = std::move(entries);
}

size_t LoginBook::users() const {
    std::lock_guard lock(mutex_);
    return entries_.size();
}

double LoginBook::lockedUntil(const std::string& key) const {
    const auto it = brakes_.find(key);
    return it == brakes_.end() ? 0.0 : it->second.locked_until_s;
}

void LoginBook::fail(const std::string& key, double now_s) {
    Brake& b = brakes_[key];
    ++b.failures;
    const int over = b.failures - params_.free_failures;
    if (over >= 0) {
        const double lockout =
            std::min(params_.max_lockout_s, params_.first_lockout_s * std::ldexp(1.0, std::min(over, 30)));
        b.locked_until_s = now_s + lockout;
    }
}

LoginBook::Attempt LoginBook::login(const std::string& user, const std::string& password, const std::string& address,
                                    double now_s) {
    const std::string by_address = "address:" + address, by_user = "user:" + user;
    std::optional<LoginEntry> entry;
    {
        std::lock_guard lock(mutex_);
        const double until = std::max(lockedUntil(by_address), lockedUntil(by_user));
        if (until > now_s) return {Outcome::kLockedOut, "", until - now_s};
        for (const LoginEntry& e : entries_) {
            if (e.user == user) entry = e;
        }
        // An unknown user costs the same work as a known one: the time does not tell which names exist.
        if (!entry && !entries_.empty()) {
            entry = entries_.front();
            entry->user.clear();
        }
    }
    const bool matches = entry && passwordMatches(*entry, password);
    const bool ok = matches && !entry->user.empty();
    std::lock_guard lock(mutex_);
    if (!ok) {
        fail(by_address, now_s);
        fail(by_user, now_s);
        return {Outcome::kWrong, "", 0};
    }
    brakes_.erase(by_address);
    brakes_.erase(by_user);
    uint8_t raw[32];
    if (RAND_bytes(raw, sizeof raw) != 1) return {Outcome::kWrong, "", 0};
    static const char* kHex = "0123456789abcdef";
    std::string token;
    for (const uint8_t b : raw) {
        token += kHex[b >> 4];
        token += kHex[b & 15];
    }
    while (sessions_.size() >= params_.max_sessions) {
        auto oldest = std::min_element(sessions_.begin(), sessions_.end(), [](const auto& a, const auto& b) {
            return a.second.created_s < b.second.created_s;
        });
        sessions_.erase(oldest);
    }
    sessions_[token] = Session{user, now_s, now_s};
    return {Outcome::kOk, token, 0};
}

std::optional<std::string> LoginBook::check(const std::string& token, double now_s) {
    std::lock_guard lock(mutex_);
    const auto it = sessions_.find(token);
    if (it == sessions_.end()) return std::nullopt;
    Session& s = it->second;
    if (now_s - s.last_s > params_.session_idle_s || now_s - s.created_s > params_.session_max_s) {
        sessions_.erase(it);
        return std::nullopt;
    }
    // A user removed from the logins file loses the sessions it had.
    const bool listed =
        std::any_of(entries_.begin(), entries_.end(), [&](const LoginEntry& e) { return e.user == s.user; });
    if (!listed) {
        sessions_.erase(it);
        return std::nullopt;
    }
    s.last_s = now_s;
    return s.user;
}

void LoginBook::logout(const std::string& token) {
    std::lock_guard lock(mutex_);
    sessions_.erase(token);
}

size_t LoginBook::sessions() const {
    std::lock_guard lock(mutex_);
    return sessions_.size();
}

}  // namespace facescan::client
